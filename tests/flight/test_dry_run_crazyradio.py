"""Dry runs and labs through cflib's own radio driver (``dry_run.radio: crazyradio``): the mission's ``radio://`` URIs
stay as they are, emulated Crazyradios are plugged into the flight's process (rpf_fly/emulator/crazyradio.py), and
every packet to the simulated drones goes through cflib's ``RadioDriver``, ``_SharedRadio`` and ``Crazyradio`` and
pyusb, as with real dongles."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from flight_harness import SHORT_MISSION
from lab_harness import LabProcess
from typer.testing import CliRunner

from rpf_fly.cli import get_app
from rpf_fly.emulator import crazyradio
from rpf_fly.flight.dry_run import DryRun
from rpf_fly.mission import MissionError, parse_mission

CRAZYRADIO = "dry_run: {radio: crazyradio, crazyradio: crazyradio_pa}\n"
NAMES = ("cf1", "cf2", "cf3")
ADDRESSES = {name: 0xE7E7E7E700 + i for i, name in enumerate(NAMES, start=1)}


def test_the_mission_keys_choose_the_radio_and_the_dongles_type() -> None:
    mission = parse_mission(
        SHORT_MISSION.replace("radio://0/80/2M/E7E7E7E703", "fake://2/80/2M/E7E7E7E703")
        + "radio: {dongle_type: crazyradio_2}\ndry_run: {radio: crazyradio}\n"
    )
    rig = DryRun(mission)  # not started: nothing plugged yet
    assert (rig.radio, rig.crazyradio, rig.plugged) == ("crazyradio", "crazyradio_2", None)  # the lab's dongle type
    assert rig.uris == {
        "cf1": "radio://0/80/2M/E7E7E7E701",
        "cf2": "radio://0/80/2M/E7E7E7E702",
        "cf3": "radio://2/80/2M/E7E7E7E703",
    }  # as the mission says them, a fake:// one as radio://
    assert DryRun(parse_mission(SHORT_MISSION)).uris["cf1"] == "fake://0/80/2M/E7E7E7E701"  # the default: fake
    with pytest.raises(
        MissionError,
        match=r"^<string>:12: dry_run.radio: expected one of 'fake', 'crazyradio', "
        r"got 'usb'$",
    ):
        parse_mission(SHORT_MISSION + "dry_run: {radio: usb}\n")


def test_a_dry_run_flies_every_drone_to_its_goal_through_cflibs_radio_driver(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    mission = tmp_path / "short-3.yaml"
    # at the product's 0.5 m/s: through a shared dongle each extpos arrives later than through fake://, and on a
    # busy host at 0.8 m/s that lag put an estimate 0.1 m behind its drone's pose (the supervisor cut it)
    text = SHORT_MISSION.replace("speed: 0.8", "speed: 0.5")
    mission.write_text(text.replace("mocap: {kind: sim, rate_hz: 100}", "mocap: {kind: natnet}") + CRAZYRADIO)
    plugs: list[crazyradio.Plugged] = []
    real_plug = crazyradio.plug

    def plug(*args: Any, **kwargs: Any) -> crazyradio.Plugged:  # the flight's own plug, kept to read its counters
        plugs.append(real_plug(*args, **kwargs))
        return plugs[-1]

    monkeypatch.setattr(crazyradio, "plug", plug)
    log = tmp_path / "flight.mcap"
    result = CliRunner().invoke(get_app(), ["fly", str(mission), "--dry-run", "--no-console", "--log", str(log)])
    assert result.exit_code == 0, result.stdout + result.stderr
    for name in NAMES:
        assert f"{name}: reached" in result.stdout, result.stdout
    assert len(plugs) == 1 and crazyradio.plugged() is None  # plugged for the flight, unplugged after it
    (plugged,) = plugs
    assert plugged.radio.name == "crazyradio_pa" and len(plugged.dongles) == 1
    counters = plugged.dongles[0].counters
    for name, address in ADDRESSES.items():
        # the emulated backend's bulk writes, which only cflib's Crazyradio makes: the connection, parameters,
        # take-off, setpoints at 10 Hz, extpos at 30 Hz, cflib's pings, the landing; and the links' polls
        assert counters.packets[address] > 300, (name, counters.packets[address])
        assert counters.polls[address] > 0
    assert counters.address_switches > 0  # three links taking turns on one dongle


LATCH = """\
import sys
import cflib.crtp
from cflib.crazyflie import Crazyflie
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie
from cflib.crtp.radiodriver import RadioDriver
from rpf_fly.emulator import crazyradio
from rpf_fly.flight.dry_run import DryRun
from rpf_fly.mission import MissionError, parse_mission
from rpf_fly.flight.lab import lab_world

plug = crazyradio.plug(lab_world(), radio="crazyradio_pa")
cflib.crtp.init_drivers()
for uri in sys.argv[2:]:
    with SyncCrazyflie(uri, cf=Crazyflie(rw_cache=sys.argv[1])) as scf:
        assert type(scf.cf.link) is RadioDriver
        print(uri, scf.cf.param.get_value("stabilizer.estimator"))
print("packets", sum(plug.dongles[0].counters.packets.values()))
"""


def test_a_cflib_program_plugged_into_a_running_lab_reaches_its_drones_and_a_flight_checks_them(tmp_path: Path) -> None:
    mission = tmp_path / "lab-short-3.yaml"
    mission.write_text(
        SHORT_MISSION.replace(
            "mocap: {kind: sim, rate_hz: 100}", "mocap: {kind: natnet, server: 127.0.0.1, rate_hz: 100}"
        )
        + CRAZYRADIO
    )
    lab = LabProcess(tmp_path, mission)
    try:
        script = tmp_path / "program.py"
        script.write_text(LATCH)
        uris = [f"radio://0/80/2M/{a:010X}" for a in ADDRESSES.values()]
        program = subprocess.run(
            [sys.executable, str(script), str(tmp_path / "toc"), *uris],
            capture_output=True,
            text=True,
            env=lab.env,
            timeout=90,
        )
        assert program.returncode == 0, program.stdout + program.stderr
        lines = program.stdout.splitlines()
        assert [line.split()[0] for line in lines[:3]] == uris and all(line.split()[1].isdigit() for line in lines[:3])
        assert int(lines[3].split()[1]) > 0
        check = lab.run("check", str(mission), "--lab")  # the lab's drones through the flight's own crazyradio path
        assert check.returncode == 0, check.stdout + check.stderr
        for name in NAMES:
            assert f"{name}: ok" in check.stdout, check.stdout
    finally:
        out = lab.stop()
    assert 'crazyradio.plug(lab_world(), dongles=1, radio="crazyradio_pa")' in out, out
