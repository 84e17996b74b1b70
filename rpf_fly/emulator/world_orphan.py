"""What a dry run's simulated drones do once the flight's process died without closing them (SIGKILL, a crash):
they are where real ones would be, no ground station, no more setpoints. The child (rpf_fly/emulator/world_process.py)
keeps simulating them in real time until every drone's motors are off and it rests on the floor (a streaming drone:
levels out 0.5 s after its last setpoint, motors cut at 2 s, falls; a drone flying a high-level plan flies it on,
as the firmware does, and hovers at its end), at most `ORPHAN_CAP_S`, writes an exit report (JSON) and exits.

The parent's death shows as the control connection's end (the kernel closes a dead process's sockets) or as a
new parent pid (the child was re-parented).
"""

from __future__ import annotations

import json
import os
import select
import threading
import time
from collections.abc import Mapping
from typing import Any

from .fake_world import FakeWorld

ORPHAN_CAP_S = 10.0
"""The longest the child simulates its drones after its parent died without closing it: the firmware's watchdog
cuts a streaming drone's motors 2 s after its last setpoint and a fall from 3 m takes 0.8 s, so every streaming
drone lies on the floor well within it; a drone flying a high-level plan hovers on (the firmware's high-level
commander has no watchdog) and would never come down: the cap bounds how long an orphaned process lingers."""
PARENT_POLL_S = 0.1
"""How often the child checks that its parent is still the process that started it (a death the control
connection did not show: while the child still waits for the parent to connect)."""
ORPHAN_POLL_S = 0.05
"""How often an orphaned child reads the world's truth samples to see whether every drone is down (the samples
carry each step's time, so the report's figures have the world step's resolution, not this one's)."""
ORPHAN_KILL_MARGIN_S = 5.0
"""Beyond the cap, a last timer ends the child whatever it is doing (a report write blocked on a full disk or
pipe): an orphan must never linger."""


class Orphan:
    """What the child does once its parent died without closing it (module doc): simulate on until every drone is
    down or `ORPHAN_CAP_S` passed, then write the exit report. The first caller (the control connection's end, or
    the parent watch) runs it; a second one waits until it is done."""

    def __init__(
        self, world: FakeWorld, parent_pid: int, names: Mapping[int, str], report: str | None, cap_s: float
    ) -> None:
        self._world = world
        self._parent_pid = parent_pid
        self._names = dict(names)
        self._report = report
        self._cap_s = cap_s
        self._lock = threading.Lock()
        self._started = False
        self._done = threading.Event()

    def watch_parent(self) -> None:
        """Start the thread that notices a parent that is gone before the control connection says so."""
        threading.Thread(target=self._watch, name="parent-watch", daemon=True).start()

    def _watch(self) -> None:
        while os.getppid() == self._parent_pid:
            time.sleep(PARENT_POLL_S)
        if self.run("the parent process is gone (the child was re-parented)"):
            os._exit(0)  # the main thread may still wait for the parent to connect: nothing else ends it

    def closing(self) -> None:
        """The parent closes the child (it landed the drones): no orphan from now on, whatever the parent does."""
        with self._lock:
            self._started = True
        self._done.set()

    def run(self, how: str) -> bool:
        """Simulate the drones down and write the report; False if another caller already did (after waiting)."""
        with self._lock:
            first, self._started = not self._started, True
        if not first:
            self._done.wait()
            return False
        try:
            last_resort = threading.Timer(self._cap_s + ORPHAN_KILL_MARGIN_S, os._exit, (3,))
            last_resort.daemon = True  # never what keeps the process up
            last_resort.start()
            report = self._fall(how)
            self._write(report)
        finally:
            self._done.set()
        return True

    def _fall(self, how: str) -> dict[str, Any]:
        """Follow every world step (the world's truth samples: motors and true height at each 10 ms step, whenever
        this thread gets to read them) until every drone's motors are off and it rests on its floor, or the cap;
        what each drone did, in seconds from the parent's death. Each time is the stamp of the step that saw it:
        ``widest_step_s``, the longest interval between two steps the report read, bounds how late (a step of a
        world the host held back comes late and covers the whole interval). ``vz_at_motors_off``: the true vertical
        speed over the step that saw the motors stop (m/s, up positive; None when the motors were off before), so
        that the fall can be checked against a throw, not a drop from rest."""
        world = self._world
        world.truth_samples()  # the parent's log no longer takes them: from now on they are this report's
        dead_at, dead_world_s = time.monotonic(), world.time_s()
        addresses = world.addresses
        at_death = {a: world.snapshot(a) for a in addresses}
        floors = {a: world.firmware(a).vehicle.floor_z for a in addresses}
        motors_off = {a: 0.0 for a in addresses if not at_death[a].motors_on}
        cut_z = {a: at_death[a].position[2] for a in motors_off}
        at_rest = {a: 0.0 for a in addresses if not world.firmware(a).body().airborne}
        previous: float | None = None
        widest = 0.0
        heights: dict[int, tuple[float, float]] = {}
        """address -> its previous sample's (stamp, true height)."""
        cut_vz: dict[int, float] = {}
        while True:
            for stamp, states in world.truth_samples():
                if previous is not None:
                    widest = max(widest, stamp - previous)
                previous = stamp
                after = max(0.0, stamp - dead_at)
                for address, (position, _yaw, motors, _crashed, _estimate) in states.items():
                    if address not in floors:
                        continue
                    if motors:
                        motors_off.pop(address, None)  # spinning again (a high-level plan): not off yet
                    elif address not in motors_off:
                        motors_off[address], cut_z[address] = after, position[2]
                        if address in heights and stamp > heights[address][0]:
                            cut_vz[address] = (position[2] - heights[address][1]) / (stamp - heights[address][0])
                    heights[address] = (stamp, position[2])
                    if motors or position[2] > floors[address] + 1e-6:
                        at_rest.pop(address, None)
                    else:
                        at_rest.setdefault(address, after)
            elapsed = time.monotonic() - dead_at
            down = len(at_rest) == len(addresses)
            if down or elapsed >= self._cap_s:
                break
            time.sleep(ORPHAN_POLL_S)
        drones = {}
        for address in addresses:
            snap, before = world.snapshot(address), at_death[address]
            setpoint = before.last_crtp_setpoint_s
            drones[self._names.get(address, f"{address:010X}")] = {
                "address": f"{address:010X}",
                "position": list(snap.position),
                "z": snap.position[2],
                "floor_z": floors[address],
                "motors_on": snap.motors_on,
                "at_rest": address in at_rest,
                "crashed": snap.crashed,
                "supervisor_state": snap.supervisor_state,
                "locked": snap.locked,
                "flying": snap.flying,
                "control_source": snap.control_source,
                "hl_state": snap.hl_state,
                "motors_on_at_death": before.motors_on,
                "z_at_death": before.position[2],
                "control_source_at_death": before.control_source,
                "setpoint_age_at_death_s": None if setpoint is None else dead_world_s - setpoint,
                "motors_off_after_s": motors_off.get(address),
                "z_at_motors_off": cut_z.get(address),
                "vz_at_motors_off": cut_vz.get(address),
                "at_rest_after_s": at_rest.get(address),
            }
        return {
            "what": "the simulated drones after the flight's process died without closing the dry run",
            "detected_by": how,
            "parent_pid": self._parent_pid,
            "world_pid": os.getpid(),
            "parent_death_monotonic_s": dead_at,
            "parent_death_world_s": dead_world_s,
            "cap_s": self._cap_s,
            "capped": not down,
            "elapsed_s": elapsed,
            "widest_step_s": widest,
            "all_down": down,
            "drones": drones,
        }

    def _write(self, report: dict[str, Any]) -> None:
        """Write the report whole (a reader never sees half of it), then tell the terminal in one line: only if
        stderr can take it at once, as nobody may read that pipe any more."""
        where = "no report path given"
        if self._report is not None:
            partial = f"{self._report}.partial"
            try:
                with open(partial, "w", encoding="utf-8") as f:
                    json.dump(report, f, indent=2)
                    f.write("\n")
                os.replace(partial, self._report)
                where = f"report {self._report}"
            except OSError as err:
                where = f"report not written: {err}"
        down = sum(d["at_rest"] for d in report["drones"].values())
        line = (
            f"rpf-fly dry run: the flight's process died; {down} of {len(report['drones'])} simulated drones "
            f"down after {report['elapsed_s']:.1f} s ({where})\n"
        )
        try:
            if select.select([], [2], [], 0.5)[1]:
                os.write(2, line.encode()[:4096])  # a pipe that polls writable takes 4096 bytes without blocking
        except (OSError, ValueError):
            pass
