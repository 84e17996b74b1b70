"""``rpf-fly sim`` end to end: the paper missions, plots, the vanilla comparison, and invalid input."""

import json
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from rpf_fly.cli import get_app

ROOT = Path(__file__).resolve().parents[2]
PAPER_MISSIONS = ["arena-a-6", "arena-b-6", "circle-8-r3", "circle-8-r8", "lab-3"]
runner = CliRunner()


def run(*args):
    return runner.invoke(get_app(), ["sim", *map(str, args)])


@pytest.mark.parametrize("name", PAPER_MISSIONS)
def test_paper_missions_succeed_with_apf(name):
    result = run(ROOT / "missions" / f"{name}.yaml", "--planner", "apf", "--json")
    assert result.exit_code == 0, result.output
    metrics = json.loads(result.stdout)
    assert metrics["mission"] == name and metrics["planner"] == "apf" and metrics["seed"] == 0
    assert metrics["success"] is True
    assert metrics["collisions"] == {"drone_drone": 0, "drone_obstacle": 0}
    assert metrics["reached"] == metrics["drones"] == len(metrics["per_drone"])


def test_seed_changes_the_jittered_layout_deterministically():
    path = ROOT / "missions" / "circle-8-r3.yaml"
    a, b, c = (json.loads(run(path, "--json", "--seed", s).stdout) for s in (1, 1, 2))
    assert a == b
    assert a["travel_distance_m"] != c["travel_distance_m"]
    assert c["seed"] == 2


def test_table_output_and_plot(tmp_path):
    png = tmp_path / "lab.png"
    result = run(ROOT / "missions" / "lab-3.yaml", "--plot", png)
    assert result.exit_code == 0, result.output
    assert "cf1" in result.stdout and "success" in result.stdout
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000


WALL_MISSION = """\
name: wall
arena: {x: [-1.0, 8.0], y: [-4.0, 4.0]}
sim: {time_limit_s: 60}
obstacles:
  - {shape: box, min: [2.0, -1.5], max: [2.2, 1.5]}
drones:
  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [0.0, 0.0], goal: [6.0, 0.0]}
"""


def test_no_wall_following_is_the_vanilla_apf(tmp_path):
    mission = tmp_path / "wall.yaml"
    mission.write_text(WALL_MISSION)
    # without guidance (the apf kind's default is path: docs/algorithm.md, *Global guidance*)
    with_wf = json.loads(run(mission, "--json", "--guidance", "none").stdout)
    stuck = run(mission, "--json", "--no-wall-following", "--guidance", "none")
    without = json.loads(stuck.stdout)
    assert with_wf["success"] and not without["success"]
    assert without["reached"] == 0 and without["per_drone"][0]["time_to_goal_s"] is None
    assert stuck.exit_code == 1  # no drone reached: exit 1, the JSON still printed
    # the path around the wall gets the vanilla APF past it too
    assert json.loads(run(mission, "--json", "--no-wall-following").stdout)["success"]


VALID = WALL_MISSION
INVALID = {
    "missing drones": VALID.split("drones:")[0],
    "empty drones": VALID.split("drones:")[0] + "drones: []\n",
    "duplicate names": VALID
    + "  - {name: cf1, uri: radio://0/80/2M/E7E7E7E702, start: [0.0, 2.0], goal: [6.0, 2.0]}\n",
    "duplicate uris": VALID + "  - {name: cf2, uri: radio://0/80/2M/E7E7E7E701, start: [0.0, 2.0], goal: [6.0, 2.0]}\n",
    "malformed uri": VALID.replace("radio://0/80/2M/E7E7E7E701", "radio://0/80/3M/E7E7"),
    "wrong type": VALID.replace("time_limit_s: 60", "time_limit_s: soon"),
    "nan": VALID.replace("time_limit_s: 60", "time_limit_s: .nan"),
    "start outside arena": VALID.replace("start: [0.0, 0.0]", "start: [-3.0, 0.0]"),
    "goal inside obstacle": VALID.replace("goal: [6.0, 0.0]", "goal: [2.1, 0.0]"),
    "start equals goal": VALID.replace("goal: [6.0, 0.0]", "goal: [0.0, 0.0]"),
    "starts closer than 2r": VALID
    + "  - {name: cf2, uri: radio://0/80/2M/E7E7E7E702, start: [0.1, 0.0], goal: [6.0, 2.0]}\n",
    "inverted range": VALID.replace("x: [-1.0, 8.0]", "x: [8.0, -1.0]"),
    "unknown key": VALID.replace("sim: {time_limit_s: 60}", "sim: {time_limit: 60}"),
    "unknown planner": VALID + "planner: {kind: rfp}\n",
    "missing policy file": VALID + "planner: {kind: rpf, policy: nowhere/rpf.onnx}\n",
    "empty file": "",
    "invalid yaml": "arena: {x: [1, 2]\n",
    "object tag": "!!python/object/apply:os.system ['echo pwned']\n",
}


@pytest.mark.parametrize("case", sorted(INVALID))
def test_invalid_mission_exits_2_with_one_line(tmp_path, case):
    mission = tmp_path / "bad.yaml"
    mission.write_text(INVALID[case])
    result = run(mission, "--json")
    assert result.exit_code == 2, (case, result.output)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith(f"{mission}:"), lines[0]
    file_, line, field, message = lines[0].split(":", 3) if lines[0].count(":") >= 3 else (None,) * 4
    assert line.isdigit() and field.strip() and message.strip()
    assert "Traceback" not in result.output
    assert result.stdout == ""


def test_invalid_mission_in_a_real_process(tmp_path):
    mission = tmp_path / "bad.yaml"
    mission.write_text(INVALID["unknown key"])
    proc = subprocess.run(
        [sys.executable, "-m", "rpf_fly", "sim", str(mission)], capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 2
    assert proc.stderr.strip() == f"{mission}:3: sim.time_limit: unknown key (did you mean 'time_limit_s'?)"
    assert proc.stdout == ""


def test_unknown_planner_option_exits_2():
    result = run(ROOT / "missions" / "lab-3.yaml", "--planner", "bogus")
    assert result.exit_code == 2
    assert "unknown planner kind 'bogus'" in result.stderr


def test_help_lists_commands_in_a_real_process():
    proc = subprocess.run([sys.executable, "-m", "rpf_fly", "--help"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0
    assert "sim" in proc.stdout


def test_exit_1_when_no_drone_reached_0_when_one_did(tmp_path):
    """A drone stuck behind the wall (vanilla APF without guidance) is exit 1 with the table; a second drone that
    reaches its goal makes it exit 0 (a failure still, said in the table)."""
    mission = tmp_path / "wall.yaml"
    mission.write_text(WALL_MISSION)
    stuck = run(mission, "--no-wall-following", "--guidance", "none")
    assert stuck.exit_code == 1 and "failure: 0/1 reached" in stuck.stdout
    mission.write_text(
        WALL_MISSION + "  - {name: cf2, uri: radio://0/80/2M/E7E7E7E702, start: [0.0, 3.0], goal: [6.0, 3.0]}\n"
    )
    one = run(mission, "--no-wall-following", "--guidance", "none")
    assert one.exit_code == 0 and "failure: 1/2 reached" in one.stdout
