"""``rpf-fly scenario FILE --dry-run --json``: one simulated drone flies a dynamics scenario through cflib, the fake
radio, the NatNet emulator and extpos, and the trace comes out in the reference's trace format.

Acceptance (docs/dynamics.md, "The simulated drone"): the dry run flies the firmware model, and every public
scenario of tests/data/crazyflie_dynamics/scenarios, and two of the same kinds that are not there, match the
reference's figures (the offline model's for the two): lags and overshoots within 4 cm or 20 %, settling times
within 0.3 s, high-level lags within 8 cm or 20 %. Each flight is 20-45 s of real time; each scenario is flown once
per worker (`flown`) and the tests that read it share it, on one worker (`xdist_group`). The first test that needs
a flight starts all of them, `CONCURRENT` at a time, the longest first (each dry run is its own processes and uses
about a fifth of a core; 6 at a time: 99 s beside two workers flying dry runs, 4 at a time: 133 s)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

import pytest
import yaml

from rpf_fly.emulator.cf_scenario import Scenario, carrot_scenario, figures, fly, hold_scenario
from rpf_fly.flight.scenario_flight import HOVER_SETTLE_S, plan_point, scenario_mission

pytestmark = pytest.mark.xdist_group("scenario")

DATA = Path(__file__).resolve().parents[1] / "data" / "crazyflie_dynamics" / "scenarios"
TRACES = DATA.parent / "traces"
PUBLIC = sorted(path.stem for path in DATA.glob("*.yaml"))


def run(tmp_path: Path, scenario: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [
            sys.executable,
            "-m",
            "rpf_fly",
            "scenario",
            str(scenario),
            "--dry-run",
            "--json",
            "--log",
            str(tmp_path / "scenario.mcap"),
        ],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=240,
    )


MADE = (carrot_scenario(0.7, name="c_carrot_0p7"), hold_scenario(0.45, name="p_hold_0p45"))
"""Scenarios of the same kinds that are not in the folder, judged against the offline model."""
CONCURRENT = 6
"""Scenario dry runs flown at once by one worker."""


def flight_s(scenario: Scenario) -> float:
    """About how long its dry run flies: a setpoint scenario hovers `HOVER_SETTLE_S` at its start first."""
    return scenario.duration_s + (0.0 if scenario.is_command else HOVER_SETTLE_S)


_FLOWN: dict[str, Future] = {}
_POOL: list[ThreadPoolExecutor] = []
_WANTED: list[str] = []
"""The scenarios the selected tests of this run read (stems): only those are flown ahead."""


@pytest.fixture(scope="module", autouse=True)
def _selected(request: pytest.FixtureRequest) -> None:
    fixed = {
        "test_a_carrot_scenario_flies_through_the_stack_and_prints_its_trace": "c_carrot_0p5",
        "test_a_command_scenario_traces_the_high_level_plan": "p_hl_slow",
    }
    for item in request.session.items:
        if getattr(item, "module", None) is not request.module:
            continue
        params = getattr(getattr(item, "callspec", None), "params", {})
        stem = params.get("name") or getattr(params.get("scenario"), "name", None) or fixed.get(item.originalname)
        if stem is not None and stem not in _WANTED:
            _WANTED.append(stem)


def made_path(scenario: Scenario, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A made scenario written as a scenario file (the same file for every test of this worker)."""
    path = tmp_path_factory.getbasetemp() / "made-scenarios" / f"{scenario.name}.yaml"
    if not path.exists():
        path.parent.mkdir(exist_ok=True)
        path.write_text(
            yaml.safe_dump(
                {
                    "name": scenario.name,
                    "start": list(scenario.start),
                    "duration_s": scenario.duration_s,
                    "stream_hz": scenario.stream_hz,
                    "setpoints": [list(row) for row in scenario.setpoints],
                    **({"hold_at": scenario.hold_at} if scenario.hold_at is not None else {}),
                }
            )
        )
    return path


def _fly(scenario: Path, folder: Path) -> tuple[dict[str, Any], Path]:
    done = run(folder, scenario)
    assert done.returncode == 0, done.stderr
    (folder / "trace.json").write_text(done.stdout)  # to read a miss by
    return json.loads(done.stdout), folder


def flown(
    scenario: Path, tmp_path_factory: pytest.TempPathFactory, *, again: bool = False
) -> tuple[dict[str, Any], Path]:
    """The trace of ``rpf-fly scenario SCENARIO --dry-run --json`` and its log's folder, flown once per worker
    (``again``: flown anew, alone). The first call starts every scenario's flight, `CONCURRENT` at a time."""
    if not _POOL:
        _POOL.append(ThreadPoolExecutor(CONCURRENT, thread_name_prefix="scenario"))
        every = [DATA / f"{name}.yaml" for name in PUBLIC] + [made_path(s, tmp_path_factory) for s in MADE]
        ahead = [path for path in every if path.stem in _WANTED or path == scenario]
        # the one asked for first, then the longest first (the sweep ends with its shortest flights)
        for path in sorted(ahead, key=lambda path: (path != scenario, -flight_s(Scenario.load(path)))):
            _FLOWN[str(path)] = _POOL[0].submit(_fly, path, tmp_path_factory.mktemp(path.stem))
    key = str(scenario)
    if key not in _FLOWN or again:
        _FLOWN[key] = Future()
        _FLOWN[key].set_result(_fly(scenario, tmp_path_factory.mktemp(scenario.stem)))
    return _FLOWN[key].result()


LAGS = ("lag_cm", "along_cm", "radial_cm", "err_mean_cm", "err_max_cm", "z_dev_cm", "z_err_at_goto_cm")
OVERSHOOTS = ("overshoot_cm", "takeoff_overshoot_cm", "goto_overshoot_cm")
HIGH_LEVEL_LAGS = ("takeoff_lag_max_cm", "goto_lag_max_cm", "land_lag_max_cm")
SETTLING = ("settle_s", "takeoff_settle_s", "goto_settle_s")
TIMES = ("rise_s", "touchdown_after_land_s")
SPEEDS = ("peak_speed_m_s", "speed_after_hold_m_s")


def unsettled(value: Any) -> bool:
    return value is None or value == "not settled" or (isinstance(value, float) and math.isinf(value))


BAND_SCALES = (1.25, 0.8)
"""The settling bands a time's comparison also reads: 20 % wider and narrower than the figure's own. A drone whose
error lingers near a band's edge settles a second earlier or later as its path passes a millimetre inside or
outside it (an extpos a world step late does that): two traces agree on a settling time when either one's time lies
between the other's times in the wider and the narrower band, give or take 0.3 s."""


def bracketed(value: Any, wide: Any, narrow: Any) -> bool:
    """Whether settling time ``value`` lies within 0.3 s of [``wide``, ``narrow``] (not settled: infinite)."""
    as_s = [math.inf if unsettled(v) else float(v) for v in (value, wide, narrow)]
    return as_s[1] - 0.3 <= as_s[0] <= as_s[2] + 0.3


def misses(
    flown_trace: dict[str, Any], reference_trace: dict[str, Any], scenario: Scenario
) -> dict[str, tuple[Any, Any]]:
    """The figures of a flight that miss the reference's: lags, overshoots and the heights' errors within 4 cm or
    20 %, high-level lags within 8 cm or 20 %, rise and touchdown times within 0.3 s, settling times within 0.3 s
    (`BAND_SCALES`; both "not settled" agree), speeds within 20 %. Tilts are not in a dry run's trace."""
    flown_figures, reference = flown_trace["figures"], reference_trace["figures"]
    banded: dict[str, tuple[dict[str, Any], dict[str, Any]]] = {}

    def settle_agrees(name: str, got: Any, ref: Any) -> bool:
        if unsettled(got) == unsettled(ref) and (unsettled(got) or abs(got - ref) <= 0.3):
            return True
        if not banded:
            for which, trace in (("flown", flown_trace), ("reference", reference_trace)):
                banded[which] = tuple(figures(trace, scenario, band_scale=k) for k in BAND_SCALES)  # type: ignore[assignment]
        wide_f, narrow_f = banded["flown"]
        wide_r, narrow_r = banded["reference"]
        return bracketed(got, wide_r[name], narrow_r[name]) or bracketed(ref, wide_f[name], narrow_f[name])

    out = {}
    for name, ref in reference.items():
        if name not in flown_figures or "tilt" in name:
            continue
        got = flown_figures[name]
        if name in SETTLING:
            ok = settle_agrees(name, got, ref)
        elif name in TIMES:
            ok = unsettled(got) == unsettled(ref) and (unsettled(got) or abs(got - ref) <= 0.3)
        elif name in HIGH_LEVEL_LAGS:
            ok = abs(got - ref) <= max(8.0, 0.2 * abs(ref))
        elif name in LAGS or name in OVERSHOOTS:
            ok = abs(got - ref) <= max(4.0, 0.2 * abs(ref))
        elif name in SPEEDS:
            ok = abs(got - ref) <= 0.2 * abs(ref)
        else:
            raise AssertionError(f"figure {name} has no tolerance")
        if not ok:
            out[name] = (got, ref)
    return out


def assert_flies_as(scenario: Path, reference_trace: dict[str, Any], tmp_path_factory: pytest.TempPathFactory) -> None:
    """The dry run's figures match the reference trace's (`misses`). A flight whose host fell behind (a late world
    step or mocap frame: extpos late, the estimate blind, the setpoint watchdog firing; the trace's
    ``host_behind_s``) or stalled its ground station's extpos feed (``feed_stall_s``) and missed is not evidence:
    it is flown once more, and a second such flight fails as the host's."""
    loaded = Scenario.load(scenario)
    trace, folder = flown(scenario, tmp_path_factory)
    assert set(reference_trace["figures"]) - set(trace["figures"]) <= {"peak_tilt_deg", "peak_tilt_after_stop_deg"}
    missed = misses(trace, reference_trace, loaded)
    if missed and not_evidence(trace):
        trace, folder = flown(scenario, tmp_path_factory, again=True)
        missed = misses(trace, reference_trace, loaded)
        if missed and not_evidence(trace):
            pytest.fail(
                f"the host could not keep up in two flights (behind {trace['host_behind_s']:.1f} s, extpos "
                f"stalled {trace['feed_stall_s']:.3f} s): this dry run is not evidence (misses {missed}; {folder})"
            )
    behind, stalled = trace.get("host_behind_s"), trace.get("feed_stall_s")
    assert missed == {}, f"{folder}: host behind {behind} s, extpos stalled {stalled} s"


def not_evidence(trace: dict[str, Any]) -> bool:
    """Whether the host fell behind during the flight (`_host_verdict` in rpf_fly/flight/scenario_flight.py)."""
    from rpf_fly.emulator.host_lag import HOST_BEHIND_REPORT_S
    from rpf_fly.flight.scenario_flight import FEED_STALL_S

    return trace.get("host_behind_s", 0.0) >= HOST_BEHIND_REPORT_S or trace.get("feed_stall_s", 0.0) > FEED_STALL_S


@pytest.mark.parametrize("name", PUBLIC)
def test_a_public_scenario_flies_as_the_reference(name: str, tmp_path_factory: pytest.TempPathFactory) -> None:
    reference = json.loads((TRACES / f"{name}.json").read_text())
    assert_flies_as(DATA / f"{name}.yaml", reference, tmp_path_factory)


@pytest.mark.parametrize("scenario", MADE, ids=lambda s: s.name)
def test_a_scenario_not_in_the_folder_flies_as_the_offline_model(
    scenario: Scenario, tmp_path_factory: pytest.TempPathFactory
) -> None:
    path = made_path(scenario, tmp_path_factory)
    assert Scenario.load(path) == scenario
    assert_flies_as(path, fly(scenario), tmp_path_factory)


def test_a_carrot_scenario_flies_through_the_stack_and_prints_its_trace(tmp_path_factory):
    trace, folder = flown(DATA / "c_carrot_0p5.yaml", tmp_path_factory)
    assert trace["name"] == "c_carrot_0p5" and len(trace["t"]) == len(trace["sp"]) == len(trace["pos"])
    assert abs(trace["t"][1] - trace["t"][0] - 0.02) < 1e-6 and trace["t"][-1] > 7.9  # 50 Hz over 8 s
    scenario = Scenario.load(DATA / "c_carrot_0p5.yaml")
    assert trace["figures"]["lag_cm"] == pytest.approx(figures(trace, scenario)["lag_cm"])
    # the drone follows the carrot: it ends near 1.5 m (0.5 m/s for 3 s), having trailed it
    assert abs(trace["pos"][-1][0] - 1.5) < 0.1 and trace["figures"]["lag_cm"] > 5.0
    assert (folder / "scenario.mcap").stat().st_size > 0
    assert 0.0 <= trace["host_behind_s"] < 60.0  # how long the host let the world fall behind (0 when it kept up)
    assert 0.009 < trace["feed_stall_s"] < 1.0  # the longest wait between two extpos: a mocap period at least


def test_the_extpos_feeds_longest_wait_is_counted_from_t0_to_the_scenarios_end() -> None:
    """`ScenarioFlight.feed_stall_s`: a 56 ms wait inside the scenario counts, one spanning t = 0 counts, a longer
    one before t = 0 (the hover) or after its end (the landing) does not."""
    from rpf_fly.flight.scenario_flight import ScenarioFlight

    scenario = Scenario.load(DATA / "c_carrot_1p0_100hz.yaml")
    flight = ScenarioFlight(scenario_mission(scenario), "cf1", scenario, backend=None, mocap=None, uri="")
    for now in (0.0, 0.01, 0.5, 0.51):  # a 0.49 s wait in the hover
        flight._fed(now)
    flight.t0 = 0.53
    for now in (0.545, 0.555, 0.611, 0.621):  # 35 ms across t = 0, then 56 ms
        flight._fed(now)
    assert flight.feed_stall_s == pytest.approx(0.056)
    flight._fed(0.53 + scenario.duration_s + 0.5)  # after the end: the landing
    assert flight.feed_stall_s == pytest.approx(0.056)


def test_a_command_scenario_traces_the_high_level_plan(tmp_path_factory):
    trace, _ = flown(DATA / "p_hl_slow.yaml", tmp_path_factory)
    z = [p[2] for p in trace["pos"]]
    assert max(z) > 0.45 and z[-1] < 0.02  # took off, landed
    assert trace["sp"][0][2] == 0.0 and max(p[2] for p in trace["sp"]) == pytest.approx(0.5, abs=1e-6)
    assert trace["figures"]["touchdown_after_land_s"] is not None


def test_the_plan_is_the_firmwares_rest_to_rest_piece():
    assert plan_point((0, 0, 0), (1, 0, 0), 2.0, 1.0)[0] == pytest.approx(0.5)  # symmetric
    assert plan_point((0, 0, 0), (1, 0, 0), 2.0, 2.5)[0] == 1.0
    # peak speed 2.1875 x distance / duration at mid-time
    dt = 1e-5
    v = (plan_point((0, 0, 0), (1, 0, 0), 2.0, 1.0 + dt)[0] - plan_point((0, 0, 0), (1, 0, 0), 2.0, 1.0)[0]) / dt
    assert v == pytest.approx(2.1875 / 2.0, rel=1e-3)


def test_the_made_mission_holds_every_point_of_the_scenario():
    scenario = Scenario.load(DATA / "p_circle_r0p5_v0p3.yaml")
    mission = scenario_mission(scenario)
    xs = [p[1] for p in scenario.setpoints]
    assert mission.arena.x[0] < min(xs) and max(xs) < mission.arena.x[1]
    assert mission.flight.height == pytest.approx(scenario.start[2])


def test_the_dry_run_chooses_the_model() -> None:
    """`dry_run.dynamics` of the mission (default firmware; first-order when it says so), `DryRun(dynamics=...)` and
    `simulated_drones`; the scenario's made mission says firmware; a bad value is a one-line error."""
    from rpf_fly.emulator.fake_world import FakeDroneConfig
    from rpf_fly.flight.dry_run import DryRun, simulated_drones
    from rpf_fly.mission.load import MissionError, parse_mission

    scenario = Scenario.load(DATA / "c_carrot_0p5.yaml")
    made = scenario_mission(scenario)
    assert made.dry_run.dynamics == "firmware"
    assert [c.vehicle.dynamics for c in simulated_drones(made).values()] == ["firmware"]
    text = made.text.replace("dry_run: {dynamics: firmware}\n", "")
    assert parse_mission(text, "m.yaml").dry_run.dynamics == "firmware"  # the default
    plain = parse_mission(text + "dry_run: {dynamics: first-order}\n", "m.yaml")
    assert plain.dry_run.dynamics == "first-order"
    assert [c.vehicle.dynamics for c in simulated_drones(plain).values()] == ["first_order"]
    given = {"cf1": FakeDroneConfig.at(0.0, 0.0, positioning="extpos", turbulence_m_s2=0.0)}
    rig = DryRun(plain, dynamics="firmware", drone_configs=given)  # not entered: nothing starts
    (config,) = rig.drone_configs.values()
    assert config.vehicle.dynamics == "firmware" and config.vehicle.turbulence_m_s2 == 0.0
    rig.close()
    with pytest.raises(MissionError) as bad:
        parse_mission(text + "dry_run: {dynamics: pid}\n", "m.yaml")
    assert "dry_run.dynamics" in str(bad.value) and "firmware" in str(bad.value)
    assert len(str(bad.value).splitlines()) == 1


def test_a_lab_of_first_order_drones_is_refused(tmp_path: Path) -> None:
    from rpf_fly.flight.lab import LabInfo
    from rpf_fly.flight.scenario_flight import ScenarioError, _check_lab_dynamics

    scenario = Scenario.load(DATA / "c_carrot_0p5.yaml")
    for dynamics, refused in (("firmware", False), ("first-order", True)):
        path = tmp_path / f"{dynamics}.yaml"
        path.write_text(scenario_mission(scenario).text.replace("dynamics: firmware", f"dynamics: {dynamics}"))
        lab = LabInfo(1, str(path), ("127.0.0.1", 1), "00", ("127.0.0.1", 2), None, {"cf1": 1}, None)
        if refused:
            with pytest.raises(ScenarioError, match="first-order model"):
                _check_lab_dynamics(lab)
        else:
            _check_lab_dynamics(lab)
    said: list[str] = []
    gone = LabInfo(1, str(tmp_path / "gone.yaml"), ("127.0.0.1", 1), "00", ("127.0.0.1", 2), None, {"cf1": 1}, None)
    _check_lab_dynamics(gone, said.append)  # cannot be read from here: flown, and said
    assert len(said) == 1 and "not checked" in said[0]


def test_the_trace_holds_the_truth_at_each_samples_instant() -> None:
    from rpf_fly.flight.scenario_flight import resample_truth

    track = [(100.0 + 0.01 * k, (0.5 * 0.01 * k, 0.0, 1.0)) for k in range(200)]  # 0.5 m/s along x
    trace = {"t": [0.0, 0.02, 0.5], "pos": [[9.0, 9.0, 9.0]] * 3}
    assert resample_truth(trace, track, 100.003)
    assert [p[0] for p in trace["pos"]] == pytest.approx([0.0015, 0.0115, 0.2515])
    late = {"t": [0.0, 5.0], "pos": [[9.0, 9.0, 9.0]] * 2}
    assert not resample_truth(late, track, 100.0) and late["pos"][0] == [9.0, 9.0, 9.0]  # not covered: kept
