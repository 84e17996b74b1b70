"""A vehicle profile in a mission (``dry_run.vehicle``): read by the loader with one line for a bad one, its gains in
every simulated drone's TOC (read through real cflib), its mocap noise and latency in the simulated mocap."""

from __future__ import annotations

from pathlib import Path

import pytest
from cflib.crazyflie import Crazyflie
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie

from rpf_fly.emulator import fake_radio
from rpf_fly.emulator.fake_world import FakeWorld
from rpf_fly.flight.dry_run import mission_mocap_noise, simulated_drones
from rpf_fly.mission import MissionError, load_mission

PROFILE = """\
format: 1
drone: cf1
params: {posCtlPid.xKp: 1.4, velCtlPid.vxKp: 32.5, posCtlPid.zKp: 2.6}
mocap: {latency_s: 0.0235, noise_m: 0.001}
"""


def mission(folder: Path, dry_run: str, profile: str = PROFILE) -> Path:
    (folder / "profiles").mkdir(exist_ok=True)
    (folder / "profiles" / "cf.yaml").write_text(profile)
    path = folder / "m.yaml"
    path.write_text(f"""\
name: profiled
arena: {{x: [-2.0, 2.0], y: [-2.0, 2.0], z: [0.0, 2.0]}}
planner: {{kind: apf}}
dry_run: {dry_run}
drones:
  - {{name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [0.0, 0.0], goal: [1.0, 0.0]}}
  - {{name: cf2, uri: radio://0/80/2M/E7E7E7E702, start: [0.0, 1.0], goal: [1.0, 1.0]}}
""")
    return path


def load_error(path: Path) -> str:
    with pytest.raises(MissionError) as caught:
        load_mission(path)
    text = str(caught.value)
    assert "\n" not in text
    return text


def test_the_profile_is_read_relative_to_the_mission(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(Path("/"))  # not found from the current folder: from the mission's
    loaded = load_mission(mission(tmp_path, "{dynamics: firmware, vehicle: profiles/cf.yaml}"))
    vehicle = loaded.dry_run.vehicle
    assert vehicle is not None and vehicle.path == (tmp_path / "profiles" / "cf.yaml").resolve()
    assert dict(vehicle.params) == {"posCtlPid.xKp": 1.4, "velCtlPid.vxKp": 32.5, "posCtlPid.zKp": 2.6}
    assert (vehicle.mocap_latency_s, vehicle.mocap_noise_m) == (0.0235, 0.001)
    # its noise in the simulated mocap unless the mission gives its own; its latency beyond the emulator's 3.5 ms
    # (20 ms: two frames at 100 Hz, the half frame selecting the second)
    assert mission_mocap_noise(loaded).position_m == 0.001
    assert vehicle.mocap_delay_s(100.0) == pytest.approx(0.015)
    own = load_mission(mission(tmp_path, "{dynamics: firmware, vehicle: profiles/cf.yaml, mocap_noise_m: 0.002}"))
    assert mission_mocap_noise(own).position_m == 0.002


@pytest.mark.parametrize(
    "dry_run, profile, expected",
    [
        (
            "{dynamics: firmware, vehicle: profiles/none.yaml}",
            PROFILE,
            "m.yaml:4: dry_run.vehicle: vehicle profile 'profiles/none.yaml' not found (looked in ",
        ),
        (
            "{dynamics: firmware, vehicle: profiles/cf.yaml}",
            PROFILE.replace("xKp", "xKq"),
            "cf.yaml: params.posCtlPid.xKq: not a parameter of the simulated firmware's controller",
        ),
        (
            "{dynamics: firmware, vehicle: profiles/cf.yaml}",
            PROFILE.replace("1.4", "fast"),
            "cf.yaml: params.posCtlPid.xKp: expected a finite number, got 'fast'",
        ),
        (
            "{dynamics: firmware, vehicle: profiles/cf.yaml}",
            "params: [1, 2]\n",
            "cf.yaml: params: expected a mapping of firmware parameters, got list",
        ),
        (
            "{dynamics: firmware, vehicle: profiles/cf.yaml}",
            "params: {}\nmocap: {latency_ms: 3}\n",
            "cf.yaml: mocap.latency_ms: unknown key (mocap has latency_s, latency_from, noise_m)",
        ),
        ("{dynamics: firmware, vehicle: profiles/cf.yaml}", "params: {posCtlPid.xKp: 2}: x\n", "cf.yaml: not YAML ("),
        (
            "{dynamics: first-order, vehicle: profiles/cf.yaml}",
            PROFILE,
            "m.yaml:4: dry_run.vehicle: a vehicle profile sets the firmware model's gains: give dry_run.dynamics: "
            "firmware with it (it is first-order)",
        ),
    ],
)
def test_a_bad_profile_is_one_line(tmp_path: Path, dry_run: str, profile: str, expected: str) -> None:
    text = load_error(mission(tmp_path, dry_run, profile))
    assert expected in text
    assert text.startswith(f"{tmp_path / 'm.yaml'}:4: dry_run.vehicle: ")


def test_the_gains_are_in_every_simulated_drones_toc(tmp_path: Path, toc_cache: Path) -> None:
    """The mission's simulated drones (`simulated_drones`, what a dry run and a lab start) hold the profile's gains as
    stored parameters: real cflib reads them from the TOC, the others keep the firmware's defaults, and the
    controller flies them."""
    loaded = load_mission(mission(tmp_path, "{dynamics: firmware, vehicle: profiles/cf.yaml}"))
    configs = simulated_drones(loaded)
    world = FakeWorld(configs)
    fake_radio.register(world)
    try:
        for address in configs:
            with SyncCrazyflie(world.uri(address), cf=Crazyflie(rw_cache=str(toc_cache))) as scf:
                scf.wait_for_params()
                get = scf.cf.param.get_value
                names = ("posCtlPid.xKp", "velCtlPid.vxKp", "posCtlPid.zKp", "posCtlPid.yKp", "velCtlPid.vyKp")
                # float32 in the TOC, as the firmware's
                assert [float(get(n)) for n in names] == pytest.approx([1.4, 32.5, 2.6, 2.0, 25.0], rel=1e-6)
            controller = world.firmware(address).vehicle.controller
            assert (controller.pid_x.kp, controller.pid_vx.kp, controller.pid_z.kp) == (1.4, 32.5, 2.6)
    finally:
        fake_radio.unregister()
        world.close()
