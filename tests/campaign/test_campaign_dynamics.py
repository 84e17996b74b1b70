"""``--dynamics first-order|firmware`` of the campaigns (rpf_fly/campaign/missions.py `with_dynamics`, runner.py):
the copy carries ``dry_run.dynamics`` and keeps the mission (a vehicle profile still found from the work folder),
every path of a campaign flies the copy (fixed, random and lab runs; checked with the flights stubbed, nothing
flies), the command and the report's name say it, and a bad value is one line and exit 2 before anything flies."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from rpf_fly.campaign import runner
from rpf_fly.campaign.judge import Verdict
from rpf_fly.campaign.missions import with_dynamics, with_extpose, with_world_seed
from rpf_fly.campaign.runner import CampaignError, default_report, maintainers_campaign, mission_campaign
from rpf_fly.mission import load_mission

ROOT = Path(__file__).resolve().parents[2]
LAB_3 = ROOT / "missions" / "lab-3.yaml"


def test_the_dynamics_copy_carries_dry_run_dynamics_and_keeps_the_mission(tmp_path):
    original = load_mission(LAB_3)
    assert original.dry_run.dynamics == "firmware"  # the default
    first_order = load_mission(with_dynamics(LAB_3, "first-order", tmp_path))
    assert first_order.dry_run.dynamics == "first-order"
    firmware = load_mission(with_dynamics(LAB_3, "firmware", tmp_path))
    assert firmware.dry_run.dynamics == "firmware"
    assert firmware.name == original.name and firmware.drones == original.drones
    assert firmware.obstacles == original.obstacles and firmware.planner.policy == original.planner.policy
    assert firmware.dry_run.seed == original.dry_run.seed
    back = load_mission(with_dynamics(with_dynamics(LAB_3, "firmware", tmp_path), "first-order", tmp_path))
    assert back.dry_run.dynamics == "first-order"
    # with the other copies, in the order a campaign makes them: each keeps what the one before changed
    chained = load_mission(
        with_world_seed(with_dynamics(with_extpose(LAB_3, tmp_path), "firmware", tmp_path), 21003, tmp_path)
    )
    assert (chained.dry_run.dynamics, chained.dry_run.seed, chained.radio.extpos) == ("firmware", 21003, "extpose")
    with pytest.raises(ValueError, match="first-order or firmware"):
        with_dynamics(LAB_3, "firmwre", tmp_path)


def test_a_copy_still_finds_the_missions_vehicle_profile(tmp_path):
    (tmp_path / "lab" / "profiles").mkdir(parents=True)
    (tmp_path / "lab" / "profiles" / "cf.yaml").write_text(
        "format: 1\ndrone: cf1\nparams: {posCtlPid.xKp: 1.4}\nmocap: {latency_s: 0.01, noise_m: 0.001}\n"
    )
    text = LAB_3.read_text().replace("policy: ../policies/rpf3.onnx", f"policy: {ROOT / 'policies' / 'rpf3.onnx'}")
    mission = tmp_path / "lab" / "m.yaml"
    mission.write_text(text + "dry_run: {dynamics: firmware, vehicle: profiles/cf.yaml}\n")
    (tmp_path / "work").mkdir()
    copy = load_mission(with_world_seed(mission, 5, tmp_path / "work"))
    assert copy.dry_run.vehicle is not None
    assert copy.dry_run.vehicle.path == (tmp_path / "lab" / "profiles" / "cf.yaml").resolve()
    # first-order cannot fly a vehicle profile: refused before anything flies
    with pytest.raises(CampaignError, match="vehicle profile"):
        mission_campaign(mission, ["gust"], dynamics="first-order")


@pytest.fixture
def flown(monkeypatch):
    """The campaign's flights stubbed: each run's mission file, its dynamics read back, and a passing verdict."""
    runs: list[tuple[str, str]] = []

    def fly(faults, mission_file, workdir, tag=""):
        mission = load_mission(mission_file)
        runs.append(("+".join(f["kind"] for f in faults), mission.dry_run.dynamics))
        return Verdict("+".join(f["kind"] for f in faults), mission.name, None, passed=True)

    def fly_lab(fault, mission_file, workdir, tag=""):
        return fly([fault], mission_file, workdir, tag)

    monkeypatch.setattr(runner, "fly_and_judge", fly)
    monkeypatch.setattr(runner, "fly_and_judge_lab", fly_lab)
    return runs


def test_every_path_of_a_campaign_flies_the_dynamics_asked_for(flown, tmp_path):
    kinds = ["gust", "ground_station_kill", "dongle_unplug"]
    lab = mission_campaign(LAB_3, kinds, dynamics="firmware", keep=tmp_path / "a")
    assert lab.command == f"rpf-fly campaign {LAB_3} --kinds {','.join(kinds)} --dynamics firmware"
    fixed = maintainers_campaign(kinds=kinds, dynamics="firmware", keep=tmp_path / "b")
    assert fixed.command == f"python tools/fault_campaign.py --kinds {','.join(kinds)} --dynamics firmware"
    # the lab's gust, its 4 kills and 1 unplug; the tool's 2 gusts, 8 kills and 2 unplugs
    assert len(flown) == 6 + 12 and all(d == "firmware" for _, d in flown), flown
    flown.clear()
    rand = maintainers_campaign(
        random_runs=3, seed=21, faults_per_run=2, vary_world=True, dynamics="firmware", keep=tmp_path / "c"
    )
    assert rand.command.endswith(
        "--random 3 --seed 21 --planners mission,rpf3 --faults-per-run 2 --vary-world --dynamics firmware"
    )
    mine = mission_campaign(LAB_3, random_runs=2, seed=4, dynamics="firmware", keep=tmp_path / "d")
    assert mine.command.endswith("--random 2 --seed 4 --faults-per-run 2 --dynamics firmware")
    assert len(flown) == 5 and all(d == "firmware" for _, d in flown), flown
    flown.clear()
    maintainers_campaign(kinds=["gust"], missions=["lab-3"], keep=tmp_path / "e")  # without: the mission's own
    assert flown == [("gust", "firmware")]


def test_the_same_seed_draws_the_same_runs_on_either_model(flown, tmp_path):
    first = maintainers_campaign(random_runs=4, seed=22, faults_per_run=2, vary_world=True, keep=tmp_path / "a")
    firmware = maintainers_campaign(
        random_runs=4, seed=22, faults_per_run=2, vary_world=True, dynamics="firmware", keep=tmp_path / "b"
    )
    assert [(v.kind, v.mission, v.params) for v in first.verdicts] == [
        (v.kind, v.mission, v.params) for v in firmware.verdicts
    ]


def test_the_firmware_campaigns_reports_have_names_of_their_own():
    names = {
        default_report(planner, runs, seed, k, extpose, dynamics).name
        for planner, runs, seed, k, extpose, dynamics in [
            (None, 0, 0, 1, False, "firmware"),
            (None, 12, 21, 2, False, "firmware"),
            ("rpf3", 0, 0, 1, True, "firmware"),
            (None, 60, 2, 1, False, "firmware"),
            (None, 0, 0, 1, False, "first-order"),
        ]
    }
    assert names == {
        "fixed-firmware.md",
        "compound-firmware-seed21.md",
        "rpf3-extpose-firmware.md",
        "random-firmware-seed2.md",
        "fixed.md",
    }


def test_a_bad_dynamics_is_one_line_and_exit_2_before_anything_flies(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "rpf_fly", "campaign", str(LAB_3), "--dynamics", "firmwre", "--out", "R.md"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=60,
    )
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == ["--dynamics: expected first-order or firmware, got 'firmwre'"]
    assert done.stdout == "" and not list(tmp_path.iterdir())
    tool = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "fault_campaign.py"), "--dynamics", "first_order", "--out", "-"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=60,
    )
    assert tool.returncode == 2 and "--dynamics: invalid choice: 'first_order'" in tool.stderr
    assert tool.stdout == "" and not list(tmp_path.iterdir())
