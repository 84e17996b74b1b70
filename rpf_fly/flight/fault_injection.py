"""Applying a fault schedule (:mod:`rpf_fly.flight.faults`) to a dry run.

Power-on faults shape the simulated drones before the flight (:meth:`FaultInjection.start_faults`); planner faults
wrap the named drone's own planner (:meth:`FaultInjection.planner_factory`); a loop stall blocks the loop thread
inside its mocap wait (:class:`StallableMocap`); everything else is a hook of the simulated world, called from a
thread of its own at its time. The clock starts when the swarm enters its planning phase. Each fault, when it is
applied, is an info event (kind ``fault``) in the flight log, so a review or the campaign knows when it struck; the
stack's own reaction is whatever events it raises.
"""

from __future__ import annotations

import threading
import time
from typing import Any, Callable, Optional

from rpf_fly.flight.events import INFO
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

    def stall(self, seconds: float) -> None:
        self._stall_s = seconds

    def receive(self, timeout_s: float) -> Optional[MocapFrame]:
        if self._stall_s > 0.0:
            seconds, self._stall_s = self._stall_s, 0.0
            time.sleep(seconds)
        return self.source.receive(timeout_s)

    def close(self) -> None:
        self.source.close()

    def __getattr__(self, name: str) -> Any:
        return getattr(self.source, name)


class _FaultyPlanner:
    """A drone's own planner with its scheduled faults: raising from ``at_s`` on, or blocking once."""

    def __init__(self, planner: Any, faults: list[Fault], clock: Callable[[], Optional[float]]):
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


class FaultInjection:
    """One schedule applied to one dry run (see the module docstring)."""

    def __init__(self, mission: Mission, faults: list[Fault]):
        self.mission = mission
        self.faults = faults
        self.t0: Optional[float] = None
        """``time.monotonic()`` at the start of the planning phase (None before)."""
        self.applied: list[tuple[float, Fault]] = []
        self._thread: Optional[threading.Thread] = None
        self._stop = threading.Event()

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

    def elapsed(self) -> Optional[float]:
        """Seconds since the planning phase started (None before)."""
        return None if self.t0 is None else time.monotonic() - self.t0

    # ------------------------------------------------------------------------------------------ during

    def start(self, loop: Any, rig: Any) -> None:
        """Start applying the timed faults once ``loop`` flies (call from the flight's ``on_loop``)."""
        if not isinstance(rig.mocap, StallableMocap):
            raise RuntimeError("wrap the rig's mocap in StallableMocap before the flight starts (FaultInjection.wrap)")
        self._thread = threading.Thread(target=self._run, args=(loop, rig), name="rpf-fly-faults", daemon=True)
        self._thread.start()

    @staticmethod
    def wrap(rig: Any) -> None:
        """Give the rig a stallable mocap source (before the flight is assembled)."""
        if not isinstance(rig.mocap, StallableMocap):
            rig.mocap = StallableMocap(rig.mocap)

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)

    def _run(self, loop: Any, rig: Any) -> None:
        while loop.phase != SwarmPhase.FLYING:
            if loop.phase in (SwarmPhase.ABORTED, SwarmPhase.DONE, SwarmPhase.LANDING) or self._stop.wait(0.005):
                return
        self.t0 = time.monotonic()
        timed = sorted((f for f in self.faults if f.at_s is not None), key=lambda f: f.at_s or 0.0)
        for fault in timed:
            if self._stop.wait(max(0.0, self.t0 + (fault.at_s or 0.0) - time.monotonic())):
                return
            if loop.phase in (SwarmPhase.DONE, SwarmPhase.ABORTED):
                return
            try:
                self._apply(fault, loop, rig)
            except Exception as err:  # noqa: BLE001 - an injection that fails is reported, the flight goes on
                loop.events.emit(INFO, "fault", f"could not inject {fault.kind}: {err}", fault.drone)
                continue
            self.applied.append((time.monotonic(), fault))
            what = ", ".join(f"{k} {v}" for k, v in fault.params.items())
            span = f" for {fault.duration_s:g} s" if fault.duration_s else ""
            loop.events.emit(INFO, "fault", f"injected {fault.kind}{span}{': ' + what if what else ''}", fault.drone)

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
        elif kind in ("planner_error", "planner_hang"):
            pass  # the drone's planner wrapper acts at its time (planner_factory)
        else:
            raise ValueError(f"no injection for {kind!r}")
