"""tools/fault_campaign.py, the maintainers' campaign over the package (rpf_fly/campaign): its flights run and judged
exactly as the full campaign's (one fault, then two at once, on lab-3), so the campaign cannot rot between full
runs; the tool's options reach the package, and the names tools/swarm_acceptance.py imports from it stay."""

from __future__ import annotations

import subprocess
import sys

from tool_modules import ROOT, load_tool

from rpf_fly.campaign.runner import default_report, fly_and_judge
from rpf_fly.campaign.schedules import fault_fields


def test_an_occlusion_on_lab_3_passes_the_campaigns_judge(tmp_path):
    """cf2 is occluded for 1 s with 0.23 m of room to an obstacle: the blind rule (docs/flight.md, "Blind") may
    land it before its estimate's possible drift could take it there; whatever it does, the others reach, the exit
    code says whether every drone did, and a landing has its reason in an event."""
    verdict = fly_and_judge([fault_fields("occlusion", "cf2")], ROOT / "missions" / "lab-3.yaml", tmp_path)
    assert verdict.passed, verdict.failures
    others = {name: outcome for name, outcome in verdict.outcomes.items() if name != verdict.drone}
    assert len(others) == 2 and set(others.values()) == {"reached"}
    every_drone_reached = verdict.outcomes[verdict.drone] == "reached"
    assert verdict.exit_code == (0 if every_drone_reached else 1)
    if not every_drone_reached:
        assert any("pose_lost" in e and "landing now" in e for e in verdict.events), verdict.events
    assert any("pose_stale" in e for e in verdict.events)
    assert verdict.min_separation_m is not None and verdict.min_separation_m > 0.13


def test_two_faults_at_once_on_lab_3_are_judged_on_the_truth(tmp_path):
    """A compound run flown and judged end to end: an occlusion of cf1 and a gust on cf3 in the same flight."""
    faults = [fault_fields("occlusion", "cf1", {"duration_s": 0.5}, 2.0), fault_fields("gust", "cf3", None, 3.0)]
    verdict = fly_and_judge(faults, ROOT / "missions" / "lab-3.yaml", tmp_path)
    assert verdict.passed, verdict.failures
    assert verdict.kind == "occlusion+gust" and verdict.drone == "cf1,cf3"
    assert verdict.outcomes["cf2"] == "reached"
    assert any("pose_" in e for e in verdict.events) and any("tracking" in e for e in verdict.events), verdict.events


def test_the_tools_options_are_checked_before_anything_flies(tmp_path):
    def tool(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run(
            [sys.executable, str(ROOT / "tools" / "fault_campaign.py"), *args],
            capture_output=True,
            text=True,
            timeout=60,
            cwd=tmp_path,
        )

    misspelt = tool("--kinds", "gust,reboto", "--out", "-")
    assert misspelt.returncode == 2 and "unknown fault kind 'reboto' (did you mean 'reboot'?)" in misspelt.stderr
    lab = tool("--random", "1", "--kinds", "dongle_unplug", "--out", "-")
    assert lab.returncode == 2 and "in the campaign without --random only" in lab.stderr, lab.stderr
    nowhere = tool("--kinds", "gust", "--out", str(tmp_path / "no" / "R.md"))
    assert nowhere.returncode == 2 and "--out" in nowhere.stderr
    assert not list(tmp_path.iterdir())


def test_each_campaign_has_its_own_report_under_docs():
    reports = {
        default_report(None, 0, 0, 1, False),
        default_report("rpf3", 0, 0, 1, False),
        default_report(None, 0, 0, 1, True),
        default_report(None, 16, 17, 2, False),
        default_report(None, 16, 18, 3, True),
        default_report(None, 60, 2, 1, False),
    }
    assert {p.name for p in reports} == {
        "fixed.md",
        "rpf3.md",
        "fixed-extpose.md",
        "compound-seed17.md",
        "compound-extpose-seed18.md",
        "random-seed2.md",
    }
    assert all(p.parent == ROOT / "docs" / "fault-campaign" for p in reports)


def test_the_names_swarm_acceptance_imports_stay(tmp_path):
    campaign = load_tool("fault_campaign")
    assert (campaign.CONTACT_M, campaign.GOAL_M, campaign.ON_FLOOR_M) == (0.13, 0.25, 0.05)
    assert callable(campaign.read_log)
