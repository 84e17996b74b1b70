"""What a loop that flies part of a swarm (a distributed flight's worker) asks of the swarm's coordinator, and
how the loop waits for it (rpf_fly/flight/loop.py): the go after the preflight, the take-off after the arming, each
keeping this loop's drones down beside the swarm's grounded ones. Why apart: a loop without a :class:`SwarmLink`
never runs this, and the rules for a swarm read best together.

:class:`LoopSwarm` is a part of :class:`~rpf_fly.flight.loop.FlightLoop`: it reads and sets the loop's attributes
named in its body.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Collection
from typing import TYPE_CHECKING, Protocol, cast

from rpf_fly.flight.agent import DroneAgent
from rpf_fly.flight.commander import Commander
from rpf_fly.flight.events import ERROR, EventBus
from rpf_fly.flight.phases import DronePhase

if TYPE_CHECKING:
    from rpf_fly.flight.loop import FlightLoop


class SwarmLink(Protocol):
    """What a loop that flies part of a swarm (a distributed flight's worker: rpf_fly/runtime/worker.py) asks of
    the swarm's coordinator. Without one the loop flies its drones alone: it takes off right after its preflight
    and ends once every drone arrived (``safety.arrival_hold_s``)."""

    def preflight_done(self, loop: FlightLoop) -> None:
        """This loop's drones passed (or failed) their preflight: tell the coordinator."""

    def verdict(self) -> str | None:
        """``go`` (take off), ``abort`` (nothing takes off) or None (not yet)."""

    def grounded(self) -> Collection[str]:
        """With ``go``: every drone of the swarm that stays on the ground (``safety.on_preflight_failure:
        ground``), whichever loop flies it; this loop keeps down its own drones beside them
        (:meth:`FlightLoop._ground_neighbours`)."""

    def armed(self, loop: FlightLoop, refused: Collection[str]) -> None:
        """This loop armed its drones; ``refused``: those that stay down (their supervisors refused, or kept down
        beside them): tell the coordinator, which then says who takes off."""

    def takeoff(self) -> Collection[str] | None:
        """Once every loop armed: every drone of the swarm that stays on the ground (the arming refusals of every
        loop, and the drones down since the go), this loop keeping its own beside them down; None: not yet."""


GO_TIMEOUT_S = 60.0
"""How long a loop with a :class:`SwarmLink` waits for its coordinator's go after its preflight, drones on the
ground, before it gives up (nothing takes off)."""


class LoopSwarm:
    """The waits for the coordinator's go and take-off."""

    agents: dict[str, DroneAgent]
    commander: Commander
    events: EventBus
    swarm: SwarmLink | None
    clock: Callable[[], float]
    _stop: threading.Event
    _stop_reason: str
    _abort: Callable[[str], None]
    _spin_once: Callable[[float | None], None]
    _ground_neighbours: Callable[[set[str]], None]

    def _await_go(self) -> bool:
        """With a :class:`SwarmLink`: report the preflight and wait, drones on the ground, for the coordinator's go
        (mocap and telemetry keep flowing); its abort, a stop or the timeout: nothing takes off."""
        if self.swarm is None:
            return True
        self.swarm.preflight_done(cast("FlightLoop", self))  # this part of a FlightLoop is the loop
        deadline = self.clock() + GO_TIMEOUT_S
        while not self._stop.is_set():
            verdict = self.swarm.verdict()
            if verdict == "go":
                return self._ground_for_swarm(set(self.swarm.grounded()))
            if verdict == "abort":
                break
            if self.clock() > deadline:
                self.events.emit(ERROR, "swarm", f"no go from the coordinator within {GO_TIMEOUT_S:.0f} s")
                break
            self._spin_once(self.clock() + 0.05)
        self._abort("the swarm does not take off" + (f" ({self._stop_reason})" if self._stop_reason else ""))
        return False

    def _ground_for_swarm(self, grounded: set[str]) -> bool:
        """The coordinator's go names every drone of the swarm that stays on the ground: keep down this loop's
        drones beside them, before anything takes off, as a single process would (their spots from this loop's
        own mocap, which sees every drone). False when none of this loop's drones is left to fly."""
        ready = [n for n, a in self.agents.items() if a.phase == DronePhase.READY]
        if grounded - set(self.agents):
            self._ground_neighbours(grounded)
        kept = sorted(n for n in ready if self.agents[n].phase == DronePhase.FAILED)
        if kept:
            others = ", ".join(sorted(grounded - set(self.agents)))
            self.events.emit(
                ERROR,
                "preflight",
                f"{', '.join(kept)} stay on the ground beside the swarm's grounded drones ({others}); the others fly",
            )
        if not any(a.phase == DronePhase.READY for a in self.agents.values()):
            self._abort("every drone of this loop stays on the ground; the swarm's others fly")
            return False
        return True

    def _await_takeoff(self, armed: list[DroneAgent]) -> list[DroneAgent]:
        """With a :class:`SwarmLink`: report the arming and wait, drones armed on the ground, for the coordinator's
        ``takeoff``; keep down this loop's armed drones beside every drone of the swarm that stays on the ground
        (another loop's arming refusal included: a drone landing on one would crash), as a single process keeps
        them down beside its own refusals (:meth:`_arm`). Its abort, a stop or the timeout: every armed drone is
        disarmed and stays down. Returns the drones that take off."""
        swarm = self.swarm
        assert swarm is not None  # the take-off calls this only with a SwarmLink
        refused = sorted(n for n, a in self.agents.items() if a.phase == DronePhase.FAILED)
        swarm.armed(cast("FlightLoop", self), refused)
        deadline = self.clock() + GO_TIMEOUT_S
        why = "the swarm does not take off"
        while not self._stop.is_set():
            grounded = swarm.takeoff()
            if grounded is not None:
                others = set(grounded) - set(self.agents)
                if others:
                    self._ground_neighbours(set(grounded))
                kept = sorted(a.name for a in armed if a.phase == DronePhase.FAILED)
                if kept:
                    self.events.emit(
                        ERROR,
                        "takeoff",
                        f"{', '.join(kept)} stay on the ground beside the swarm's "
                        f"grounded drones ({', '.join(sorted(others))}); the others fly",
                    )
                return [a for a in armed if a.phase == DronePhase.READY]
            if swarm.verdict() == "abort":
                break
            if self.clock() > deadline:
                why = f"no take-off from the coordinator within {GO_TIMEOUT_S:.0f} s"
                self.events.emit(ERROR, "swarm", why)
                break
            self._spin_once(self.clock() + 0.05)
        for agent in armed:  # on the ground, armed: disarming is safe
            self.commander.refuse_take_off(agent, why + (f" ({self._stop_reason})" if self._stop_reason else ""))
        return []
