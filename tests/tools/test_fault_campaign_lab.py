"""The fault campaign's lab kinds (``ground_station_kill``, ``dongle_unplug``): one run flown against a lab of its
own and judged on the lab's log as the campaign does (rpf_fly/campaign; the judge's rules on made-up records:
tests/campaign/test_campaign_judge.py)."""

from __future__ import annotations

import pytest
from tool_modules import ROOT

from rpf_fly.campaign.runner import fly_and_judge_lab


@pytest.mark.xdist_group("lab")
def test_a_ground_station_killed_while_planning_passes_the_campaigns_judge(tmp_path):
    fault = {"kind": "ground_station_kill", "at_phase": "planning", "at_s": 2.0}
    verdict = fly_and_judge_lab(fault, ROOT / "missions" / "lab-3.yaml", tmp_path)
    assert verdict.passed, verdict.failures
    assert verdict.exit_code == -9 and verdict.outcomes == {}
    assert verdict.events and verdict.events[0].startswith("3 of 3 airborne at the ground station kill"), verdict.events
