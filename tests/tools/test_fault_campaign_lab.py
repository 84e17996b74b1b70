"""The fault campaign's lab kinds (``ground_station_kill``, ``dongle_unplug``): their fixed runs, the random campaign
leaving them out, and one run flown against a lab and judged on the lab's log as the campaign does."""

from __future__ import annotations

import subprocess
import sys

import pytest
from tool_modules import ROOT, load_tool


def load_campaign():  # type: ignore[no-untyped-def]
    return load_tool("fault_campaign")


def test_the_fixed_campaign_flies_each_lab_kind_on_two_missions_and_every_run_parses(tmp_path):
    from rpf_fly.flight.faults import parse_faults
    from rpf_fly.mission import load_mission

    campaign = load_campaign()
    runs = campaign.lab_runs(sorted(campaign.LAB_KINDS), "lab-3,circle-8-r3", "lab-3,circle-8-r3", None, False,
                             tmp_path)
    missions: dict[str, set[str]] = {}
    for kind, path, fault in runs:
        missions.setdefault(kind, set()).add(path.stem)
        (parsed,) = parse_faults(campaign.schedule_of([fault]), "run.yaml", load_mission(path))
        assert parsed.kind == kind
    assert missions == {"ground_station_kill": {"lab-3", "circle-8-r3"}, "dongle_unplug": {"pillars-6", "split-10"}}
    phases = sorted(f["at_phase"] for k, _, f in runs if k == "ground_station_kill")
    assert phases == sorted(["takeoff", "settle", "planning", "landing"] * 2)
    # another mission list: each lab kind on it, the unplug of its highest dongle
    pillars = str(ROOT / "missions" / "campaign" / "pillars-6.yaml")
    other = campaign.lab_runs(["dongle_unplug"], pillars, "lab-3,circle-8-r3", None, False, tmp_path)
    assert [(k, f["dongle"]) for k, _, f in other] == [("dongle_unplug", 1)]
    assert campaign.lab_runs(["occlusion"], "lab-3,circle-8-r3", "lab-3,circle-8-r3", None, False, tmp_path) == []


def test_the_random_campaign_does_not_draw_the_lab_kinds():
    campaign = load_campaign()
    assert not campaign.LAB_KINDS & set(campaign.DEFAULTS)
    done = subprocess.run([sys.executable, str(ROOT / "tools" / "fault_campaign.py"), "--random", "1", "--kinds",
                           "dongle_unplug", "--out", "-"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "in the fixed campaign only" in done.stderr, done.stderr


def test_the_phase_a_kill_struck_in_is_read_from_the_flights_stderr():
    campaign = load_campaign()
    stderr = ("[phase] swarm: takeoff\n[takeoff] take-off commanded: 3 drone(s)\n[phase] swarm: flying\n"
              "[phase] swarm: landing (mission complete)\n[fault] injected ground_station_kill at landing + 0.7 s\n")
    assert campaign._phase_at_kill(stderr) == "landing"  # noqa: SLF001
    planning = stderr.replace("[phase] swarm: landing (mission complete)\n", "")
    assert campaign._phase_at_kill(planning) == "flying"  # noqa: SLF001


@pytest.mark.xdist_group("lab")
def test_a_ground_station_killed_while_planning_passes_the_campaigns_judge(tmp_path):
    campaign = load_campaign()
    fault = {"kind": "ground_station_kill", "at_phase": "planning", "at_s": 2.0}
    verdict = campaign.judge_lab(fault, ROOT / "missions" / "lab-3.yaml", tmp_path)
    assert verdict.passed, verdict.failures
    assert verdict.exit_code == -9 and verdict.outcomes == {}
    assert verdict.events and verdict.events[0].startswith("3 of 3 airborne at the ground station kill"), \
        verdict.events
