"""The mocap relay's process as a distributed flight's coordinator runs it (rpf_fly/runtime/coordinator.py): started
after the logger and awaited before any worker, its stderr kept, its token watched (gone: an event naming it, and,
when the workers fly on its frames, every drone lands), its line in the log's ``runtime`` record and in the
summary, and its end after the workers'. The relay itself is rpf_fly/runtime/relay.py.

:class:`MocapRelayProcess` is a part of :class:`~rpf_fly.runtime.coordinator.Coordinator`: it reads and sets the
coordinator's attributes named in its body.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from rpf_fly.flight.events import FATAL, WARNING, EventBus
from rpf_fly.runtime.auth import SECRET_ENV
from rpf_fly.runtime.bus import FlightBus
from rpf_fly.runtime.relay import RelayError
from rpf_fly.runtime.swarm_views import WorkerView

RELAY_WAIT_S = 30.0
"""How long the coordinator waits for the mocap relay's token (it imports, then its mocap must answer: 5 s)."""


class MocapRelayProcess:
    """The coordinator's side of the mocap relay."""

    say: Callable[[str], None]
    mission_path: Path
    flight: str
    log_path: Path
    local_endpoint: str
    dry_run: bool
    secret: str
    bus: FlightBus | None
    events: EventBus
    workers: dict[str, WorkerView]
    relayed: bool
    relay_process: subprocess.Popen | None
    relay_alive: bool
    relay_info: dict[str, Any]
    _relay_said: list[str]
    _stop_reason: str
    _wake: threading.Event
    _closing: bool

    def _start_relay(self) -> None:
        """Start the mocap relay (rpf_fly/runtime/relay.py) and wait for its token before any worker starts;
        :class:`RelayError` (one line: the relay's own reason when it exited) if it never comes."""
        cmd = [
            sys.executable,
            "-m",
            "rpf_fly.runtime.relay",
            str(self.mission_path),
            "--flight",
            self.flight,
            "--log",
            str(self.log_path),
            "--connect",
            self.local_endpoint,
        ] + (["--dry-run"] if self.dry_run else [])
        self.relay_process = subprocess.Popen(
            cmd, stdin=subprocess.DEVNULL, stderr=subprocess.PIPE, env=dict(os.environ, **{SECRET_ENV: self.secret})
        )
        threading.Thread(
            target=self._relay_stderr, args=(self.relay_process,), name="relay-stderr", daemon=True
        ).start()
        deadline = time.monotonic() + RELAY_WAIT_S
        while not self.relay_alive and time.monotonic() < deadline:
            code = self.relay_process.poll()
            if code is not None:
                time.sleep(0.1)  # its last line
                why = self._relay_said[-1] if self._relay_said else f"see {self.log_path.stem}.relay.log"
                raise RelayError(f"the mocap relay exited at start (code {code}): {why}; nothing armed")
            self._wake.wait(0.1)
            self._wake.clear()
        if not self.relay_alive:
            raise RelayError(
                f"the mocap relay did not come up within {RELAY_WAIT_S:.0f} s (see "
                f"{self.log_path.stem}.relay.log); nothing armed"
            )
        if self.relayed:
            self.say(
                f"mocap relay up (pid {self.relay_process.pid}): the workers fly on its frames "
                f"({self.bus.keys.mocap_frames if self.bus is not None else 'mocap_frames'})"
            )
        else:
            self.say(f"mocap relay up (pid {self.relay_process.pid}): the log's mocap; the workers read their own")

    def _relay_stderr(self, process: subprocess.Popen) -> None:
        """The relay's stderr: kept (its last line explains a failed start) and, once it is up, on the console."""
        assert process.stderr is not None
        for raw in process.stderr:
            line = raw.decode(errors="replace").rstrip()
            self._relay_said.append(line)
            if self.relay_alive:
                self.say(line)

    def _relay_alive(self, alive: bool) -> None:
        if alive:
            self.relay_alive = True
        elif self.relay_alive:
            self.relay_alive = False
            if not self._closing:
                pid, host = self.relay_info.get("pid", "?"), self.relay_info.get("host", "?")
                if self.relayed:  # no worker sees anything any more: land now, not once each pose is stale
                    self.events.emit(
                        FATAL,
                        "relay_lost",
                        f"the mocap relay (pid {pid} on {host}) is gone: the workers get no mocap; every drone lands",
                    )
                    self._stop_reason = self._stop_reason or "the mocap relay is gone: landing every drone"
                else:
                    self.events.emit(
                        WARNING,
                        "relay_lost",
                        f"the mocap relay (pid {pid} on {host}) is gone: the "
                        "workers fly on their own mocap; the log's /mocap ends here",
                    )
        self._wake.set()

    def _relay_record(self) -> dict[str, Any]:
        """The ``runtime`` record's ``relay`` (the log's metadata): the process, and whether the workers fly on its
        frames (``relayed``; else it publishes the log's mocap only)."""
        return {
            "relay": {
                **{k: self.relay_info.get(k) for k in ("name", "host", "pid", "source", "key")},
                "relayed": self.relayed,
            }
        }

    def _stop_relay(self) -> None:
        process = self.relay_process
        if process is None:
            return
        if process.poll() is None:
            process.send_signal(signal.SIGTERM)
            try:
                process.wait(10.0)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait(5.0)

    def _relay_summary(self) -> list[str]:
        """The relay's line: frames relayed, its CPU, and each worker's hop from the relay's receipt to its own."""
        if not self.relay_info:
            return []
        hops = [
            f"{w.name} p50 {w.info['relay_transit_p50_s'] * 1e3:.2f} ms p99 "
            f"{w.info['relay_transit_p99_s'] * 1e3:.2f} ms"
            for w in self.workers.values()
            if w.info.get("relay_transit_p50_s") is not None
        ]
        cpu = self.relay_info.get("cpu_pct")
        return [
            f"relay: {self.relay_info.get('frames', 0)} frames"
            + (f", {cpu:.1f} % of a core" if cpu is not None else "")
            + (f"; relay to worker: {', '.join(hops)}" if hops else "")
        ]
