"""``rpf-fly calibrate TRACE``: each reference trace of the Crazyflie dynamics reference (the firmware's default
gains, tests/data/crazyflie_dynamics) calibrated from a start 30 % off the defaults gives the defaults back, within
15 %, for the axes its setpoints move; the others are reported not identified. And bad input is one line, exit 2."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from rpf_fly.calibrate.profile import load_profile
from rpf_fly.cli import get_app
from rpf_fly.emulator.cf_controller import CfGains
from rpf_fly.log import schemas as S
from rpf_fly.log.writer import FlightLog
from rpf_fly.mission import parse_mission

TRACES = Path(__file__).resolve().parents[1] / "data" / "crazyflie_dynamics" / "traces"
OFF = {
    "posCtlPid.xKp": 1.4,
    "velCtlPid.vxKp": 32.5,
    "posCtlPid.yKp": 2.6,
    "velCtlPid.vyKp": 17.5,
    "posCtlPid.zKp": 2.6,
    "velCtlPid.vzKp": 17.5,
    "posCtlPid.zKi": 0.35,
}
"""The fit's start: each gain x0.7 or x1.3 of the firmware's."""
GAINS = {
    "x": ("posCtlPid.xKp", "velCtlPid.vxKp"),
    "y": ("posCtlPid.yKp", "velCtlPid.vyKp"),
    "z": ("posCtlPid.zKp", "velCtlPid.vzKp", "posCtlPid.zKi"),
}
MOVED = {"p_circle_r0p5_v0p3": "xy", "p_hl_slow": "xz"}
"""The axes each trace's setpoints move (the others: x only)."""


@pytest.fixture(scope="module")
def start(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("start") / "off.yaml"
    path.write_text("format: 1\nparams:\n" + "".join(f"  {k}: {v}\n" for k, v in OFF.items()))
    return path


@pytest.mark.parametrize("trace", sorted(p.stem for p in TRACES.glob("*.json")))
def test_a_reference_trace_gives_the_default_gains_back(trace: str, start: Path, tmp_path: Path) -> None:
    out = tmp_path / "profile.yaml"
    done = CliRunner().invoke(
        get_app(), ["calibrate", str(TRACES / f"{trace}.json"), "--start", str(start), "--out", str(out), "--json"]
    )
    assert done.exit_code == 0, done.output
    fit = json.loads(done.stdout)["drones"][trace]
    defaults = CfGains().params()
    moved = MOVED.get(trace, "x")
    print(
        f"| {trace} | "
        + ", ".join(f"{n} x{fit['params'][n] / defaults[n]:.3f}" for a in moved for n in GAINS[a])
        + f" | {fit['residual_rms_m'] * 1000:.2f} |"
    )  # docs/dynamics.md's table (pytest -s)
    for axis, names in GAINS.items():
        for name in names:
            if axis in moved:
                assert fit["params"][name] == pytest.approx(defaults[name], rel=0.15), (name, fit)
                assert name not in fit["not_identified"]
            else:  # an axis held still says nothing: the start's value stays, and the fit says so
                assert fit["params"][name] == OFF[name]
                assert "moved 0.000 m" in fit["not_identified"][name]
    for axis in moved:  # the same model: the reference's positions within a millimetre
        assert fit["residual_axis_rms_m"][axis] < 0.001, fit
    assert (fit["latency_s"], fit["noise_m"], fit["latency_from"]) == (0.0, 0.0, "none")
    profile = load_profile(out)  # what a mission's dry_run.vehicle reads
    assert dict(profile.params) == pytest.approx(fit["params"], rel=1e-5)


def run_cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "rpf_fly", "calibrate", *args], capture_output=True, text=True, cwd=cwd, timeout=60
    )


def test_not_a_log_is_one_line_and_exit_2(tmp_path: Path) -> None:
    junk = tmp_path / "notes.mcap"
    junk.write_text("flew fine, battery 3.9 V\n")
    done = run_cli(str(junk), "--out", "p.yaml", cwd=tmp_path)
    assert done.returncode == 2
    assert (
        done.stderr == f"{junk}: neither an MCAP flight log nor a trace JSON with t, sp and pos "
        "(tests/data/crazyflie_dynamics/README.md)\n"
    )
    assert not (tmp_path / "p.yaml").exists()


def test_a_log_without_setpoints_is_one_line_and_exit_2(tmp_path: Path) -> None:
    """A real MCAP flight log (the recorder's writer) with poses and events but no setpoint stream."""
    mission = parse_mission(
        "arena: {x: [-1, 1], y: [-1, 1]}\nplanner: {kind: apf}\ndrones:\n"
        "  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [0, 0], goal: [0.5, 0]}\n"
    )
    log = tmp_path / "hover.mcap"
    with FlightLog(log, S.mission_metadata(mission, 0, "flight"), S.scenario_metadata(mission)) as flight:
        for k in range(50):
            flight.pose("cf1", 1_800_000_000_000_000_000 + k * 10_000_000, (0.0, 0.0, 0.5), (0.0, 0.0, 0.0, 1.0))
        flight.event(1_800_000_000_500_000_000, 2, "cf1: hover")
    done = run_cli(str(log), cwd=tmp_path)
    assert done.returncode == 2
    assert (
        done.stderr == f"{log}: no setpoints in the log (no /<drone>/setpoint topic): calibrate needs a streamed "
        "flight's log (rpf-fly fly or rpf-fly scenario with --log)\n"
    )


def test_a_flight_the_model_cannot_explain_is_calibrated_with_a_warning(tmp_path: Path) -> None:
    """A reference carrot pushed 5 cm aside for a second (a gust the setpoints do not say): the fit leaves it
    unexplained and says so on stderr, in the JSON and in the profile."""
    doc = json.loads((TRACES / "c_carrot_0p5.json").read_text())
    doc["pos"] = [[x + (0.05 if 4.0 <= t < 5.0 else 0.0), y, z] for t, (x, y, z) in zip(doc["t"], doc["pos"])]
    trace = tmp_path / "gust.json"
    trace.write_text(json.dumps(doc))
    done = run_cli(str(trace), "--out", "p.yaml", "--json", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    fit = json.loads(done.stdout)["drones"]["c_carrot_0p5"]
    assert fit["residual_rms_m"] > 0.01
    assert len(fit["warnings"]) == 1 and fit["warnings"][0].startswith("the fitted model leaves ")
    assert done.stderr == f"{trace}: c_carrot_0p5: warning: {fit['warnings'][0]}\n"
    assert load_profile(tmp_path / "p.yaml").params  # written all the same: the warning says what it is worth
    assert "the fitted model leaves" in (tmp_path / "p.yaml").read_text()


def test_a_log_written_from_a_trace_is_fitted_as_the_trace(tmp_path: Path) -> None:
    """The log path on a known flight: the reference's carrot written as a dry run's MCAP log (its setpoint stream,
    its positions as the mocap's poses and the truth, at the trace's instants) by the recorder's own writer and read
    back: the default gains, no latency, no noise; and since the logged mission says its dry run flew the
    first-order model, the calibration says so."""
    doc = json.loads((TRACES / "c_carrot_1p0.json").read_text())
    mission = parse_mission(
        "arena: {x: [-1, 4], y: [-1, 1]}\nplanner: {kind: apf}\ndrones:\n"
        "  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [0, 0], goal: [3, 0]}\n"
        "dry_run: {dynamics: first-order}\n"
    )
    log, t0 = tmp_path / "carrot.mcap", 1_800_000_000_000_000_000
    scenario = yaml.safe_load((TRACES.parent / "scenarios" / "c_carrot_1p0.yaml").read_text())
    with FlightLog(log, S.mission_metadata(mission, 0, "dry-run"), S.scenario_metadata(mission)) as flight:
        listed = {round(row[0] * 10): row[1:] for row in scenario["setpoints"]}
        last = listed[0]
        for k in range(round(scenario["duration_s"] * 10) + 1):  # the stream: every tick, the last listed point
            last = listed.get(k, last)
            flight.setpoint("cf1", t0 + k * 100_000_000, last)
        for t, p in zip(doc["t"], doc["pos"]):
            stamp = t0 + round(t * 1e9)
            flight.pose("cf1", stamp, p)
            flight.truth(stamp, {"cf1": (p, 0.0, True, False, p)})
    done = run_cli(str(log), "--json", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    fit = json.loads(done.stdout)["drones"]["cf1"]
    assert fit["kind"] == "log" and fit["origin"] == "dry-run"
    for name in GAINS["x"]:
        assert fit["params"][name] == pytest.approx(CfGains().params()[name], rel=0.02), fit
    assert fit["latency_from"] == "truth" and fit["latency_s"] == 0.0 and fit["noise_m"] < 1e-6
    assert abs(fit["delay_s"]) < 0.003 and fit["residual_axis_rms_m"]["x"] < 0.001, fit
    assert fit["warnings"] == [
        "its simulated drones flew the first-order model (the log's mission record), "
        "not the firmware's cascade: no gains describe them"
    ]
