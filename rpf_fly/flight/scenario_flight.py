"""``rpf-fly scenario``: fly one drone through a dynamics scenario file, through the whole stack, and trace it.

A scenario file (the format of the Crazyflie dynamics reference: `rpf_fly.emulator.cf_scenario.Scenario`, docs/
dynamics.md) is either a stream of position setpoints at ``stream_hz`` (optionally, from ``hold_at`` on, the
drone's own position: a ground station holding a drone where it is) or a list of high-level commands. Flown here
as a lab flies it: the mission's drone (or a one-drone mission made around the scenario's start,
`scenario_mission`) through cflib and the radio (a simulated drone through the fake radio in a dry run or a lab),
its pose from the mocap, extpos fed to its estimator, the emergency-stop watchdog fed from the take-off on.

- A setpoint scenario starts from a settled hover at ``start``: the drone takes off to the start's height, goes to
  the start and hovers there on streamed setpoints for `HOVER_SETTLE_S` (its integrators carry the hover thrust, as
  the reference's start state), then t = 0. After ``duration_s`` it lands.
- A command scenario starts on the floor under ``start``: the drone is armed and each command is sent at its time.

The simulated drone of a dry run flies the firmware model (`VehicleConfig.dynamics` "firmware": the firmware's PID
cascade on the identified Crazyflie 2.1+ body, docs/dynamics.md) in the reference's environment: still air (no
turbulence) and a radio that loses nothing (no loss bursts); what the stack adds stays (the radio's and the mocap's
latency, the mocap's noise, the estimator). A lab's drones fly what the lab's mission says, and a lab whose drones
do not fly the firmware model is refused.

The trace (`rpf_fly.emulator.cf_scenario` trace format, 50 Hz): ``t``, ``sp`` (the setpoint in effect; for commands
the plan: the firmware's rest-to-rest degree-7 piece from where the drone was to the command's goal), ``pos`` (the
simulated drone's true position in a dry run or lab at each sample's instant, `resample_truth`; the mocap position
of a real one), ``figures`` and, simulated, ``host_behind_s`` and ``feed_stall_s`` (`_host_verdict`).
"""

from __future__ import annotations

import bisect
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rpf_fly.emulator.cf_scenario import Scenario, figures
from rpf_fly.mission.load import parse_mission
from rpf_fly.mission.model import Mission

HOVER_SETTLE_S = 10.0
"""How long a setpoint scenario's drone hovers at the start before t = 0, as the reference's start state
(tests/data/crazyflie_dynamics/README.md, "Start states": 10 s): the height and vertical-velocity integrators,
wound up by the take-off from the floor, unwind slowly (height ki 0.5); after 6 s the drone still hovered 1.7 cm
high, after 10 s 0.6 cm (docs/dynamics.md, "The simulated drone")."""
TAKEOFF_S = 2.0
GOTO_S = 2.5
LAND_S = 2.0
SAMPLE_PERIOD_S = 0.02
EXTPOS_PERIOD_S = 0.01
FEED_STALL_S = 0.04
"""The longest wait between two extpos the ground station may feed a simulated drone during its scenario (four
frames at 100 Hz) for the figures to be evidence: the reference's drone has no latency at all, and a ground station
the host stalls for 56 ms while its drone brakes from 1 m/s lets the estimate run on the IMU there, which moved its
stop 2 cm and its settling from 0.74 s to 1.54 s (measured beside a loaded test suite, the simulated world on time).
The test suite's scenario sweep (six at a time on 2 cores) waits 20-85 ms at the longest; most flights still
match, and one that misses with a stall is flown again. A real drone's figures are the lab's mocap's to judge."""
ARENA_MARGIN_M = 1.0


class ScenarioError(RuntimeError):
    """The scenario could not be flown (no link, no pose, the drone did not take off); the message says why."""


def scenario_mission(scenario: Scenario, name: str = "cf1", uri: str = "radio://0/80/2M/E7E7E7E701") -> Mission:
    """A one-drone mission around ``scenario``: the drone standing under its start, an arena 1 m beyond every
    point it names, mocap from the NatNet emulator on 127.0.0.1 (a dry run's)."""
    points = [scenario.start] + [tuple(r[1:4]) for r in scenario.setpoints]
    points += [(r[2], r[3], r[4]) for r in scenario.commands if str(r[1]) == "go_to"]
    heights = [p[2] for p in points] + [float(r[2]) for r in scenario.commands if str(r[1]) == "takeoff"]
    xs, ys = [p[0] for p in points], [p[1] for p in points]
    height = scenario.start[2] if scenario.start[2] > 0 else max(heights + [0.5])
    sx, sy = scenario.start[0], scenario.start[1]
    text = f"""\
name: scenario-{scenario.name}
arena: {{x: [{min(xs) - ARENA_MARGIN_M:.3f}, {max(xs) + ARENA_MARGIN_M:.3f}], y: [{min(ys) - ARENA_MARGIN_M:.3f}, \
{max(ys) + ARENA_MARGIN_M:.3f}], z: [0.0, {max(heights + [height]) + ARENA_MARGIN_M:.3f}]}}
flight: {{height: {height:.3f}, speed: 0.5, rate_hz: 10, takeoff_s: {TAKEOFF_S}, land_s: {LAND_S}, timeout_s: 120}}
planner: {{kind: apf}}
mocap: {{kind: natnet, server: 127.0.0.1, rate_hz: 100}}
dry_run: {{dynamics: firmware}}
drones:
  - {{name: {name}, uri: {uri}, start: [{sx:.3f}, {sy:.3f}], goal: [{sx + 0.5:.3f}, {sy:.3f}]}}
"""
    return parse_mission(text, f"<scenario {scenario.name}>")


def plan_point(
    start: tuple[float, float, float], goal: tuple[float, float, float], duration_s: float, elapsed_s: float
) -> tuple[float, float, float]:
    """The high-level commander's rest-to-rest piece (degree 7, zero velocity, acceleration and jerk at both ends:
    crazyflie-firmware pptraj.c, planner.c) at ``elapsed_s`` into it."""
    s = min(1.0, max(0.0, elapsed_s / duration_s)) if duration_s > 0 else 1.0
    k = 35 * s**4 - 84 * s**5 + 70 * s**6 - 20 * s**7
    return (
        start[0] + (goal[0] - start[0]) * k,
        start[1] + (goal[1] - start[1]) * k,
        start[2] + (goal[2] - start[2]) * k,
    )


@dataclass
class _Plan:
    """The plan position a command scenario's sp shows: pieces (start time, start, goal, duration)."""

    floor: tuple[float, float, float]
    pieces: list[tuple[float, tuple[float, float, float], tuple[float, float, float], float]] = field(
        default_factory=list
    )

    def at(self, t_s: float) -> tuple[float, float, float]:
        current = self.floor
        for start_s, a, b, d in self.pieces:
            if t_s >= start_s:
                current = plan_point(a, b, d, t_s - start_s)
        return current

    def add(self, t_s: float, goal: tuple[float, float, float], duration_s: float) -> None:
        self.pieces.append((t_s, self.at(t_s), goal, duration_s))


class ScenarioFlight:
    """Flies ``scenario`` with drone ``name`` of ``mission`` on ``backend`` (connected here) and ``mocap``.

    ``truth(name)``: the drone's true position in a simulated world (a dry run's or a lab's), None for a real drone
    (the trace then holds the mocap position). ``on_event(message)``: each step of the flight, for the console."""

    def __init__(
        self,
        mission: Mission,
        name: str,
        scenario: Scenario,
        backend: Any,
        mocap: Any,
        uri: str,
        truth: Callable[[str], tuple[float, float, float]] | None = None,
        on_event: Callable[[str], None] = lambda message: None,
        log: Any = None,
    ) -> None:
        self.mission = mission
        self.name = name
        self.scenario = scenario
        self.backend = backend
        self.mocap = mocap
        self.uri = uri
        self.truth = truth
        self.say = on_event
        self.log = log
        drone = next(d for d in mission.drones if d.name == name)
        self.body = drone.rigid_body
        self.pose: tuple[float, float, float] | None = None
        self._last_extpos = -math.inf
        self._armed = False
        self.t0: float | None = None
        """`time.monotonic()` at the scenario's t = 0 (None before)."""
        from rpf_fly.emulator.host_lag import LagMeter

        self.feed_stall_s = 0.0
        """The longest wait between two extpos fed from t = 0 to the scenario's end (`FEED_STALL_S`)."""
        self._last_feed_s: float | None = None
        self.stream_lag = LagMeter()
        """How late each streamed setpoint left against the scenario's schedule: a ground station the host starves
        streams late, and the drone answers a late stream, not the scenario (`_host_verdict`)."""

    # ------------------------------------------------------------------------------------------- helpers

    def _spin(self, until_s: float) -> None:
        """Take mocap frames and feed extpos until ``until_s`` (monotonic)."""
        while True:
            now = time.monotonic()
            if now >= until_s:
                return
            frame = self.mocap.receive(min(0.01, until_s - now))
            if frame is None:
                continue
            body = frame.bodies.get(self.body)
            if body is None or not body.valid:
                continue
            self.pose = tuple(body.position)
            if self.log is not None:
                self.log.pose(self.name, time.time_ns(), body.position, body.quaternion)
            if frame.receive_time_s - self._last_extpos >= EXTPOS_PERIOD_S:
                self._last_extpos = frame.receive_time_s
                self.backend.send_extpos(self.name, tuple(body.position))
                self._fed(time.monotonic())

    def _fed(self, now: float) -> None:
        """Count the wait since the last extpos fed, while the scenario runs (t = 0 to its end)."""
        if self.t0 is not None and self._last_feed_s is not None and now <= self.t0 + self.scenario.duration_s:
            self.feed_stall_s = max(self.feed_stall_s, now - self._last_feed_s)
        self._last_feed_s = now

    def _position(self) -> tuple[float, float, float]:
        if self.truth is not None:
            return self.truth(self.name)
        if self.pose is None:
            raise ScenarioError(f"{self.name}: no mocap pose")
        return self.pose

    def _event(self, message: str) -> None:
        self.say(message)
        if self.log is not None:
            self.log.event(time.time_ns(), 2, f"{self.name}: {message}")

    # ---------------------------------------------------------------------------------------------- run

    def run(self) -> dict[str, Any]:
        """Connect, fly, land, close; the trace with its figures."""
        failures = self.backend.connect({self.name: self.uri})
        if failures:
            raise ScenarioError(f"{self.name}: connection failed: {failures[self.name].splitlines()[0]}")
        try:
            self._spin(time.monotonic() + 1.0)
            if self.pose is None:
                raise ScenarioError(f"{self.name}: no valid mocap pose of rigid body {self.body!r} within 1 s")
            if not self.backend.reset_estimator(self.name, self.pose, 0.0):
                raise ScenarioError(f"{self.name}: its estimator could not be reset")
            self._spin(time.monotonic() + 1.5)
            if not self.backend.arm(self.name, True):
                raise ScenarioError(f"{self.name}: arming request not delivered")
            self._spin(time.monotonic() + 0.3)
            self.backend.arm_watchdog(self.name)
            self._armed = True
            trace = self._commands() if self.scenario.is_command else self._setpoints()
        finally:
            self._land()
            self.backend.close()
        trace["figures"] = figures(trace, self.scenario)
        return trace

    def _land(self) -> None:
        if not self._armed:
            return
        state = self.backend.state(self.name)
        if self.pose is not None and self.pose[2] > 0.05:
            self.backend.land(self.name, 0.0, LAND_S)
            self._spin(time.monotonic() + LAND_S + 1.5)
        deadline = time.monotonic() + 3.0
        while time.monotonic() < deadline:
            state = self.backend.state(self.name)
            if state.supervisor is not None and not state.supervisor.flying:
                break
            self._spin(time.monotonic() + 0.1)
        self.backend.arm(self.name, False)
        self._spin(time.monotonic() + 0.3)

    def _sampler(self) -> tuple[dict[str, Any], Callable[[float, tuple[float, float, float]], None]]:
        trace: dict[str, Any] = {"name": self.scenario.name, "t": [], "sp": [], "pos": []}

        def sample(t_s: float, sp: tuple[float, float, float]) -> None:
            trace["t"].append(round(t_s, 4))
            trace["sp"].append([float(v) for v in sp])
            trace["pos"].append([float(v) for v in self._position()])

        return trace, sample

    def _setpoints(self) -> dict[str, Any]:
        s = self.scenario
        start = s.start
        self._event(f"taking off to {start[2]:.2f} m, then to the start {start} and a {HOVER_SETTLE_S:g} s hover")
        self.backend.takeoff(self.name, start[2], TAKEOFF_S)
        self._spin(time.monotonic() + TAKEOFF_S + 0.5)
        if self.pose is None or self.pose[2] < 0.5 * start[2]:
            raise ScenarioError(f"{self.name}: the take-off did not reach {start[2]:.2f} m")
        self.backend.go_to(self.name, start, 0.0, GOTO_S)
        self._spin(time.monotonic() + GOTO_S + 0.3)
        assert s.stream_hz is not None
        period = 1.0 / s.stream_hz
        settle_until = time.monotonic() + HOVER_SETTLE_S
        while time.monotonic() < settle_until:
            self.backend.send_position_setpoint(self.name, *start, 0.0)
            self._spin(min(settle_until, time.monotonic() + period))
        self._event("t = 0")
        trace, sample = self._sampler()
        t0 = self.t0 = time.monotonic()
        sp = start
        held: tuple[float, float, float] | None = None
        index = -1
        tick = 0
        next_sample = 0.0
        while True:
            t_send = tick * period
            if t_send > s.duration_s + 1e-9:
                break
            while next_sample < min(t_send, s.duration_s) - 1e-9:  # the samples before this send
                self._spin(t0 + next_sample)
                sample(next_sample, sp)
                next_sample += SAMPLE_PERIOD_S
            self._spin(t0 + t_send)
            now = time.monotonic()
            self.stream_lag.record(now - (t0 + t_send), now, period)
            if s.hold_at is not None and t_send >= s.hold_at - 1e-9:
                if held is None:
                    x, y, _ = self._position()
                    held = (x, y, sp[2])
                    self._event(f"hold where it is: ({x:.3f}, {y:.3f}, {sp[2]:.3f})")
                sp = held
            else:
                while index + 1 < len(s.setpoints) and s.setpoints[index + 1][0] <= t_send + 1e-9:
                    index += 1
                if index >= 0:
                    row = s.setpoints[index]  # (t, x, y, z)
                    sp = (row[1], row[2], row[3])
            self.backend.send_position_setpoint(self.name, *sp, 0.0)
            if self.log is not None:
                self.log.setpoint(self.name, time.time_ns(), sp)
            tick += 1
        while next_sample < s.duration_s - 1e-9:
            self._spin(t0 + next_sample)
            sample(next_sample, sp)
            next_sample += SAMPLE_PERIOD_S
        self.backend.hand_over(self.name)
        self._spin(time.monotonic() + 0.2)
        return trace

    def _commands(self) -> dict[str, Any]:
        s = self.scenario
        floor = self._position()
        plan = _Plan((floor[0], floor[1], 0.0))
        trace, sample = self._sampler()
        events = sorted((float(r[0]), r) for r in s.commands)
        t0 = self.t0 = time.monotonic()
        next_sample = 0.0
        for t_cmd, row in events + [(s.duration_s, None)]:
            while next_sample < min(t_cmd, s.duration_s) - 1e-9:
                self._spin(t0 + next_sample)
                sample(next_sample, plan.at(next_sample))
                next_sample += SAMPLE_PERIOD_S
            if row is None:
                break
            self._spin(t0 + t_cmd)
            kind = str(row[1])
            here = plan.at(t_cmd)
            if kind == "takeoff":
                height, duration = float(row[2]), float(row[3])
                x, y, _ = self._position()
                plan.floor = (x, y, 0.0)
                plan.add(t_cmd, (x, y, height), duration)
                self.backend.takeoff(self.name, height, duration)
            elif kind == "go_to":
                goal = (float(row[2]), float(row[3]), float(row[4]))
                plan.add(t_cmd, goal, float(row[5]))
                self.backend.go_to(self.name, goal, 0.0, float(row[5]))
            elif kind == "land":
                height, duration = float(row[2]), float(row[3])
                plan.add(t_cmd, (here[0], here[1], height), duration)
                self.backend.land(self.name, height, duration)
            else:
                raise ScenarioError(f"scenario {s.name}: unknown command {kind!r}")
            self._event(f"{kind} at t = {t_cmd:g} s")
        return trace


def write_json_trace(trace: dict[str, Any], path: Path | None = None) -> str:
    """The trace as one strict JSON document (no NaN or Infinity: an unsettled figure is null)."""
    import json

    def clean(value: Any) -> Any:
        if isinstance(value, float) and not math.isfinite(value):
            return None
        if isinstance(value, dict):
            return {k: clean(v) for k, v in value.items()}
        if isinstance(value, list):
            return [clean(v) for v in value]
        return value

    text = json.dumps(clean(trace), allow_nan=False)
    if path is not None:
        path.write_text(text + "\n", encoding="utf-8")
    return text


def _check_lab_dynamics(lab: Any, say: Callable[[str], None] = lambda message: None) -> None:
    """A lab's drones fly the dynamics of the mission the lab was started with (`rpf_fly.flight.dry_run`); a scenario
    is flown on the firmware model only: a lab of first-order drones is refused (ScenarioError). A lab whose mission
    file cannot be read from here (a path relative to where the lab started, a file moved since) is flown, and
    ``say`` tells so."""
    from rpf_fly.mission.load import load_mission

    try:
        dynamics = load_mission(Path(lab.mission)).dry_run.dynamics
    except Exception as err:  # noqa: BLE001 - the lab's file cannot be read from here: the lab itself cannot say
        say(
            f"the lab's mission {lab.mission} cannot be read from here ({type(err).__name__}): its drones fly the "
            "dynamics it says (dry_run.dynamics), not checked"
        )
        return
    if dynamics != "firmware":
        raise ScenarioError(
            f"the lab's drones fly the {dynamics} model (its mission {lab.mission}, dry_run.dynamics): "
            "a scenario is flown on the firmware model; start the lab with dry_run: "
            "{dynamics: firmware}"
        )


def resample_truth(trace: dict[str, Any], track: list[tuple[float, tuple[float, float, float]]], t0: float) -> bool:
    """Replace the trace's ``pos`` by the simulated world's truth at each sample's own instant (t0 + t, monotonic):
    linear between the world's 10 ms steps (`track`: its stamped truth samples). The live samples are read when
    the flight's loop gets to them, a few ms late and later still on a busy host, which a forward difference (a
    step's ``peak_speed_m_s``) turns into nonsense. False (the trace as it was) where the track does not cover the
    samples (the truth feed failed)."""
    stamps = [stamp for stamp, _ in track]
    if not stamps or any(not stamps[0] <= t0 + t <= stamps[-1] for t in (trace["t"][0], trace["t"][-1])):
        return False
    pos = []
    for t in trace["t"]:
        at = t0 + t
        i = min(max(bisect.bisect_right(stamps, at), 1), len(stamps) - 1)
        (s0, p0), (s1, p1) = track[i - 1], track[i]
        w = (at - s0) / (s1 - s0) if s1 > s0 else 0.0
        pos.append([a + (b - a) * w for a, b in zip(p0, p1)])
    trace["pos"] = pos
    return True


def _host_verdict(trace: dict[str, Any], rig: Any, flight: ScenarioFlight) -> None:
    """``host_behind_s`` in the trace: how long the host let the simulated world fall behind its time during the
    flight (`rpf_fly.emulator.host_lag`: a late world step or mocap frame is time the drone did not have: extpos
    late, the estimate drifting blind, a setpoint watchdog firing), or the ground station's setpoint stream fall
    behind the scenario's schedule (`ScenarioFlight.stream_lag`: the drone then answers a late stream), whichever
    is longer; from `HOST_BEHIND_REPORT_S` on an event says the figures are not evidence."""
    from rpf_fly.emulator.host_lag import HOST_BEHIND_REPORT_S

    try:
        behind = float(rig.host_lag().behind_s)
    except Exception:  # noqa: BLE001 - the world is gone or cannot say: no verdict
        return
    behind = max(behind, flight.stream_lag.snapshot().behind_s)
    trace["host_behind_s"] = behind
    trace["feed_stall_s"] = round(flight.feed_stall_s, 4)
    if behind >= HOST_BEHIND_REPORT_S:
        flight._event(
            f"the host could not keep up for {behind:.1f} s (simulated steps, mocap frames or streamed setpoints "
            "late): these figures are not evidence"
        )
    elif flight.feed_stall_s > FEED_STALL_S:
        flight._event(
            f"the ground station fed no extpos for {flight.feed_stall_s * 1000:.0f} ms (the host stalled it; "
            f"over {FEED_STALL_S * 1000:.0f} ms): these figures are not evidence"
        )


def run_scenario(
    scenario: Scenario,
    mission: Mission,
    name: str,
    *,
    dry_run: bool,
    lab: Any = None,
    log_path: Path | None = None,
    on_event: Callable[[str], None] = lambda m: None,
) -> dict[str, Any]:
    """Fly ``scenario`` with drone ``name`` of ``mission``: on a private simulated drone (``dry_run``), on a running
    lab's (``lab``: its `rpf_fly.flight.lab.LabInfo`), else on the real one with the mission's mocap. Logs as a
    flight (``log_path``: poses, setpoints, events and, simulated, the truth). Returns the trace."""
    from rpf_fly.flight.session import DEFAULT_TOC_CACHE, mocap_source
    from rpf_fly.flight.truth import TruthFeed
    from rpf_fly.log.metadata import mission_metadata, scenario_metadata
    from rpf_fly.log.writer import FlightLog
    from rpf_fly.radio.cflib_backend import CflibBackend

    drone = next((d for d in mission.drones if d.name == name), None)
    if drone is None:
        raise ScenarioError(f"--drone {name}: not a drone of the mission ({', '.join(d.name for d in mission.drones)})")
    one = mission.__class__(**{**mission.__dict__, "drones": (drone,)}) if len(mission.drones) > 1 else mission
    rig: Any = None
    log = None
    feed = None
    truth: Callable[[str], tuple[float, float, float]] | None = None  # a simulated drone's true position
    try:
        if dry_run or lab is not None:
            from rpf_fly.flight.dry_run import DryRun

            if lab is not None:
                _check_lab_dynamics(lab, on_event)
                rig = DryRun(one, lab=lab).__enter__()
            else:
                from rpf_fly.emulator.fake_world import FakeDroneConfig

                still = FakeDroneConfig.at(
                    drone.start[0], drone.start[1], 0.0, positioning="extpos", turbulence_m_s2=0.0
                )
                rig = DryRun(one, dynamics="firmware", drone_configs={name: still}, radio_loss=None).__enter__()
            backend, mocap, uri = CflibBackend.for_mission(one, rig.cache_dir), rig.mocap, rig.uris[name]
            address = rig.addresses[name]
            world = rig.world

            def true_position(_: str) -> tuple[float, float, float]:
                x, y, z = world.true_poses()[address][0]
                return x, y, z

            truth = true_position
        else:
            backend, mocap, uri = CflibBackend.for_mission(one, DEFAULT_TOC_CACHE), mocap_source(one), drone.uri
        if log_path is not None:
            meta = mission_metadata(one, 0, source="scenario")
            meta["scenario"] = scenario.name
            log = FlightLog(log_path, meta, scenario_metadata(one))
        truth_track: list[tuple[float, tuple[float, float, float]]] = []
        if rig is not None:
            offset_ns = time.time_ns() - time.monotonic_ns()

            def sink(stamp: float, states: dict[str, Any]) -> None:
                if log is not None:
                    log.truth(offset_ns + int(stamp * 1e9), states)
                state = states.get(name)
                if state is not None:
                    truth_track.append((stamp, tuple(state[0])))

            feed = TruthFeed(rig.truth_samples, sink).start()
        flight = ScenarioFlight(one, name, scenario, backend, mocap, uri, truth=truth, on_event=on_event, log=log)
        trace = flight.run()
        if feed is not None and flight.t0 is not None:
            feed.stop()  # its last fetch: the world's truth up to now
            if resample_truth(trace, truth_track, flight.t0):
                trace["figures"] = figures(trace, scenario)
        if rig is not None:
            _host_verdict(trace, rig, flight)
        return trace
    finally:
        if feed is not None:
            feed.stop()
        if log is not None:
            log.close()
        if rig is not None:
            rig.close()
        elif "mocap" in locals() and mocap is not None:
            mocap.close()
