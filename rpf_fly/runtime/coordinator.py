"""A distributed flight's coordinator: the swarm's phases, Ctrl-C, the watchdog over the workers, the console
(docs/distributed.md).

It opens the flight's Zenoh session (listening on loopback by default), declares ``alive/coordinator``, starts the
logger process and one local worker process per dongle (``python -m rpf_fly worker MISSION --dongle K ...``: ``ps``
shows which process flies which dongle; the flight's secret goes in their environment), and waits until every
dongle's worker is alive, remote ones included, before any drone arms. Then, from the drones' status messages:

- preflight: once every live worker's drones are ready or failed, ``go`` (or ``abort`` when none can fly, or one
  failed under ``safety.on_preflight_failure: abort``); the ``go`` names the failed ones, and each worker keeps
  down its drones beside them, as one process would;
- flying: once every live worker's drones are at their goals (or down) for ``safety.arrival_hold_s``, ``finish``;
- a worker whose liveliness token vanishes (killed, its host lost) is an event naming it and its drones; its drones
  are left to their firmware's watchdog and stay in the others' views from mocap; the others fly on;
- Ctrl-C once: ``land``; twice: ``emergency_stop``.

In a dry run it also owns the simulated drones (the world process) and serves where they are on the ``rig`` key, so a
worker on another "host" reaches them through its fake radio; their truth goes to the logger on ``truth/<drone>``.

Every flight has a mocap relay (rpf_fly/runtime/relay.py): started after the logger, and ``alive/relay`` awaited,
before any worker. The workers fly on its frames with unicast NatNet or a ``motioncapture`` system; otherwise it
publishes the log's mocap only. Its token vanishing is an event naming the relay at once (relayed, the workers'
mocap stops: their supervisors hold, then land the drones; direct, they fly on).
"""

from __future__ import annotations

import json
import logging
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from rpf_fly.flight.events import ERROR, EventBus
from rpf_fly.mission.model import Mission
from rpf_fly.radio.budget import dongle_of
from rpf_fly.runtime.auth import SECRET_ENV, new_secret
from rpf_fly.runtime.bus import FlightBus
from rpf_fly.runtime.keys import COORDINATOR, worker_name
from rpf_fly.runtime.relay import uses_relay
from rpf_fly.runtime.relay_process import MocapRelayProcess
from rpf_fly.runtime.session import DEFAULT_PORT, StartError, free_loopback_endpoint, open_session, rig_host
from rpf_fly.runtime.swarm_phases import SwarmPhases
from rpf_fly.runtime.swarm_views import DroneView, SwarmViews, WorkerView

logger = logging.getLogger(__name__)

LOCAL_WAIT_S = 60.0
"""How long the coordinator waits for its local workers' tokens (each imports cflib and the planners)."""
REMOTE_WAIT_S = 120.0
"""How long it waits for the remote workers (``--remote-dongles``) before it gives up, nothing armed."""
LOGGER_WAIT_S = 30.0
END_WAIT_S = 30.0
"""After the finish or a land command: how long the coordinator waits for the workers to land and exit."""


class Coordinator(SwarmViews, MocapRelayProcess, SwarmPhases):
    """One distributed flight, from the coordinator's process. Its parts: what it knows of the swarm and its console
    (rpf_fly/runtime/swarm_views.py), the mocap relay's process (relay_process.py), the swarm's phases
    (swarm_phases.py); here: its processes, from start to end."""

    def __init__(
        self,
        mission: Mission,
        mission_path: Path,
        log_path: Path,
        *,
        dry_run: bool,
        remote_dongles: tuple[int, ...] = (),
        listen: tuple[str, ...] = (),
        say: Callable[[str], None] = print,
        radio_loss: bool = True,
        remote_wait_s: float = REMOTE_WAIT_S,
        worker_args: tuple[str, ...] = (),
        status_hook: Callable[[Coordinator], None] | None = None,
        start_faults: Mapping[str, Any] | None = None,
    ):
        """``start_faults``: a dry run's power-on faults (``DryRun(start_faults=...)``: a drone standing off its
        start, rotated, tumbled, with a failing motor), applied by the simulated drones themselves."""
        self.mission = mission
        self.mission_path = Path(mission_path)
        self.log_path = Path(log_path)
        self.flight = self.log_path.stem
        self.dry_run = dry_run
        self.say = say
        self.status_hook = status_hook
        """Called with the coordinator from its own thread on each status message (at least every 0.2 s) while it
        waits for the workers and flies: the console's live table, which reads :meth:`snapshot`."""
        self.radio_loss = radio_loss
        self.remote_wait_s = remote_wait_s
        self.worker_args = worker_args
        self.start_faults = dict(start_faults or {})
        self.secret = new_secret()
        dongles = sorted({dongle_of(d.uri) for d in mission.drones})
        unknown = sorted(set(remote_dongles) - set(dongles))
        if unknown:
            raise ValueError(
                f"--remote-dongles: the mission has no dongle {', '.join(map(str, unknown))} (its "
                f"dongles: {', '.join(map(str, dongles))})"
            )
        self.workers = {
            worker_name(k): WorkerView(
                worker_name(k), k, [d.name for d in mission.drones if dongle_of(d.uri) == k], k in remote_dongles
            )
            for k in dongles
        }
        if listen:
            self.listen = tuple(listen)
        elif mission.runtime.zenoh.listen:
            self.listen = mission.runtime.zenoh.listen
        elif remote_dongles:
            self.listen = (f"tcp/127.0.0.1:{DEFAULT_PORT}",)
        else:
            self.listen = (free_loopback_endpoint(),)
        self.local_endpoint = self.listen[0].replace("0.0.0.0", "127.0.0.1").replace("[::]", "[::1]")
        self.rig_host = rig_host(self.listen) if dry_run else None
        """Where a dry run's simulated drones serve: the listen address (ValueError: one line, nothing started)."""
        self.drones = {d.name: DroneView() for d in mission.drones}
        self._goals = {d.name: complex(*d.goal) for d in mission.drones}
        self.events = EventBus(time.monotonic)
        self.events.subscribe(self._print_event)
        self.phase = "starting"
        self._lock = threading.Lock()
        self._stop_reason = ""
        self._estop = False
        self._interrupts = 0
        self._wake = threading.Event()
        self.bus: FlightBus | None = None
        self.logger_process: subprocess.Popen | None = None
        self.logger_alive = False
        self.logger_info: dict[str, Any] = {}
        self.started_s: float | None = None
        self.ended_s: float | None = None
        self.rig: Any = None
        self.recorder: Any = None
        self.relayed = uses_relay(mission)
        self.relay_process: subprocess.Popen | None = None
        self.relay_alive = False
        self.relay_info: dict[str, Any] = {}
        self._relay_said: list[str] = []
        self._closing = False
        """Set as :meth:`_close` begins: the logger's and the relay's tokens vanish because it ends them."""

    # ------------------------------------------------------------------------------------------ signals

    def interrupt(self) -> None:
        """Ctrl-C: once lands every drone, twice stops every motor (safe from a signal handler: flags only)."""
        self._interrupts += 1
        if self._interrupts == 1:
            self._stop_reason = "interrupted: landing every drone (Ctrl-C again: emergency stop)"
        else:
            self._estop = True
        self._wake.set()

    def _serve_rig(self, query: Any) -> None:
        world = self.rig.world
        query.reply(
            query.key_expr,
            json.dumps(
                {
                    "radio": list(world.radio),
                    "natnet_command_port": world.natnet_command_port,
                    "air_time_s": self.rig.timing.transaction_s,
                }
            ).encode(),
        )

    # ------------------------------------------------------------------------------------------ the flight

    def run(self) -> int:
        """Fly the mission; the exit code (0 every drone reached its goal, 1 otherwise, 130 interrupted)."""
        from rpf_fly.flight.recording import McapRecorder

        session = open_session(
            self.mission.runtime.zenoh, listen=self.listen, mode="router"
        )  # ZenohUnavailable: nothing armed
        self.bus = bus = FlightBus(session, self.flight, COORDINATOR)
        keys = bus.keys
        self.events.subscribe(lambda e: self.recorder.event(e) if self.recorder is not None else None)
        try:
            bus.subscribe(keys.key("status/*"), self._status)
            bus.subscribe(keys.key("tf/*"), self._tf)
            bus.subscribe(keys.workers_all, self._worker_info)
            bus.subscribe(keys.events, self._worker_event, remote_only=True)
            bus.watch_alive(keys.alive_all, self._alive)
            bus.token(COORDINATOR)
            self.say(f"flight {self.flight}: zenoh on {', '.join(self.listen)}; log {self.log_path}")
            if self.dry_run:
                self._start_rig(bus)
            truth = self.rig.truth_samples if self.rig is not None and self.rig.truth else None
            self.recorder = McapRecorder(
                Path(f"zenoh-{self.flight}-coordinator"),
                self.mission,
                source="dry-run" if self.dry_run else "flight",
                truth=truth,
                out=bus.out,
            )
            self._start_logger()
            self._start_relay()
            self._start_workers()
            if not self._wait_workers():
                self._command("abort", "not every worker is alive: nothing takes off")
                self._end_workers()
                return 1
            bus.put_json(
                "runtime",
                json.dumps(
                    {
                        "flight_id": self.flight,
                        "workers": [
                            {k: w.info.get(k) for k in ("name", "dongle", "host", "pid", "drones")}
                            for w in self.workers.values()
                        ],
                        **self._relay_record(),
                    }
                ).encode(),
            )
            self.started_s = time.monotonic()
            self._fly()
            self._end_workers()
            self.ended_s = time.monotonic()
        finally:
            self._close()
        return self._exit_code()

    def _start_rig(self, bus: FlightBus) -> None:
        from rpf_fly.flight.dry_run import RADIO_LOSS, DryRun, world_exit_report_for

        host = self.rig_host or "127.0.0.1"  # where the workers reach the coordinator, they reach the drones
        self.rig = DryRun(
            self.mission,
            radio="fake",  # nothing here flies: each worker reaches the drones itself (its dongle, `dry_run.radio`)
            radio_loss=RADIO_LOSS if self.radio_loss else None,
            world_exit_report=world_exit_report_for(self.log_path),
            host=host,
            start_faults=self.start_faults,
        ).__enter__()
        if not host.startswith("127."):
            self.say(
                f"dry run: the simulated drones serve on {host} (radio udp/{self.rig.world.radio[1]}, NatNet "
                f"udp/{self.rig.world.natnet_command_port}), as Zenoh listens there"
            )
        if self.rig.mocap is not None:  # the workers receive the mocap; the coordinator needs none
            self.rig.mocap.close()
            self.rig.mocap = None
        bus._handles.append(bus.session.declare_queryable(bus.keys.rig, self._serve_rig))  # noqa: SLF001

    def _start_logger(self) -> None:
        cmd = [
            sys.executable,
            "-m",
            "rpf_fly.runtime.logger",
            str(self.mission_path),
            "--flight",
            self.flight,
            "--log",
            str(self.log_path),
            "--connect",
            self.local_endpoint,
            "--source",
            "dry-run" if self.dry_run else "flight",
        ]
        self.logger_process = subprocess.Popen(cmd, stdin=subprocess.DEVNULL)
        deadline = time.monotonic() + LOGGER_WAIT_S
        while not self.logger_alive and time.monotonic() < deadline:
            if self.logger_process.poll() is not None:
                raise StartError(
                    f"the logger exited at start (code {self.logger_process.returncode}; see "
                    f"{self.log_path.stem}.logger.log): nothing armed"
                )
            self._wake.wait(0.1)
            self._wake.clear()
        if not self.logger_alive:
            raise StartError(
                f"the logger did not come up within {LOGGER_WAIT_S:.0f} s (see "
                f"{self.log_path.stem}.logger.log): nothing armed"
            )

    def worker_command(self, dongle: int, endpoint: str) -> list[str]:
        return (
            ["worker", str(self.mission_path), "--dongle", str(dongle), "--flight", self.flight, "--connect", endpoint]
            + (["--dry-run"] if self.dry_run else [])
            + list(self.worker_args)
        )

    def _start_workers(self) -> None:
        for worker in self.workers.values():
            if worker.remote:
                self.say(
                    f"waiting for dongle {worker.dongle} ({', '.join(worker.drones)}): on its host run  "
                    f"{SECRET_ENV}={self.secret} rpf-fly "
                    + " ".join(
                        self.worker_command(worker.dongle, "tcp/<this host>:" + self.listen[0].rsplit(":", 1)[-1])
                    )
                )
                continue
            out = self.log_path.with_name(f"{self.log_path.stem}.{worker.name}.log")
            env = dict(
                os.environ,
                **{
                    SECRET_ENV: self.secret,
                    "RPF_FLY_WORKER_LOG": str(
                        self.log_path.with_name(f"{self.log_path.stem}.{worker.name}.records.log")
                    ),
                },
            )
            with open(out, "ab") as handle:
                worker.process = subprocess.Popen(
                    [sys.executable, "-m", "rpf_fly", *self.worker_command(worker.dongle, self.local_endpoint)],
                    env=env,
                    stdin=subprocess.DEVNULL,
                    stdout=handle,
                    stderr=subprocess.STDOUT,
                )

    def _wait_workers(self) -> bool:
        start = time.monotonic()
        while True:
            missing = [w for w in self.workers.values() if not (w.seen and w.info)]
            if not missing:
                return True
            for w in missing:
                if w.process is not None and w.process.poll() is not None:
                    self.events.emit(
                        ERROR,
                        "worker",
                        f"worker {w.name} exited at start (code {w.process.returncode}"
                        f"; see {self.log_path.stem}.{w.name}.log)",
                    )
                    return False
            waited = time.monotonic() - start
            local = [w for w in missing if not w.remote]
            if (local and waited > LOCAL_WAIT_S) or (not local and waited > self.remote_wait_s) or self._stop_reason:
                names = ", ".join(f"dongle {w.dongle}" for w in missing)
                why = self._stop_reason or f"no worker alive for {names} within {waited:.0f} s"
                self.events.emit(ERROR, "worker", f"{why}: nothing takes off")
                return False
            self._wake.wait(0.2)
            self._wake.clear()
            self._show()

    def _end_workers(self) -> None:
        """Wait for the local workers to land and exit (a stuck one: land, then SIGTERM, then SIGKILL)."""
        deadline = time.monotonic() + END_WAIT_S
        for worker in self.workers.values():
            process = worker.process
            if process is None:
                continue
            while process.poll() is None and time.monotonic() < deadline:
                if self._estop:
                    assert self.bus is not None
                    self.bus.command(self.secret, "emergency_stop", "second Ctrl-C")
                    self._estop = False
                time.sleep(0.1)
            if process.poll() is None:
                self.events.emit(ERROR, "worker", f"worker {worker.name} did not exit: terminating it (it lands)")
                process.terminate()
                try:
                    process.wait(15.0)
                except subprocess.TimeoutExpired:
                    process.kill()
                    process.wait(5.0)
        remote_deadline = time.monotonic() + 10.0
        while any(w.alive for w in self.workers.values() if w.remote) and time.monotonic() < remote_deadline:
            time.sleep(0.1)

    def _close(self) -> None:
        self._closing = True
        if self.recorder is not None:
            try:
                self.recorder.close()  # the last truth samples and events go out
            except Exception:  # noqa: BLE001
                logger.exception("coordinator: closing its recorder failed")
            time.sleep(0.3)
        if self.logger_process is not None:
            self.logger_process.send_signal(signal.SIGTERM)
            try:
                self.logger_process.wait(30.0)
            except subprocess.TimeoutExpired:
                self.logger_process.kill()
        for worker in self.workers.values():  # an exception above: no worker outlives its coordinator
            if worker.process is not None and worker.process.poll() is None:
                worker.process.terminate()
                try:
                    worker.process.wait(15.0)
                except subprocess.TimeoutExpired:
                    worker.process.kill()
        self._stop_relay()  # after the workers: their drones land on its frames
        if self.bus is not None:
            self.bus.close()
        if self.rig is not None:
            self.rig.close()

    def _exit_code(self) -> int:
        if self._interrupts:
            return 130
        ok = all(v.outcome == "reached" for v in self.drones.values()) and not any(
            w.lost for w in self.workers.values()
        )
        return 0 if ok else 1

    def summary(self) -> list[str]:
        lines = []
        for name, view in self.drones.items():
            lines.append(f"{name}: {view.outcome or view.state}")
        for w in self.workers.values():
            latency = w.info.get("latency") or {}
            if latency.get("latency_p50_s") is not None:
                lines.append(
                    f"{w.name}: mocap-to-setpoint latency p50 {latency['latency_p50_s'] * 1e3:.2f} ms "
                    f"p99 {latency['latency_p99_s'] * 1e3:.2f} ms" + (" (lost)" if w.lost else "")
                )
            elif w.lost:
                lines.append(f"{w.name}: lost")
        lines += self._relay_summary()
        lines.append(f"log: {self.log_path}  (rpf-fly review {self.log_path})")
        return lines
