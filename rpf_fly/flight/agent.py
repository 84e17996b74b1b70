"""One drone's flight logic: its phase, its OWN planner, and the setpoint it streams.

Isolation: every drone has its own planner instance and plans only from its own local view (neighbours and
obstacles within its sensing range, its own goal). A planner call that raises, returns no finite direction, or
takes longer than the budget is a planner fault for that drone alone: it holds and lands, the others fly on. The
budget is measured in CPU time of the calling thread (``time.thread_time``): a drone is blamed for the computing its
planner did, not for the time the loop thread waited for the GIL or the operating system (a dry run saw a 51.6 ms
wall-clock stall inside one batched call of 10 drones that computes for ~0.3 ms).

Setpoints: the planner gives a direction; the drone should move at the mission speed along it. Streaming
``measured + v dt d`` would make a position controller crawl (its lag eats the step), so the agent integrates a
reference ``ref += v dt d`` (a carrot) that never leads the measured position by more than ``max_lead`` and never
leaves the arena (the geofence clamps every setpoint). Planar vectors are complex.

Planning on the commanded geometry: the position controller tracks the reference with a lag (in steady state the
drone trails its reference by ``v * tau``). Planning from the measured pose would close the avoidance loop on a
picture ``tau`` seconds old, and two drones that cross then pass closer than the planner chose (dry runs of lab-3
came within 0.186 m with 2r = 0.2 m). So the agent plans from its own reference, as the simulator's kinematic drone
does, and sees each neighbour where its reference should be: the measured position plus its measured velocity times
this drone's own observed lag (``|ref - measured| / v``, which needs no model of the vehicle and no message from the
neighbour). Goal arrival and every safety check still use the measured pose.
"""

from __future__ import annotations

import math
import queue
import threading
import time
from collections.abc import Callable, Mapping
from concurrent.futures import Future
from dataclasses import dataclass
from typing import Protocol, TypeVar

import numpy as np

from rpf_fly.flight.phases import DronePhase, FlightOutcome
from rpf_fly.flight.response import ResponseGains, braking_for
from rpf_fly.mission.model import Arena, Drone, Mission
from rpf_fly.planning.planner import PlanStep, plan_row
from rpf_fly.planning.view import LocalView
from rpf_fly.radio.budget import radio_loads

T = TypeVar("T", complex, np.ndarray)

REFINE_HOLD_ABOVE_M_S = 0.05
"""A held drone slower than this is at rest: its hold setpoint stays (`DroneAgent.refine_hold`)."""
LEAD_ALLOWANCE = 1.25
"""How far a drone's carrot may lead it, over its steady lag at the mission speed (`DroneAgent.set_controller`)."""
MIN_LEAD_M = 0.3
"""The carrot's lead is never held under this (a slow mission's drone still gets a firm pull)."""


def link_lags_s(mission: Mission) -> dict[str, float]:
    """Drone name -> how long a setpoint takes from its planning tick to the drone, as the radio budget models the
    drone's dongle (`DongleLoad.setpoint_p50_s`: cflib's shared radio thread, the other links' turns, retries;
    rpf_fly/radio/budget.py); 0 where the model has no figure. A neighbour flies the setpoint it was sent that long
    ago, so its newest setpoint leads it by that much more than its controller's lag (`DroneAgent.prediction`)."""
    return {
        name: load.setpoint_p50_s if math.isfinite(load.setpoint_p50_s) else 0.0
        for load in radio_loads(mission)
        for name in load.drones
    }


def carrot_max_lead_m(speed_m_s: float, gains: ResponseGains) -> float:
    """How far a drone's carrot may lead it at ``speed_m_s`` (`DroneAgent.set_controller`): `LEAD_ALLOWANCE` times
    its steady lag at that speed, never under `MIN_LEAD_M`."""
    return max(MIN_LEAD_M, LEAD_ALLOWANCE * speed_m_s * gains.steady_lag_s)


class PlannerLike(Protocol):
    def step(self, view: LocalView) -> PlanStep: ...


class PlannerFault(RuntimeError):
    """A drone's planner raised, returned garbage, or ran over its time budget."""


MAX_DIRECTION_NORM = 1.0 + 1e-6
"""A planner's direction is at most a unit vector (this rounding allowed); one call or a batched row alike."""


def check_direction(direction: complex) -> None:
    """A planner's direction must be finite and at most a unit vector; else it is a :class:`PlannerFault`."""
    if not (math.isfinite(direction.real) and math.isfinite(direction.imag)) or abs(direction) > MAX_DIRECTION_NORM:
        raise PlannerFault(f"planner returned an invalid direction {direction!r}")


class PlannerWorker:
    """One drone's planner on a daemon thread of its own. :meth:`submit` hands it a view and returns at once with a
    :class:`~concurrent.futures.Future` of ``(step, direction, cpu seconds)`` (or of its :class:`PlannerFault`), so a
    tick can hand every such drone its view first and wait for them together, and stream the drones that answered
    without waiting for one that did not. A call that never answers is left to finish (or never) on its own, and
    its late answer is dropped by whoever gave up on it. Daemon: a planner stuck for good must not keep the process
    alive."""

    def __init__(self, step: Callable[[LocalView], tuple[PlanStep, complex, float]], name: str):
        self._step = step
        self._requests: queue.Queue[tuple[LocalView, Future] | None] = queue.Queue()
        self._current: Future | None = None
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    @property
    def busy(self) -> bool:
        """Whether the last call submitted has not answered yet."""
        return self._current is not None and not self._current.done()

    def submit(self, view: LocalView) -> Future:
        """Hand ``view`` to the planner's thread; raises :class:`PlannerFault` while an earlier call still runs."""
        if self.busy:
            raise PlannerFault("planner still busy with an earlier call")
        future: Future = Future()
        self._current = future
        self._requests.put((view, future))
        return future

    def close(self) -> None:
        self._requests.put(None)

    def _run(self) -> None:
        while (request := self._requests.get()) is not None:
            view, future = request
            try:
                future.set_result(self._step(view))
            except BaseException as err:  # noqa: BLE001 - handed to the caller
                future.set_exception(err if isinstance(err, PlannerFault) else PlannerFault(f"planner raised {err!r}"))


@dataclass
class PlanResult:
    """One planning tick of one drone: its setpoint, the planner's seconds (its share of a batched call), and the
    planner's step for the log. A batched call's row is cut out only when :attr:`step` is read, after the sends."""

    setpoint: complex
    seconds: float
    planned: PlanStep
    row: int | None = None
    """None: ``planned`` is this drone's own one-drone step; else its row in the batched ``planned``."""

    @property
    def step(self) -> PlanStep:
        return self.planned if self.row is None else plan_row(self.planned, self.row)


class DroneAgent:
    """A drone as the flight loop sees it."""

    def __init__(
        self,
        drone: Drone,
        planner: PlannerLike,
        *,
        height: float,
        speed: float,
        dt: float,
        arena: Arena,
        budget_s: float,
        body_radius_m: float = 0.0,
        max_lead_m: float | None = None,
        link_lag_s: float = 0.0,
        clock: Callable[[], float] = time.thread_time,
    ):
        self.drone = drone
        self.name = drone.name
        self.planner = planner
        self.goal = complex(*drone.goal)
        self.start = complex(*drone.start)
        self.height = height
        self.speed = speed
        self.dt = dt
        self.arena = arena
        self.budget_s = budget_s
        self.body_radius_m = body_radius_m
        inset = [
            (lo + body_radius_m, hi - body_radius_m) if hi - lo > 2 * body_radius_m else ((lo + hi) / 2,) * 2
            for lo, hi in (arena.x, arena.y, arena.z)
        ]
        self._fence = tuple(inset)
        self._max_lead_given_m = max_lead_m
        """How far the carrot may lead the drone when the caller fixed it; None: from the drone's steady lag."""
        self.link_lag_s = link_lag_s
        """How late its radio delivers a setpoint (`link_lags_s`): its neighbours' setpoints lead them by that much
        more (`prediction`; the swarm shares its dongles' kind of traffic)."""
        self.braking = braking_for(None)
        self.max_lead_m = MIN_LEAD_M
        self.acceleration_lead_s2 = 0.0
        """How far its neighbours' setpoints lead them per m/s^2 of their acceleration (`predict`)."""
        self.first_order = False
        """A dry run's first-order simulated drone (`set_controller`)."""
        self.set_controller(None)
        """How this drone comes to rest once held, from its own controller's gains (`set_controller`)."""
        self._clock = clock
        self.phase = DronePhase.WAITING
        self.outcome: FlightOutcome | None = None
        self.reason = ""
        self.heading = 1 + 0j
        self.reference = self.start
        self.hold_point: complex = self.start
        self._hold_limit: complex = self.start
        self._hold_way: complex = 0j
        self.phase_since_s = 0.0
        self.arrived_at_s: float | None = None
        self.stale_since_s: float | None = None
        self.landing_until_s: float | None = None
        self.touchdown_s: float | None = None
        """When its landing's descent ends (the land command's duration from when it was sent)."""
        self._worker: PlannerWorker | None = None
        self.planned_from: complex = self.start
        """The reference its newest planning step planned from (its own position in that view), for the log:
        a replay restarts a drone's planning from it (rpf_fly/flight/replay.py)."""
        self.last_setpoint: complex | None = None
        """The last position setpoint streamed to it (x + iy), for the supervisor's tracking check."""

    @classmethod
    def for_mission(cls, drone: Drone, planner: PlannerLike, mission: Mission, **overrides: object) -> DroneAgent:
        """The agent the flight loop flies ``drone`` with (height, speed, step, arena, budget and body radius from
        the mission); ``overrides`` replace keyword arguments (``rpf-fly replay`` lifts the time budget)."""
        flight = mission.flight
        kwargs: dict = dict(
            height=flight.height,
            speed=flight.speed,
            dt=flight.dt,
            arena=mission.arena,
            budget_s=mission.safety.planner_budget_s,
            body_radius_m=mission.planner.safety_radius,
            link_lag_s=link_lags_s(mission).get(drone.name, 0.0),
        )
        kwargs.update(overrides)
        return cls(drone, planner, **kwargs)

    # ------------------------------------------------------------------------------------------ phases

    def set_phase(self, phase: DronePhase, now_s: float, reason: str = "") -> None:
        """Called by :class:`rpf_fly.flight.commander.Commander` only: it owns the phase (with the command that goes
        with each change)."""
        self.phase = phase
        self.phase_since_s = now_s
        if reason:
            self.reason = reason

    def begin_planning(self, measured: complex, now_s: float) -> None:
        """Start planning from the measured position, heading for the goal (paper: the initial heading points at
        the goal)."""
        self.reference = measured
        delta = self.goal - measured
        self.heading = delta / abs(delta) if abs(delta) > 1e-9 else 1 + 0j
        self.set_phase(DronePhase.PLANNING, now_s)

    def set_controller(self, params: Mapping[str, float] | None, first_order: bool = False) -> None:
        """The drone's position controller's gains as its parameters hold them (None: the firmware's defaults): how
        it brakes, how far its carrot may lead it (`LEAD_ALLOWANCE` times the steady lag at the mission speed:
        a drone trails a moving setpoint by `ResponseGains.steady_lag_s` x speed, 0.55 s with the defaults, and a
        carrot held closer than that caps its speed below the mission's), and how far ahead of an accelerating
        neighbour its setpoint is (`ResponseGains.acceleration_lead_s2`; the swarm flies one kind of controller).
        ``first_order``: a dry run's first-order simulated drone, whose setpoint leads it by its speed alone."""
        self.braking = braking_for(params)
        self.first_order = first_order
        self.acceleration_lead_s2 = 0.0 if first_order else self.braking.gains.acceleration_lead_s2
        if self._max_lead_given_m is not None:
            self.max_lead_m = self._max_lead_given_m
        else:
            self.max_lead_m = carrot_max_lead_m(self.speed, self.braking.gains)

    def hold(self, at: complex, now_s: float, reason: str, velocity: complex = 0j) -> None:
        """Stop planning and bring the drone to rest near ``at`` (where it is), moving at ``velocity``: the hold
        setpoint is the one its own controller stops it nearest with (`Braking.hold_point`: a real drone held where
        it is flies past that point, by its braking distance)."""
        self.hold_point = self.clamp(self.braking.hold_point(at, velocity, self.last_setpoint))
        self._hold_limit = self.braking.stop_point(at, velocity, self.last_setpoint)
        self._hold_way = velocity / abs(velocity) if abs(velocity) > 1e-3 else 0j
        self.set_phase(DronePhase.HOLDING, now_s, reason)

    def refine_hold(self, position: complex, velocity: complex) -> None:
        """While a held drone still moves: the hold setpoint that brings it to rest from here (`Braking.hold_point`
        from its present speed and tilt), never beyond where the hold was to stop it. The first hold setpoint brakes
        it hardest, often behind where it stops; moved up as it slows, the drone stops where it braked to instead
        of flying back to it."""
        if self.phase != DronePhase.HOLDING or not self._hold_way or abs(velocity) < REFINE_HOLD_ABOVE_M_S:
            return
        if (velocity * self._hold_way.conjugate()).real <= 0.0:
            return  # braked to a stop already, or turned: keep the point
        way = self._hold_way
        point = self.braking.hold_point(position, velocity, self.hold_point)
        beyond = ((point - self._hold_limit) * way.conjugate()).real
        if beyond > 0.0:
            point -= way * beyond
        if ((point - self.hold_point) * way.conjugate()).real > 0.0:  # only ever forward along its way
            self.hold_point = self.clamp(point)

    # ---------------------------------------------------------------------------------------- planning

    def plan(self, view: LocalView, measured: complex) -> PlanResult:
        """One guarded planning step from this drone's own view, inline; raises :class:`PlannerFault`. A planner
        that may block runs on the drone's own thread instead (:meth:`submit`, flight/swarm_plan.py)."""
        return self.finish(self._step(view), measured)

    def submit(self, view: LocalView) -> Future:
        """Start a planning step on this drone's own worker thread (see :class:`PlannerWorker`); take its answer
        with :meth:`finish`. Raises :class:`PlannerFault` while an earlier call still runs."""
        return self._worker_of().submit(view)

    def finish(self, answer: tuple[PlanStep, complex, float], measured: complex) -> PlanResult:
        """Check a planner's answer (direction, CPU-time budget) and take it: raises :class:`PlannerFault`."""
        step, direction, seconds = answer
        check_direction(direction)
        if seconds > self.budget_s:
            raise PlannerFault(f"planner took {seconds * 1e3:.1f} ms (budget {self.budget_s * 1e3:.0f} ms)")
        return self.accept(step, direction, measured, seconds)

    def _worker_of(self) -> PlannerWorker:
        if self._worker is None:
            self._worker = PlannerWorker(self._step, f"rpf-fly-planner-{self.name}")
        return self._worker

    def _step(self, view: LocalView) -> tuple[PlanStep, complex, float]:
        """The planner's call, timed in CPU time of the thread that runs it."""
        started = self._clock()
        try:
            step = self.planner.step(view)
            direction = complex(step.direction)
        except Exception as err:  # noqa: BLE001 - any planner failure is this drone's fault only
            raise PlannerFault(f"planner raised {type(err).__name__}: {err}") from err
        return step, direction, self._clock() - started

    def close(self) -> None:
        """Let this drone's planner worker thread (if any) end."""
        if self._worker is not None:
            self._worker.close()

    def accept(
        self, step: PlanStep, direction: complex, measured: complex, seconds: float, row: int | None = None
    ) -> PlanResult:
        """Take a checked planning result (from :meth:`plan`, or row ``row`` of a batched call): turn the heading
        and move the reference."""
        self.planned_from = self.reference
        if abs(direction) > 0:
            self.heading = direction / abs(direction)
        return PlanResult(self.advance(direction, measured), seconds, step, row)

    def tracking_lag_s(self, measured: complex) -> float:
        """This drone's observed tracking lag: how far its reference leads it, in seconds at the mission speed."""
        if self.speed <= 0.0:
            return 0.0
        return min(abs(self.reference - measured), self.max_lead_m) / self.speed

    def predict(self, xy: T, velocity: T, acceleration: T, measured: complex) -> T:
        """Where this drone plans its neighbours to be: where their setpoints are, as far as mocap can tell (a swarm
        flies one controller; docs/flight.md, "Where a neighbour is"): ahead of where they are by the controller's
        steady lag plus the radio's setpoint latency (`link_lag_s`) times their velocity and `acceleration_lead_s2`
        times their acceleration. A dry run's first-order drone (`set_controller`): by this drone's own observed lag
        times their velocity. Why not their
        measured positions: this drone plans its own setpoint, which leads it, so setpoints are kept apart against
        setpoints; and a neighbour speeding up from a stop has its setpoint far ahead of what its speed says."""
        lag_s, lead_s2 = self.prediction(measured)
        return xy + lag_s * velocity + lead_s2 * acceleration

    def prediction(self, measured: complex) -> tuple[float, float]:
        """`predict`'s two factors: (seconds of velocity, seconds squared of acceleration)."""
        if self.first_order:
            return self.tracking_lag_s(measured), 0.0
        return self.braking.gains.steady_lag_s + self.link_lag_s, self.acceleration_lead_s2

    def advance(self, direction: complex, measured: complex) -> complex:
        """Move the reference one step along ``direction``; keep it within ``max_lead`` of the drone and inside
        the arena."""
        ref = self.reference + self.speed * self.dt * direction
        lead = ref - measured
        if abs(lead) > self.max_lead_m:
            ref = measured + lead * (self.max_lead_m / abs(lead))
        self.reference = self.clamp(ref)
        return self.reference

    def next_setpoint(self, measured: complex) -> complex | None:
        """The setpoint this drone may be streamed next, at the farthest: a planning drone's reference one more
        step along its heading (`advance`, within ``max_lead_m`` of ``measured``), else the last one streamed. The
        separation and clearance checks predict a planning drone's stop from it: a setpoint that goes out between
        two of their passes drives the drone until a hold decided after it reaches it (a pair resuming from rest
        at 0.4 m apart: each step's carrot 0.1 m further on drove them 4 cm past the stop the last one predicted)."""
        if self.phase != DronePhase.PLANNING or self.last_setpoint is None:
            return self.last_setpoint
        ref = self.reference + self.speed * self.dt * self.heading
        lead = ref - measured
        if abs(lead) > self.max_lead_m:
            ref = measured + lead * (self.max_lead_m / abs(lead))
        return self.clamp(ref)

    def clamp(self, xy: complex) -> complex:
        """The geofence: a setpoint keeps the drone's whole body (a disc of ``body_radius_m``, the mission's safety
        radius) inside the arena, not only its centre."""
        (x0, x1), (y0, y1) = self._fence[0], self._fence[1]
        return complex(min(max(xy.real, x0), x1), min(max(xy.imag, y0), y1))

    def clamp_height(self, z: float) -> float:
        """The geofence in height: the body stays under the arena's ceiling (and over its floor)."""
        z0, z1 = self._fence[2]
        return min(max(z, z0), z1)
