"""What a distributed flight's coordinator knows of the swarm (rpf_fly/runtime/coordinator.py): each drone's status
and pose, each worker's liveliness and reports, the logger's and the relay's, from the messages on the flight's
Zenoh keys; and the console's view of them.

:class:`SwarmViews` is a part of :class:`~rpf_fly.runtime.coordinator.Coordinator` (its callbacks and console): it
reads and sets the coordinator's attributes named in its body.
"""

from __future__ import annotations

import json
import logging
import subprocess
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rpf_fly.flight.events import ERROR, FATAL, WARNING, EventBus, FlightEvent
from rpf_fly.runtime.keys import LOGGER, RELAY

logger = logging.getLogger(__name__)


@dataclass
class DroneView:
    """What the coordinator knows of one drone: its status messages (state, outcome, battery, link), where its
    worker's ``tf`` last put it, and the reason its worker gave at the end."""

    state: str = "connecting"
    outcome: str | None = None
    battery_v: float | None = None
    link_pct: float | None = None
    position: tuple[float, float, float] | None = None
    reason: str = ""


REPORT_GRACE_S = 1.0
"""How long after a worker's liveliness token vanished its last report may still come before it is lost (one Zenoh
lease: the report and the token's end travel apart)."""


@dataclass
class WorkerView:
    name: str
    dongle: int
    drones: list[str]
    remote: bool
    alive: bool = False
    seen: bool = False
    done: bool = False
    lost: bool = False
    info: dict[str, Any] = field(default_factory=dict)
    process: subprocess.Popen | None = None
    gone_at: float | None = None
    """When its liveliness token vanished before its report came (`SwarmViews.judge_gone`)."""


class SwarmViews:
    """The coordinator's callbacks on the workers', logger's and relay's messages, and its console."""

    say: Callable[[str], None]
    status_hook: Callable[[Any], None] | None
    workers: dict[str, WorkerView]
    drones: dict[str, DroneView]
    _goals: dict[str, complex]
    events: EventBus
    phase: str
    log_path: Path
    logger_alive: bool
    logger_info: dict[str, Any]
    relay_info: dict[str, Any]
    _wake: threading.Event
    _closing: bool
    _relay_alive: Callable[[bool], None]  # rpf_fly/runtime/relay_process.py

    def _print_event(self, event: FlightEvent) -> None:
        if event.level >= WARNING or event.drone is None:
            who = f"{event.drone}: " if event.drone else ""
            self.say(f"[{event.kind}] {who}{event.message}")

    def snapshot(self) -> list[dict[str, Any]]:
        """Per-drone rows for the console, those of ``FlightLoop.snapshot`` (name, phase, position, goal distance,
        battery, link quality, reason) from the drones' status and tf messages, with the drone's ``worker``, whether
        that worker is ``lost`` and the drone's ``outcome`` once known (rpf_fly/cli/flight_console.py)."""
        worker_of = {name: w for w in self.workers.values() for name in w.drones}
        rows = []
        for name, view in self.drones.items():
            worker, pos = worker_of[name], view.position
            reason = view.reason or (
                f"worker {worker.name} lost: left to its firmware's watchdog" if worker.lost else ""
            )
            rows.append(
                {
                    "name": name,
                    "phase": view.state,
                    "position": pos,
                    "goal_distance": abs(self._goals[name] - complex(pos[0], pos[1])) if pos is not None else None,
                    "battery_v": view.battery_v,
                    "link_pct": view.link_pct,
                    "reason": reason,
                    "outcome": view.outcome,
                    "worker": worker.name,
                    "lost": worker.lost,
                }
            )
        return rows

    def _show(self) -> None:
        if self.status_hook is None:
            return
        try:
            self.status_hook(self)
        except Exception:  # noqa: BLE001 - the console never stops the flight
            logger.exception("coordinator: the console's status hook failed")
            self.status_hook = None

    def _worker_event(self, sample: Any) -> None:
        """The workers' events: the console shows warnings and errors, and the swarm-wide lines."""
        message = json.loads(sample.payload.to_bytes())
        level, name = int(message.get("level", 2)), message.get("name", "")
        if level >= WARNING:
            if name == "flight" or not name:
                name = ""
            self.say(f"[{message.get('file', '')}] {name + ': ' if name else ''}{message.get('message', '')}")

    # ------------------------------------------------------------------------------------------ callbacks

    def _status(self, sample: Any) -> None:
        drone = str(sample.key_expr).rsplit("/", 1)[-1]
        view = self.drones.get(drone)
        if view is None:
            return
        message = json.loads(sample.payload.to_bytes())
        battery, quality = message.get("battery_v"), message.get("link_quality")
        battery, link = None if battery is None else float(battery), None if quality is None else 100.0 * float(quality)
        view.state = str(message["state"])
        view.outcome = message.get("outcome") or view.outcome
        view.battery_v, view.link_pct = battery, link
        self._wake.set()

    def _tf(self, sample: Any) -> None:
        """A worker's ``tf`` (20 Hz, its drones' mocap poses): where the console shows them."""
        for transform in json.loads(sample.payload.to_bytes())["transforms"]:
            view = self.drones.get(str(transform["child_frame_id"]))
            if view is not None:
                t = transform["translation"]
                view.position = (float(t["x"]), float(t["y"]), float(t["z"]))

    def _worker_info(self, sample: Any) -> None:
        info = json.loads(sample.payload.to_bytes())
        if info.get("name") == LOGGER:
            self.logger_info = info
            return
        if info.get("name") == RELAY:
            self.relay_info = info
            return
        worker = self.workers.get(str(info.get("name")))
        if worker is None:
            return
        worker.info = info
        if info.get("state") == "done":
            worker.done = True
            for name, outcome in (info.get("outcomes") or {}).items():
                if name in self.drones:
                    self.drones[name].outcome = outcome
            for name, reason in (info.get("reasons") or {}).items():
                if name in self.drones:
                    self.drones[name].reason = str(reason)
        self._wake.set()

    def _how_gone(self, worker: WorkerView) -> str:
        """What this host knows of a lost worker it started: its exit (a crash's traceback is in its log) or, still
        running, that its link lapsed (no message within the Zenoh lease: a stalled or starved host). '' for a
        worker started elsewhere."""
        if worker.process is None:
            return ""
        log = f"{self.log_path.stem}.{worker.name}.log"
        code = worker.process.poll()
        if code is None:
            return f" (its process still runs: its link to the coordinator lapsed; see {log})"
        if code < 0:
            return f" (its process was killed by signal {-code}; see {log})"
        return f" (its process exited with code {code} without its report; see {log})"

    def _alive(self, name: str, alive: bool) -> None:
        if name == RELAY:
            self._relay_alive(alive)
            return
        if name == LOGGER:
            self.logger_alive = alive
            if not alive and self.phase not in ("done",) and not self._closing:
                self.events.emit(
                    ERROR,
                    "logger",
                    "the logger is gone: the flight goes on, the log ends here "
                    f"(rpf-fly review --salvage {self.log_path})",
                )
            self._wake.set()
            return
        worker = self.workers.get(name)
        if worker is None:
            return
        if alive:
            worker.alive = worker.seen = True
        else:
            worker.alive = False
            if not worker.done and worker.gone_at is None:
                worker.gone_at = time.monotonic()  # judged by the flight's loop, woken now (`judge_gone`)
        self._wake.set()

    def judge_gone(self) -> None:
        """Each worker whose token vanished before its report: lost once its process was killed, or once its report
        has not come within `REPORT_GRACE_S` of the token (a worker's last report and its token's end travel apart:
        the report may come second)."""
        now = time.monotonic()
        for worker in self.workers.values():
            if worker.gone_at is None or worker.done or worker.lost:
                continue
            if self._killed(worker) or now - worker.gone_at >= REPORT_GRACE_S:
                self._lose(worker)

    def leaving(self, worker: WorkerView) -> bool:
        """Its token vanished, its report may still come (`judge_gone`)."""
        return worker.gone_at is not None and not worker.done and not worker.lost

    @staticmethod
    def _killed(worker: WorkerView) -> bool:
        """A worker this host started that a signal ended (a killed process's socket closes as it exits)."""
        code = worker.process.poll() if worker.process is not None else None
        return code is not None and code < 0

    def _lose(self, worker: WorkerView) -> None:
        worker.lost = True
        pid = worker.info.get("pid", "?")
        host = worker.info.get("host", "?")
        self.events.emit(
            FATAL,
            "worker_lost",
            f"worker {worker.name} (dongle {worker.dongle}, pid {pid} on {host}) is gone{self._how_gone(worker)}: "
            f"its drones {', '.join(worker.drones)} are left to their firmware's watchdog; the others fly on",
        )
        self._wake.set()
