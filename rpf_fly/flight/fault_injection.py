"""Applying a fault schedule (:mod:`rpf_fly.flight.faults`) to a dry run.

Power-on faults shape the simulated drones before the flight (:meth:`FaultInjection.start_faults`); planner faults
wrap the named drone's own planner (:meth:`FaultInjection.planner_factory`); a loop stall blocks the loop thread
inside its mocap wait (:class:`StallableMocap`); a dongle unplug fails the fake radio's links of that dongle in this
process (:func:`rpf_fly.emulator.fake_radio.unplug`); a ground station kill SIGKILLs this process; everything else
is a hook of the simulated world, called from a thread of its own at its time.

The clock of a fault starts when the swarm enters its planning phase (``swarm: flying``), except a
``ground_station_kill``'s, which starts at its ``at_phase``: the take-off commands sent (``take-off commanded``),
the settle (the mission's ``takeoff_s`` after that), the planning phase, or the landing phase (``swarm: landing``).
The injection thread reads those moments from the flight's events as the loop emits them, from the take-off on.
Each fault, when it is applied, is an info event (kind ``fault``) in the flight log, so a review or the campaign
knows when it struck (a ground station kill's comes just before the kill, and reaches the text log and stderr; the
MCAP log is cut wherever the kill finds it); the stack's own reaction is whatever events it raises.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Callable
from typing import Any

from rpf_fly.flight.events import INFO, FlightEvent
from rpf_fly.flight.faults import LOW_BATTERY_OPEN_CIRCUIT_V, Fault
from rpf_fly.flight.phases import SwarmPhase
from rpf_fly.mission.model import Drone, Mission
from rpf_fly.mocap.frame import MocapFrame, MocapSource

__all__ = ["FaultInjection", "StallableMocap"]


class StallableMocap:
    """A mocap source whose :meth:`receive` can be made to block (the flight loop's thread waits in it): the
    ``loop_stall`` fault, without a hook in the flight loop."""

    def __init__(self, source: MocapSource):
        self.source = source
        self._stall_s = 0.0
        self._hold_s = 0.0

    def stall(self, seconds: float) -> None:
        """The next wait blocks ``seconds`` before it reads a frame (the frame it then hands over is fresh)."""
        self._stall_s = seconds

    def hold(self, seconds: float) -> None:
        """The next frame read is handed over ``seconds`` later (the ground station held back between reading a
        frame and using it: a host that deschedules it, a long garbage collection): its poses are that old."""
        self._hold_s = seconds

    def receive(self, timeout_s: float) -> MocapFrame | None:
        if self._stall_s > 0.0:
            seconds, self._stall_s = self._stall_s, 0.0
            time.sleep(seconds)
        frame = self.source.receive(timeout_s)
        if frame is not None and self._hold_s > 0.0:
            seconds, self._hold_s = self._hold_s, 0.0
            time.sleep(seconds)
        return frame

    def close(self) -> None:
        self.source.close()

    def __getattr__(self, name: str) -> Any:
        return getattr(self.source, name)


class _FaultyPlanner:
    """A drone's own planner with its scheduled faults: raising from ``at_s`` on, or blocking once."""

    def __init__(self, planner: Any, faults: list[Fault], clock: Callable[[], float | None]):
        self.planner = planner
        self.faults = faults
        self._clock = clock
        self._hung: set[int] = set()

    def step(self, view: Any) -> Any:
        t = self._clock()
        if t is not None:
            for i, fault in enumerate(self.faults):
                if t < (fault.at_s or 0.0):
                    continue
                if fault.kind == "planner_error":
                    raise RuntimeError(f"injected planner error (fault at {fault.at_s:g} s)")
                if fault.kind == "planner_hang" and i not in self._hung:
                    self._hung.add(i)
                    time.sleep(fault.duration_s or 0.0)
        return self.planner.step(view)


def _kill_this_process() -> None:
    os.kill(os.getpid(), signal.SIGKILL)


class FaultInjection:
    """One schedule applied to one dry run (see the module docstring). ``kill``: what a ``ground_station_kill``
    does (default: SIGKILL of this process; a test may pass its own)."""

    POLL_S = 0.05
    """How often the injection thread looks whether the flight ended while it waits."""

    def __init__(self, mission: Mission, faults: list[Fault], kill: Callable[[], None] | None = None):
        self.mission = mission
        self.faults = faults
        self.t0: float | None = None
        """``time.monotonic()`` at the start of the planning phase (None before)."""
        self.phases: dict[str, float] = {}
        """``time.monotonic()`` at the start of each phase a fault may count from (`faults.GROUND_STATION_PHASES`)
        that the flight reached so far."""
        self.applied: list[tuple[float, Fault]] = []
        self._kill = kill or _kill_this_process
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._lock = threading.Lock()

    # ------------------------------------------------------------------------------------------ before

    def start_faults(self) -> dict[str, Any]:
        """The power-on faults (``yaw_offset``, ``start_offset``, ``upside_down``, ``motor_fault``) as
        ``DryRun(start_faults=...)`` takes them."""
        from dataclasses import replace

        from rpf_fly.flight.dry_run import StartFault

        faults: dict[str, Any] = {}
        for f in self.faults:
            if f.at_s is not None or f.drone is None:
                continue
            current = faults.get(f.drone, StartFault())
            if f.kind == "yaw_offset":
                current = replace(current, yaw_deg=f.params["deg"])
            elif f.kind == "start_offset":
                current = replace(current, offset_m=tuple(f.params["offset_m"]))
            elif f.kind == "upside_down":
                current = replace(current, upside_down=True)
            elif f.kind == "motor_fault":
                current = replace(current, motor_fault=True)
            else:
                continue
            faults[f.drone] = current
        return faults

    def planner_factory(self, base: Callable[[Drone], Any]) -> Callable[[Drone], Any]:
        """``base`` with the planner faults of each drone wrapped around its own planner."""

        def factory(drone: Drone) -> Any:
            mine = [f for f in self.faults if f.drone == drone.name and f.kind in ("planner_error", "planner_hang")]
            planner = base(drone)
            return _FaultyPlanner(planner, mine, self.elapsed) if mine else planner

        return factory

    def elapsed(self) -> float | None:
        """Seconds since the planning phase started (None before)."""
        return None if self.t0 is None else time.monotonic() - self.t0

    # ------------------------------------------------------------------------------------------ during

    def start(self, loop: Any, rig: Any) -> None:
        """Start applying the timed faults, each at its time in ``loop``'s phases (call from the flight's
        ``on_loop``, before the loop runs: the phases are read from its events)."""
        if not isinstance(rig.mocap, StallableMocap):
            raise RuntimeError("wrap the rig's mocap in StallableMocap before the flight starts (FaultInjection.wrap)")
        loop.events.subscribe(self._on_event)
        self._thread = threading.Thread(target=self._run, args=(loop, rig), name="rpf-fly-faults", daemon=True)
        self._thread.start()

    def _on_event(self, event: FlightEvent) -> None:
        """The flight's events (in the thread that emits them): the phases' starts."""
        now = time.monotonic()
        found: dict[str, float] = {}
        if event.kind == "takeoff" and event.drone is None and event.message.startswith("take-off commanded"):
            found = {"takeoff": now, "settle": now + self.mission.flight.takeoff_s}
        elif event.kind == "phase" and event.message == f"swarm: {SwarmPhase.FLYING.value}":
            found = {"planning": now}
        elif event.kind == "phase" and event.message.startswith(f"swarm: {SwarmPhase.LANDING.value}"):
            found = {"landing": now}
        if not found:
            return
        with self._lock:
            for phase, t in found.items():
                self.phases.setdefault(phase, t)
            if "planning" in found and self.t0 is None:
                self.t0 = found["planning"]
        self._wake.set()

    @staticmethod
    def wrap(rig: Any) -> None:
        """Give the rig a stallable mocap source (before the flight is assembled)."""
        if not isinstance(rig.mocap, StallableMocap):
            rig.mocap = StallableMocap(rig.mocap)

    def close(self) -> None:
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)

    def due(self, fault: Fault) -> float | None:
        """When ``fault`` is due (``time.monotonic()``): ``at_s`` after the start of its phase; None while the
        flight has not reached that phase."""
        with self._lock:
            start = self.phases.get(fault.phase)
        return None if start is None else start + (fault.at_s or 0.0)

    def _run(self, loop: Any, rig: Any) -> None:
        pending = [f for f in self.faults if f.at_s is not None]  # in schedule order: a tie goes to the first
        while pending:
            self._wake.clear()
            if self._stop.is_set() or loop.phase in (SwarmPhase.DONE, SwarmPhase.ABORTED):
                return
            times = [(t, i) for i, f in enumerate(pending) if (t := self.due(f)) is not None]
            now = time.monotonic()
            if not times or min(times)[0] > now:
                self._wake.wait(min([self.POLL_S] + [t - now for t, _ in times]))
                continue
            fault = pending.pop(min(times)[1])
            if fault.kind == "ground_station_kill":
                self._kill_ground_station(fault, loop)
                continue
            try:
                self._apply(fault, loop, rig)
            except Exception as err:  # noqa: BLE001 - an injection that fails is reported, the flight goes on
                loop.events.emit(INFO, "fault", f"could not inject {fault.kind}: {err}", fault.drone)
                continue
            self.applied.append((time.monotonic(), fault))
            what = ", ".join(f"{k} {v}" for k, v in fault.params.items())
            span = f" for {fault.duration_s:g} s" if fault.duration_s else ""
            loop.events.emit(INFO, "fault", f"injected {fault.kind}{span}{': ' + what if what else ''}", fault.drone)

    def _kill_ground_station(self, fault: Fault, loop: Any) -> None:
        """The ground station dies at once: one event (the text log and stderr have it; the MCAP log's writer may
        not get to write it), then SIGKILL. Nothing after it runs: no landing, no disconnect, no log close; the
        drones are left to their firmware (its emergency-stop watchdog, fed from each take-off on)."""
        self.applied.append((time.monotonic(), fault))
        loop.events.emit(
            INFO,
            "fault",
            f"injected ground_station_kill at {fault.phase} + {fault.at_s or 0.0:g} s: "
            "SIGKILL of this ground station (no landing, no log close)",
        )
        self._kill()

    def _apply(self, fault: Fault, loop: Any, rig: Any) -> None:
        kind, name, seconds, p = fault.kind, fault.drone, fault.duration_s or 0.0, fault.params
        if kind == "occlusion":
            rig.hide(name, seconds)
        elif kind == "blackout":
            rig.blackout(seconds)
        elif kind == "pose_jump":
            rig.pose_jump(name, p["offset_m"], seconds)
        elif kind == "orientation_flip":
            rig.orientation_flip(name, p["deg"], seconds)
        elif kind == "mocap_delay":
            rig.mocap_delay(p["delay_s"], seconds)
        elif kind == "link_drop":
            rig.world.drop_link(rig.addresses[name])
        elif kind == "packet_loss":
            rig.packet_loss(name, p["rate"], seconds)
        elif kind == "low_battery":
            rig.world.set_battery(rig.addresses[name], LOW_BATTERY_OPEN_CIRCUIT_V)
        elif kind == "loop_stall":
            rig.mocap.stall(seconds)
        elif kind == "gust":
            rig.gust(name, p["accel"], seconds)
        elif kind == "estimator_divergence":
            rig.estimator_divergence(name, p["rate_m_s"])
        elif kind == "reboot":
            rig.reboot(name)
        elif kind == "dongle_unplug":
            from rpf_fly.emulator import crazyradio, fake_radio

            fake_radio.unplug(p["dongle"])
            crazyradio.pull_out(p["dongle"])  # an emulated Crazyradio of that number (dry_run.radio: crazyradio)
        elif kind in ("planner_error", "planner_hang"):
            pass  # the drone's planner wrapper acts at its time (planner_factory)
        else:
            raise ValueError(f"no injection for {kind!r}")
