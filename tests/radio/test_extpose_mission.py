"""A mission that streams whole poses (``radio.extpos: extpose``) configures its drones for them: every flight path
builds its `CflibBackend` from the mission (`CflibBackend.for_mission`), which sets `locSrv.extQuatStdDev`."""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import pytest

import rpf_fly
from rpf_fly.mission import parse_mission
from rpf_fly.radio.cflib_backend import CflibBackend

MISSION = """\
name: extpose-2
arena: {{x: [-2.0, 2.0], y: [-2.0, 2.0], z: [0.0, 1.5]}}
flight: {{height: 0.5, speed: 0.5, rate_hz: 10, goal_tolerance: 0.1, takeoff_s: 1.0, land_s: 1.0, timeout_s: 30}}
planner: {{kind: apf, margin: 0}}
mocap: {{kind: sim, rate_hz: 100}}
radio: {{extpos: {extpos}}}
drones:
  - {{name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [-1.0, -0.3], goal: [1.0, -0.3]}}
  - {{name: cf2, uri: radio://0/80/2M/E7E7E7E702, start: [-1.0, 0.3], goal: [1.0, 0.3]}}
"""
FIRMWARE_DEFAULT = 4.5e-3
"""`locSrv.extQuatStdDev` of a Crazyflie that was never told (the fake firmware's default, the real one's)."""


@pytest.mark.parametrize("extpos", ["extpose", "extpos"])
def test_a_dry_run_check_sets_the_pose_std_dev_of_an_extpose_mission(
    extpos: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``rpf-fly check --dry-run`` connects the mission's simulated drones as a flight does: with extpose each
    drone's estimator gets the backend's orientation standard deviation, with extpos it keeps the firmware's."""
    from rpf_fly.app.flight import FlightApp
    from rpf_fly.flight import dry_run

    params: dict[str, dict[str, float]] = {}

    class Recorded(dry_run.DryRun):
        """The check's rig, in this process; it keeps each drone's parameters as they were at the end."""

        def __init__(self, mission, **kwargs):  # type: ignore[no-untyped-def]
            super().__init__(mission, **{**kwargs, "process": False, "mocap": "sim"})

        def close(self) -> None:
            if self.world is not None:
                params.update({name: self.snapshot(name).params for name in self.addresses})
            super().close()

    monkeypatch.setattr(dry_run, "DryRun", Recorded)
    mission = parse_mission(MISSION.format(extpos=extpos))
    checked = FlightApp(tmp_path / "mission.yaml", mission=mission)
    problems = checked.preflight(checked.planner_factory(), dry_run=True)
    assert not any(problems.values()), problems
    assert set(params) == {"cf1", "cf2"}
    backend_default = inspect.signature(CflibBackend).parameters["ext_quat_std_dev"].default
    wanted = backend_default if extpos == "extpose" else FIRMWARE_DEFAULT
    for name, values in params.items():
        assert values["locSrv.extQuatStdDev"] == pytest.approx(wanted), name


def test_every_flight_path_builds_its_backend_from_the_mission() -> None:
    """No `CflibBackend(...)` in the package outside its own module: the flight, the check and a distributed
    worker all call `CflibBackend.for_mission`, so none drops the mission's extpose."""
    package = Path(rpf_fly.__file__).parent
    direct: list[str] = []
    for path in sorted(package.rglob("*.py")):
        if path.name == "cflib_backend.py":
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "CflibBackend":
                direct.append(f"{path.relative_to(package.parent)}:{node.lineno}")
    assert direct == []


def test_for_mission_reads_the_extpos_setting() -> None:
    assert CflibBackend.for_mission(parse_mission(MISSION.format(extpos="extpose")), None)._use_extpose
    assert not CflibBackend.for_mission(parse_mission(MISSION.format(extpos="extpos")), None)._use_extpose
