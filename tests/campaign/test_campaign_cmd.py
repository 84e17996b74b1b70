"""``rpf-fly campaign`` as a lab runs it: through the CLI in a process of its own, two cheap kinds flown on lab-3
(each a real-time dry run of about 15 s), the report's rows and the verdicts against the exit code; bad input is one
line and exit 2 before anything flies."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
KINDS = ("loop_stall", "blackout")
"""Two kinds whose flights end soon after the fault (the watchdog lands the swarm; the blind swarm lands)."""


def campaign(*args: str, cwd: Path, timeout: float = 240) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "rpf_fly", "campaign", *args], capture_output=True, text=True, cwd=cwd, timeout=timeout
    )


def test_a_campaign_on_lab_3_reports_each_kind_judged_on_the_truth(tmp_path):
    mission = ROOT / "missions" / "lab-3.yaml"
    done = campaign(str(mission), "--kinds", ",".join(KINDS), "--out", "R.md", "--json", cwd=tmp_path)
    assert "Traceback" not in done.stderr, done.stderr
    doc = json.loads(done.stdout)
    verdicts = doc["verdicts"]
    assert [v["kind"] for v in verdicts] == list(KINDS)
    assert done.returncode == (0 if all(v["passed"] for v in verdicts) else 1)
    for v in verdicts:
        assert v["passed"], (v["kind"], v["failures"])
        assert v["mission"] == "lab-3" and v["drone"] is None  # swarm kinds name no drone
        # the judge read the truth: three drones' outcomes, a separation measured, the fault's own warning said
        assert set(v["outcomes"]) == {"cf1", "cf2", "cf3"}
        assert v["min_separation_m"] is not None and v["min_separation_m"] > 0.13
        assert v["events"], v
    stall, blackout = verdicts
    assert set(stall["outcomes"].values()) == {"landed_early"} and stall["exit_code"] == 1
    assert any(e.startswith("loop:") for e in stall["events"]), stall["events"]
    assert any("mocap" in e for e in blackout["events"]), blackout["events"]
    assert doc["passed"] == 2 and doc["failed"] == 0

    report = (tmp_path / "R.md").read_text()
    head, _, table = report.partition("\n\n")
    assert f"rpf-fly campaign {mission} --kinds {','.join(KINDS)}" in head and "2 of 2 pass" in head
    rows = [line.split(" | ") for line in table.splitlines()[2:]]
    assert [(r[0].lstrip("| "), r[1], r[3]) for r in rows] == [(k, "lab-3", "pass") for k in KINDS]
    assert "; ".join(stall["events"]) in report


def test_a_misspelt_kind_is_one_line_with_the_kind_meant_and_exit_2(tmp_path):
    done = campaign(
        str(ROOT / "missions" / "lab-3.yaml"),
        "--kinds",
        "loop_stall,occlusoin",
        "--out",
        "R.md",
        cwd=tmp_path,
        timeout=60,
    )
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == ["--kinds: unknown fault kind 'occlusoin' (did you mean 'occlusion'?)"]
    assert done.stdout == "" and not (tmp_path / "R.md").exists()  # nothing flew, no report


def test_a_random_campaign_refuses_a_lab_kind_and_a_missing_mission_is_named(tmp_path):
    lab = campaign(
        str(ROOT / "missions" / "lab-3.yaml"),
        "--random",
        "2",
        "--kinds",
        "gust,dongle_unplug",
        cwd=tmp_path,
        timeout=60,
    )
    assert lab.returncode == 2 and len(lab.stderr.strip().splitlines()) == 1
    assert "dongle_unplug" in lab.stderr and "--random" in lab.stderr
    missing = campaign("no-such-mission.yaml", cwd=tmp_path, timeout=60)
    assert missing.returncode == 2 and missing.stderr.strip().splitlines() == [
        "no-such-mission.yaml:0: (file): no such file"
    ]
