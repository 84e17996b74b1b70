"""Relative policy paths: a mission copied out of ``missions/`` keeps its shipped policy, and a missing policy's
error names each place looked once (docs/mission-format.md, *Policy paths*)."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from rpf_fly.mission import MissionError, load_mission, with_planner
from rpf_fly.mission.policy_paths import PROJECT_POLICIES

ROOT = Path(__file__).resolve().parents[2]


def test_the_project_policies_are_the_shipped_ones():
    assert PROJECT_POLICIES == ROOT / "policies" and (PROJECT_POLICIES / "rpf.onnx").is_file()


def test_a_copied_mission_finds_the_shipped_policy(tmp_path, monkeypatch):
    mission = tmp_path / "my-lab.yaml"
    shutil.copy(ROOT / "missions" / "lab-3.yaml", mission)
    assert "policy: ../policies/rpf3.onnx" in mission.read_text()
    elsewhere = tmp_path / "somewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    loaded = load_mission(mission)
    assert loaded.planner.policy == (ROOT / "policies" / "rpf3.onnx").resolve()
    # --planner of another learned kind takes its default from the shipped policies too.
    assert with_planner(loaded, "rpf-mean").planner.policy == (ROOT / "policies" / "rpf-mean.onnx").resolve()


def test_a_policy_beside_the_mission_wins_over_the_shipped_one(tmp_path):
    (tmp_path / "policies").mkdir()
    mine = tmp_path / "policies" / "rpf3.onnx"
    shutil.copy(ROOT / "policies" / "rpf3.onnx", mine)
    mission = tmp_path / "m.yaml"
    mission.write_text((ROOT / "missions" / "lab-3.yaml").read_text().replace("../policies/", "policies/"))
    assert load_mission(mission).planner.policy == mine.resolve()


def test_a_policy_of_ones_own_has_no_fallback(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    mission = tmp_path / "m.yaml"
    mission.write_text((ROOT / "missions" / "lab-3.yaml").read_text().replace("../policies/rpf3.onnx", "mine/rpf.onnx"))
    with pytest.raises(MissionError) as info:
        load_mission(mission)
    message = str(info.value)
    # The mission's folder is the current directory: one place, named once, and no shipped fallback.
    assert message.endswith(f"policy file 'mine/rpf.onnx' not found (looked in {tmp_path / 'mine' / 'rpf.onnx'})")


def test_a_missing_policy_names_each_place_once_with_dots_folded(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    mission = tmp_path / "m.yaml"
    mission.write_text(
        (ROOT / "missions" / "lab-3.yaml").read_text().replace("../policies/rpf3.onnx", "../policies/nope.onnx")
    )
    with pytest.raises(MissionError) as info:
        load_mission(mission)
    looked = str(info.value).split("(looked in ", 1)[1].rstrip(")").split(", ")
    assert looked == [str(tmp_path.parent / "policies" / "nope.onnx"), str(ROOT / "policies" / "nope.onnx")]


def test_sim_of_a_copied_mission_in_a_real_process(tmp_path):
    shutil.copy(ROOT / "missions" / "lab-3.yaml", tmp_path / "lab.yaml")
    proc = subprocess.run(
        [sys.executable, "-m", "rpf_fly", "sim", "lab.yaml", "--json"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["planner"] == "rpf3"
