"""The dry run's simulated drones and Motive emulator in a process of their own.

Why: a real flight's process holds the flight loop, the NatNet client, cflib with its radio driver and the log
writer; the drones and Motive are other machines. In a dry run the simulated firmwares (stepped at 100 Hz, about
0.4 ms of Python for 10 drones), the packet handling of every radio transaction and the NatNet emulator would
otherwise run on threads of the flight's process and hold its GIL at random moments, delaying setpoints in a way
no real flight sees. So the dry run starts them here, in a child process, and reaches them over 127.0.0.1 (a
distributed flight's coordinator: over the address it listens on, so workers on other hosts reach them too):

- the radio: each fake link (``fake_radio.FakeLink``, in the flight's process, emulating cflib's Crazyradio driver
  thread) performs each transaction as one UDP request to the child and waits for its reply, as the real driver
  waits on the USB dongle; lost attempts, unreachable drones and the firmware's answers are decided in the child
  (the wire: rpf_fly/emulator/radio_wire.py; the flight's side: rpf_fly/emulator/remote_world.py; the child's:
  rpf_fly/emulator/world_server.py);
- the mocap: the child runs the NatNet server emulator, which the flight's NatNet client receives as from Motive
  (rpf_fly/emulator/simulated_bodies.py);
- the fault hooks and firmware snapshots of tests and demos, and the truth samples of the dry run's log
  (:meth:`WorldProcess.truth_samples`, fetched in batches: rpf_fly/flight/truth.py), go over a
  `multiprocessing.connection` to 127.0.0.1 (:class:`WorldProcess`, its calls: rpf_fly/emulator/world_calls.py).

The child ignores SIGINT (a Ctrl-C in a terminal reaches the whole process group: the drones must stay up while
the flight lands them) and exits when the parent closes it (`WorldProcess.close`: at once, the parent landed the
drones). When the parent dies without closing it (SIGKILL, a crash), the drones are then where real ones would be:
the child simulates them down, at most `ORPHAN_CAP_S`, writes an exit report and exits
(rpf_fly/emulator/world_orphan.py).
"""

from __future__ import annotations

import json
import logging
import os
import pickle
import queue
import secrets
import signal
import subprocess
import sys
import threading
from collections.abc import Mapping, Sequence
from multiprocessing.connection import Client, Listener
from typing import Any

from rpf_fly.mission.model import Obstacle

from .fake_world import FakeDroneConfig
from .host_lag import ahead_of_the_ground_station
from .mocap_noise import MocapNoise
from .remote_world import RemoteWorld  # noqa: F401 (rpf_fly/flight/dry_run.py and lab.py import it from here)
from .simulated_bodies import SimulatedBodies  # noqa: F401 (rpf_fly/flight/dry_run.py imports it from here)
from .world_calls import WorldCalls
from .world_orphan import ORPHAN_CAP_S, Orphan
from .world_server import WorldServer

logger = logging.getLogger(__name__)

START_TIMEOUT_S = 60.0


class WorldProcess(WorldCalls):
    """Starts the child process and speaks to it: the fault hooks and snapshots of `FakeWorld` and
    `SimulatedBodies`, by the same names. ``natnet``: the NatNet server's settings (``version``, ``rate_hz``,
    ``up_axis``, optionally ``multicast``), None for no NatNet server. ``obstacles``: the mission's obstacles, for
    the world's contacts.

    The child is ``python -m rpf_fly.emulator.world_process``, not a multiprocessing spawn (which re-imports the
    caller's main script: a user's unguarded script would run again in it). It reads its settings as one pickle on
    stdin, answers with one JSON line on stdout (its ports), then serves calls on a `multiprocessing.connection`
    to 127.0.0.1, authenticated with a random key."""

    def __init__(
        self,
        drones: Mapping[int, FakeDroneConfig],
        bodies: Mapping[int, str],
        *,
        seed: int = 0,
        natnet: Mapping[str, Any] | None = None,
        obstacles: Sequence[Obstacle] = (),
        names: Mapping[int, str] | None = None,
        exit_report: str | os.PathLike[str] | None = None,
        orphan_cap_s: float = ORPHAN_CAP_S,
        host: str = "127.0.0.1",
        mocap_noise: MocapNoise | None = None,
    ) -> None:
        """``names``: the drones' names (radio address -> name) for the exit report (else their addresses).
        ``exit_report``: where the child writes its exit report if this process dies without closing it (None:
        no report); ``orphan_cap_s``: how long it simulates the drones at most then (`ORPHAN_CAP_S`). ``host``: the
        IPv4 address its radio server and NatNet server bind (default loopback; a distributed flight's coordinator
        gives its Zenoh listen address, so workers on other hosts reach the drones: docs/distributed.md); the
        control connection stays on loopback."""
        self._lock = threading.Lock()
        self._conn: Any = None
        key = secrets.token_bytes(32)
        settings = {
            "drones": dict(drones),
            "bodies": dict(bodies),
            "seed": seed,
            "obstacles": tuple(obstacles),
            "natnet": dict(natnet) if natnet else None,
            "authkey": key,
            "names": dict(names or {}),
            "exit_report": os.fspath(exit_report) if exit_report is not None else None,
            "orphan_cap_s": float(orphan_cap_s),
            "host": host,
            "mocap_noise": MocapNoise.default() if mocap_noise is None else mocap_noise,
        }
        self._process = subprocess.Popen(
            [sys.executable, "-m", "rpf_fly.emulator.world_process"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
        )
        try:
            assert self._process.stdin is not None and self._process.stdout is not None
            self._process.stdin.write(pickle.dumps(settings))
            self._process.stdin.close()
            line = _read_line(self._process.stdout, START_TIMEOUT_S)
            if line is None:
                raise RuntimeError(f"the simulated drones' process did not start within {START_TIMEOUT_S:g} s")
            ready = json.loads(line)
            if "error" in ready:
                raise RuntimeError(f"the simulated drones' process failed to start: {ready['error']}")
            self._conn = Client(tuple(ready["control"]), authkey=key)
        except BaseException:
            self.close()
            raise
        self.pid: int = self._process.pid
        """The child's process id (a test watches it outlive a killed parent)."""
        self.radio: tuple[str, int] = (ready["radio"][0], ready["radio"][1])
        self.natnet_command_port: int | None = ready["natnet_command_port"]
        self.addresses: tuple[int, ...] = tuple(drones)

    def call(self, method: str, *args: Any) -> Any:
        with self._lock:
            if self._conn is None:
                raise RuntimeError(f"simulated drones: {method} after close")
            self._conn.send((method, args))
            status, value = self._conn.recv()
        if status != "ok":
            raise RuntimeError(f"simulated drones: {method} failed: {value}")
        return value

    def close(self) -> None:
        """Stop the child (its world powers the drones off) and wait for it; idempotent."""
        if self._conn is not None:
            try:
                self.call("close")
            except (OSError, EOFError, RuntimeError):
                pass
            with self._lock:
                self._conn.close()
                self._conn = None
        try:
            self._process.wait(5.0)
        except subprocess.TimeoutExpired:
            self._process.kill()
            self._process.wait(2.0)
        if self._process.stdout is not None:
            self._process.stdout.close()


def _read_line(stream: Any, timeout_s: float) -> bytes | None:
    """One line from a pipe; None after ``timeout_s`` or at its end (a thread: portable, unlike select on pipes)."""
    lines: queue.Queue[bytes] = queue.Queue()
    threading.Thread(target=lambda: lines.put(stream.readline()), daemon=True).start()
    try:
        line = lines.get(timeout=timeout_s)
    except queue.Empty:
        return None
    return line or None


def serve(settings: dict[str, Any], out: Any) -> None:
    """The child process: world, radio server, NatNet server; reports its ports as one JSON line on ``out``, then
    answers the parent's calls until it closes them, or until it goes away (then `Orphan`)."""
    server = WorldServer(settings)
    orphan = Orphan(
        server.world,
        os.getppid(),
        settings.get("names", {}),
        settings.get("exit_report"),
        settings.get("orphan_cap_s", ORPHAN_CAP_S),
    )
    orphan.watch_parent()
    try:
        with Listener(("127.0.0.1", 0), authkey=settings["authkey"]) as listener:
            out.write(json.dumps({"control": list(listener.address), **server.ports()}) + "\n")
            out.flush()
            conn = listener.accept()
        with conn:
            while True:
                try:
                    method, args = conn.recv()
                except (EOFError, OSError):
                    orphan.run("the control connection closed without a close call")
                    return  # the parent is gone
                if method == "close":
                    orphan.closing()
                    conn.send(("ok", None))
                    return
                conn.send(server.handle(method, args))
    finally:
        server.close()


SWITCH_INTERVAL_S = 0.5e-3
"""The world process's GIL switch interval (Python's default 5 ms): a radio request waits for the simulation's
thread to let go of the GIL, and a real Crazyflie's radio answers in its own time. Measured through the emulated
Crazyradio, 8 drones: the world's round trip p90 2.1 ms and p99 4.6 ms at 5 ms, 0.9 and 3.2 ms at 0.5 ms."""


def main() -> None:
    """``python -m rpf_fly.emulator.world_process``: settings as one pickle on stdin (from `WorldProcess` only)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a Ctrl-C reaches the whole process group: the parent lands first
    ahead_of_the_ground_station()
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    out = sys.stdout
    sys.stdout = sys.stderr  # nothing else may write on the parent's pipe
    try:
        settings = pickle.loads(sys.stdin.buffer.read())
        serve(settings, out)
    except Exception as err:  # noqa: BLE001 - tell the parent (it waits for this line at startup)
        logger.exception("simulated drones failed")
        try:
            out.write(json.dumps({"error": f"{type(err).__name__}: {err}"}) + "\n")
            out.flush()
        except (OSError, ValueError):
            pass


if __name__ == "__main__":
    main()
