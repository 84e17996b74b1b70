"""A distributed flight's phases as its coordinator drives them (rpf_fly/runtime/coordinator.py): preflight, the
go (or the abort), arming, the take-off, flying until every drone is at its goal, the finish; Ctrl-C's land and
emergency stop; each a signed command to every worker (docs/distributed.md).

:class:`SwarmPhases` is a part of :class:`~rpf_fly.runtime.coordinator.Coordinator`: it reads and sets the
coordinator's attributes named in its body.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from rpf_fly.flight.events import INFO, WARNING, EventBus
from rpf_fly.mission.model import Mission
from rpf_fly.runtime.bus import FlightBus
from rpf_fly.runtime.swarm_views import DroneView, WorkerView

PREFLIGHT_STATES = {"ready", "failed"}
DOWN_STATES = {"landed", "failed", "grounded", "emergency", "link_lost", "landing"}
ARM_WAIT_S = 15.0
"""After the go: how long the coordinator waits for every worker to report its arming (each waits up to 3 s for its
drones' supervisors) before it aborts, nothing taking off."""


class SwarmPhases:
    """The swarm's phase machine, from the drones' states and the workers' reports."""

    mission: Mission
    secret: str
    bus: FlightBus | None
    events: EventBus
    phase: str
    workers: dict[str, WorkerView]
    drones: dict[str, DroneView]
    _stop_reason: str
    _estop: bool
    _wake: threading.Event
    _show: Callable[[], None]
    judge_gone: Callable[[], None]  # rpf_fly/runtime/swarm_views.py
    leaving: Callable[[WorkerView], bool]

    def _command(self, command: str, reason: str = "", grounded: tuple[str, ...] = ()) -> None:
        assert self.bus is not None
        self.events.emit(
            INFO if command in ("go", "takeoff", "finish") else WARNING,
            "command",
            f"{command}{': ' + reason if reason else ''}",
        )
        self.bus.command(self.secret, command, reason, grounded)

    def _live(self) -> list[WorkerView]:
        self.judge_gone()
        return [w for w in self.workers.values() if (w.alive or self.leaving(w)) and not w.done]

    def _states(self, workers: list[WorkerView]) -> list[str]:
        return [self.drones[n].state for w in workers for n in w.drones]

    def _fly(self) -> None:
        self.phase = "preflight"
        self.events.emit(INFO, "phase", "swarm: preflight")
        arrived_since: float | None = None
        arming_since = 0.0
        sent_stop = sent_estop = False
        timeout = self.mission.flight.timeout_s + 120.0
        start = time.monotonic()
        while True:
            self._wake.wait(0.1)
            self._wake.clear()
            self._show()
            now = time.monotonic()
            live = self._live()
            if self._estop and not sent_estop:
                sent_estop = True
                self._command("emergency_stop", "second Ctrl-C: emergency stop, motors off")
            if self._stop_reason and not sent_stop:
                sent_stop = True
                self._command("land", self._stop_reason)
                self.phase = "landing"
            if not live:
                break
            if now - start > timeout:
                self._command("land", "the coordinator's flight timeout")
                self.phase = "landing"
                break
            states = self._states(live)
            gone = [w.name for w in self.workers.values() if w.done or w.lost]
            if self.phase == "preflight" and gone:
                # As a single-process flight aborts when a drone fails to connect: a worker that ended (its links
                # failed, it aborted) or died before take-off grounds the whole swarm.
                self._command("abort", f"{', '.join(gone)} ended before take-off: no drone takes off")
                self.phase = "aborted"
            elif self.phase == "preflight" and all(s in PREFLIGHT_STATES for s in states):
                failed = [n for w in live for n in w.drones if self.drones[n].state == "failed"]
                if len(failed) == len(states) or (failed and self.mission.safety.on_preflight_failure == "abort"):
                    self._command("abort", f"preflight failed for {', '.join(failed)}: no drone takes off")
                    self.phase = "aborted"
                else:  # the failed stay down; the go names them, each worker keeps down its drones beside them
                    self._command(
                        "go",
                        f"every worker finished its preflight; {', '.join(failed)} stay on the "
                        "ground, with every drone that could not take off or land beside them"
                        if failed
                        else "every worker passed its preflight",
                        tuple(failed),
                    )
                    self.phase = "arming"
                    arming_since = now
            elif self.phase == "arming":
                if all(w.info.get("state") == "armed" for w in live):
                    down = self._grounded_at_takeoff(live)
                    self._command(
                        "takeoff",
                        "every worker armed"
                        + (
                            f"; {', '.join(down)} stay on the ground, with every drone that could not take off or land "
                            "beside them"
                            if down
                            else ""
                        ),
                        tuple(down),
                    )
                    self.phase = "flying"
                    self.events.emit(INFO, "phase", "swarm: flying")
                elif now - arming_since > ARM_WAIT_S:
                    waiting = [w.name for w in live if w.info.get("state") != "armed"]
                    self._command(
                        "abort", f"{', '.join(waiting)} did not arm within {ARM_WAIT_S:.0f} s: no drone takes off"
                    )
                    self.phase = "aborted"
            elif self.phase == "flying":
                if states and all(s == "arrived" or s in DOWN_STATES for s in states) and "arrived" in states:
                    arrived_since = arrived_since if arrived_since is not None else now
                    if now - arrived_since >= self.mission.safety.arrival_hold_s:
                        self._command("finish", "every drone of the swarm is at its goal")
                        self.phase = "landing"
                        self.events.emit(INFO, "phase", "swarm: landing")
                else:
                    arrived_since = None
        self.phase = "done" if self.phase != "aborted" else self.phase

    def _grounded_at_takeoff(self, live: list[WorkerView]) -> list[str]:
        """Every drone that stays on the ground once the workers armed: their arming refusals (each worker's report
        names them: their "failed" status may come later), every drone down since the go, and the drones of a
        worker that ended or died meanwhile (on the ground where they stand). Each worker keeps down its drones
        beside them, as a single process keeps its own down beside its refusals."""
        down = {n for w in live for n in w.info.get("refused", ()) if n in self.drones}
        down |= {n for n, view in self.drones.items() if view.state == "failed"}
        down |= {n for w in self.workers.values() if w not in live for n in w.drones}
        return sorted(down)
