"""tools/log_margin.py, the independent reader of a dry run's margin (docs/bench/rpf3.md): it reads a real MCAP file
written by the flight log's writer and judges the airborne truth against 2r + margin and r + margin, both ways."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from rpf_fly.log.writer import FlightLog

ROOT = Path(__file__).resolve().parents[2]
MISSION = """name: two
arena: {x: [-2, 2], y: [-2, 2], z: [0, 2]}
planner: {kind: apf, safety_radius: 0.1}
obstacles: [{shape: circle, center: [0.0, 1.0], radius: 0.3}]
drones:
  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [-1, 0], goal: [1, 0]}
  - {name: cf2, uri: radio://0/80/2M/E7E7E7E702, start: [1, 0], goal: [-1, 0]}
"""


def judge(tmp_path: Path, cf2_x: float, cf1_y: float = 0.0, cf2_z: float = 1.0) -> tuple[int, dict]:
    log = FlightLog(tmp_path / "t.mcap", {"name": "two"}, {})
    for k in range(3):
        log.truth(
            1_000_000_000 + k,
            {
                "cf1": ((0.0, cf1_y, 1.0), 0.0, True, False, (0.0, cf1_y, 1.0)),
                "cf2": ((cf2_x, 0.0, cf2_z), 0.0, True, False, (cf2_x, 0.0, cf2_z)),
            },
        )
    log.close()
    (tmp_path / "m.yaml").write_text(MISSION)
    done = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "log_margin.py"), str(tmp_path / "t.mcap"), str(tmp_path / "m.yaml")],
        capture_output=True,
        text=True,
        timeout=60,
    )
    return done.returncode, json.loads(done.stdout)


def test_drones_apart_and_clear_of_the_obstacle_hold(tmp_path):
    code, verdict = judge(tmp_path, cf2_x=0.3)
    assert code == 0 and verdict["held"] and verdict["min_separation_m"] == 0.3, verdict
    assert verdict["min_clearance_m"] == 0.7  # cf1 at (0, 0): 1 m from the pillar's centre, radius 0.3


def test_two_airborne_drones_inside_2r_plus_the_margin_break_it(tmp_path):
    code, verdict = judge(tmp_path, cf2_x=0.24)
    assert code == 1 and not verdict["held"] and verdict["min_separation_m"] == 0.24, verdict


def test_a_drone_inside_r_plus_the_margin_of_an_obstacle_breaks_it(tmp_path):
    code, verdict = judge(tmp_path, cf2_x=1.5, cf1_y=0.56)
    assert code == 1 and verdict["min_clearance_m"] == 0.14, verdict


def test_a_drone_on_the_floor_is_not_judged(tmp_path):
    code, verdict = judge(tmp_path, cf2_x=0.1, cf2_z=0.0)
    assert code == 0 and verdict["min_separation_m"] is None, verdict
