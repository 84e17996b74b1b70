"""A simulated lab: the mission's simulated Crazyflies and its Motive emulator, alive until stopped.

Real drones outlive the ground station that flies them: the firmware's commander priority, the supervisor's arming
and its timers, the estimator, the battery and where each drone landed carry over from ``rpf-fly check`` to
``rpf-fly fly`` to the next flight, and a drone whose ground station died flies on as its firmware would. A dry run
(``--dry-run``) boots fresh drones for each command and so cannot show what that carries; a lab can.

``rpf-fly lab MISSION`` runs a `Lab` in the foreground: the world server of
:mod:`rpf_fly.emulator.world_process` (the simulated drones, their radio server, the NatNet emulator and the fault
hooks), a listener that any number of ground stations connect to, one after the other or side by side
(``rpf-fly check|fly MISSION --lab``: `LabClient` through :class:`rpf_fly.flight.dry_run.DryRun`'s ``lab``), and its
own MCAP log from start to stop, whatever happens to the processes that connect to it:

- ``/truth/<drone>``: every 10 ms world step (the dry run's truth, docs/log-format.md);
- ``/firmware/<drone>``: each drone's supervisor, motors, commander and high-level commander at 10 Hz
  (``rpf_fly.FirmwareState``), and every supervisor transition as an event;
- ``/lab/host``: once a second, how far the host let the world fall behind (``rpf_fly.HostLag``,
  :mod:`rpf_fly.emulator.host_lag`); past the bound, an event;
- ``/events``: the lab's start and stop, each ground station's connection and its end (closed, or gone without
  closing: a killed or crashed process).

How to reach a running lab is written to the lab file (`lab_file`: ``$RPF_FLY_LAB``, else
``<temp dir>/rpf-fly-lab-<uid>.json``, readable by its owner only: it holds the control connection's key); the lab
removes it when it stops. A cflib program reaches the lab's drones with ``fake://`` URIs after
``fake_radio.register(lab_world())``, or with the mission's ``radio://`` URIs through cflib's own radio driver after
``crazyradio.plug(lab_world(), dongles=N, radio=TYPE)`` (`crazyradio_plug_call`).
"""

from __future__ import annotations

import json
import logging
import os
import secrets
import tempfile
import threading
import time
from collections import deque
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from multiprocessing.connection import Client, Listener
from pathlib import Path
from typing import Any

from rpf_fly.emulator.host_lag import HostLag
from rpf_fly.emulator.world_process import RemoteWorld, WorldCalls, WorldServer
from rpf_fly.flight import response
from rpf_fly.flight.agent import carrot_max_lead_m
from rpf_fly.flight.response import DEFAULT_GAINS
from rpf_fly.log import schemas as S
from rpf_fly.mission.model import Mission

logger = logging.getLogger(__name__)

LAB_ENV = "RPF_FLY_LAB"
"""The environment variable naming the lab file (several labs on one machine: one file each)."""

RECORD_PERIOD_S = 0.1
"""How often the lab's recorder takes the world's truth samples and the firmwares' states."""
HOST_PERIOD_S = 1.0
"""How often ``/lab/host`` is written."""
TRUTH_BUFFER = 1000
"""Truth samples each connected ground station's ``truth_samples`` keeps until it takes them (10 s at 100 Hz)."""


def lab_file() -> Path:
    """Where a running lab says how to reach it: ``$RPF_FLY_LAB``, else ``<temp dir>/rpf-fly-lab-<uid>.json``."""
    env = os.environ.get(LAB_ENV)
    if env:
        return Path(env)
    uid = os.getuid() if hasattr(os, "getuid") else 0
    return Path(tempfile.gettempdir()) / f"rpf-fly-lab-{uid}.json"


class LabNotRunning(RuntimeError):
    """No lab answers at the lab file (none started, or it is gone)."""


@dataclass(frozen=True)
class LabInfo:
    """How to reach a running lab (the lab file's content)."""

    pid: int
    mission: str
    """The mission file the lab was started with."""
    control: tuple[str, int]
    authkey: str
    """The control connection's key, hex."""
    radio: tuple[str, int]
    natnet_command_port: int | None
    addresses: dict[str, int]
    """drone name -> radio address."""
    log: str | None

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=2) + "\n"

    @classmethod
    def from_json(cls, text: str) -> LabInfo:
        d = json.loads(text)
        return cls(
            int(d["pid"]),
            str(d["mission"]),
            (d["control"][0], int(d["control"][1])),
            str(d["authkey"]),
            (d["radio"][0], int(d["radio"][1])),
            d.get("natnet_command_port"),
            {str(k): int(v) for k, v in d["addresses"].items()},
            d.get("log"),
        )


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def read_lab(path: Path | None = None) -> LabInfo:
    """The running lab's `LabInfo`; `LabNotRunning` with the one line to say when there is none."""
    path = lab_file() if path is None else path
    try:
        info = LabInfo.from_json(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise LabNotRunning(
            f"no lab is running ({path} does not exist): start one with `rpf-fly lab MISSION` "
            f"(another lab file: {LAB_ENV}=PATH)"
        ) from None
    except (OSError, ValueError, KeyError, IndexError, TypeError) as err:
        raise LabNotRunning(f"{path}: not a lab file ({err})") from None
    if not _alive(info.pid):
        raise LabNotRunning(f"the lab that wrote {path} (pid {info.pid}) is gone: start one with `rpf-fly lab MISSION`")
    return info


class LabClient(WorldCalls):
    """A ground station's control connection to a running lab: the fault hooks, snapshots and truth of its world
    (`WorldCalls`). Closing it leaves the lab and its drones as they are."""

    def __init__(self, info: LabInfo, timeout_s: float = 5.0) -> None:
        self._lock = threading.Lock()
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                host, port = info.control  # a JSON list in the lab's file
                self._conn: Any = Client((host, port), authkey=bytes.fromhex(info.authkey))
                break
            except OSError as err:
                if time.monotonic() > deadline:
                    raise LabNotRunning(
                        f"the lab (pid {info.pid}) does not answer at {info.control[0]}:{info.control[1]}: {err}"
                    ) from None
                time.sleep(0.1)
        self.addresses = tuple(info.addresses.values())

    def call(self, method: str, *args: Any) -> Any:
        with self._lock:
            if self._conn is None:
                raise RuntimeError(f"lab: {method} after close")
            self._conn.send((method, args))
            status, value = self._conn.recv()
        if status != "ok":
            raise RuntimeError(f"lab: {method} failed: {value}")
        return value

    def close(self) -> None:
        """Say goodbye and close the connection (the lab and its drones go on); idempotent."""
        with self._lock:
            conn, self._conn = self._conn, None
        if conn is None:
            return
        try:
            conn.send(("close", ()))
            conn.recv()
        except (OSError, EOFError):
            pass
        conn.close()


def lab_world(info: LabInfo | None = None) -> RemoteWorld:
    """What ``fake_radio.register`` (``fake://`` URIs with the mission's paths) or ``crazyradio.plug`` (the
    mission's ``radio://`` URIs) takes to reach the running lab's drones from a cflib program."""
    info = read_lab() if info is None else info
    return RemoteWorld(info.radio, tuple(info.addresses.values()))


def crazyradio_plug_call(mission: Mission) -> str:
    """The call that plugs emulated Crazyradios (`rpf_fly.emulator.crazyradio.plug`) for a lab of ``mission`` into a
    cflib program: one dongle per dongle number its URIs use, of its dry run's type."""
    from rpf_fly.flight.dry_run import uri_dongle

    dongles = 1 + max(uri_dongle(d.uri) for d in mission.drones)
    kind = mission.dry_run.crazyradio or mission.radio.dongle_type
    return f'crazyradio.plug(lab_world(), dongles={dongles}, radio="{kind}")'


class _TruthFanout:
    """The lab's recorder is the world's one truth reader; each connected ground station gets its own copy."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._subscribers: dict[int, deque[Any]] = {}
        self._next = 0

    def subscribe(self) -> int:
        with self._lock:
            self._next += 1
            self._subscribers[self._next] = deque(maxlen=TRUTH_BUFFER)
            return self._next

    def unsubscribe(self, key: int) -> None:
        with self._lock:
            self._subscribers.pop(key, None)

    def publish(self, samples: list[Any]) -> None:
        with self._lock:
            for buffer in self._subscribers.values():
                buffer.extend(samples)

    def take(self, key: int) -> list[Any]:
        with self._lock:
            buffer = self._subscribers.get(key)
            if buffer is None:
                return []
            out = list(buffer)
            buffer.clear()
            return out


class Lab:
    """The simulated drones and Motive emulator of ``mission``, serving ground stations until `close` (module doc).

    ``start_faults``: how drones stand at power-on (`rpf_fly.flight.dry_run.StartFault` by drone name);
    ``log_path``: the lab's MCAP log (None: no log); ``path``: the lab file (default `lab_file`)."""

    def __init__(
        self,
        mission: Mission,
        mission_path: str | os.PathLike[str],
        log_path: Path | None,
        *,
        start_faults: Mapping[str, Any] | None = None,
        seed: int | None = None,
        host: str = "127.0.0.1",
        path: Path | None = None,
    ) -> None:
        from rpf_fly.flight.dry_run import RADIO_LOSS, mission_mocap_noise, simulated_drones, uri_address

        self.mission = mission
        self.mission_path = os.fspath(mission_path)
        self.log_path = log_path
        self.path = lab_file() if path is None else path
        self.names = {uri_address(d.uri): d.name for d in mission.drones}
        self.seed = mission.dry_run.seed if seed is None else seed
        m = mission.mocap
        self._settings = {
            "drones": simulated_drones(mission, None, start_faults, RADIO_LOSS),
            "bodies": {uri_address(d.uri): d.rigid_body for d in mission.drones},
            "seed": self.seed,
            "obstacles": tuple(mission.obstacles),
            "host": host,
            "natnet": {
                "version": "4.1",
                "rate_hz": m.rate_hz,
                "up_axis": m.up_axis,
                "multicast": m.kind == "motioncapture",
            },
            "mocap_noise": mission_mocap_noise(mission),
        }
        self._authkey = secrets.token_bytes(32)
        self._stop = threading.Event()
        self._truth = _TruthFanout()
        self._threads: list[threading.Thread] = []
        self._connections = 0
        self._conn_lock = threading.Lock()
        self.server: WorldServer | None = None
        self.log: Any = None
        self.info: LabInfo | None = None
        self._listener: Any = None
        self._reported_behind_s = 0.0

    # -------------------------------------------------------------------------------------------- life

    def start(self) -> LabInfo:
        """Power the drones on, open the listener and the log, and write the lab file; raises `RuntimeError` if
        another lab answers at the lab file."""
        try:
            running = read_lab(self.path)
        except LabNotRunning:
            running = None
        if running is not None:
            raise RuntimeError(
                f"a lab is already running (pid {running.pid}, {running.mission}; lab file "
                f"{self.path}): stop it, or give this one another lab file ({LAB_ENV}=PATH)"
            )
        if self.log_path is not None:
            from rpf_fly.log.writer import FlightLog

            meta = S.mission_metadata(self.mission, self.seed, source="lab")
            self.log = FlightLog(self.log_path, meta, S.scenario_metadata(self.mission))
        self.server = WorldServer(self._settings)
        self._listener = Listener(("127.0.0.1", 0), authkey=self._authkey)
        ports = self.server.ports()
        self.info = LabInfo(
            os.getpid(),
            self.mission_path,
            tuple(self._listener.address),
            self._authkey.hex(),
            tuple(ports["radio"]),
            ports["natnet_command_port"],
            {name: address for address, name in self.names.items()},
            os.fspath(self.log_path) if self.log_path is not None else None,
        )
        partial = self.path.with_name(self.path.name + ".partial")
        fd = os.open(partial, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(self.info.to_json())
        os.replace(partial, self.path)
        self._event(2, f"lab started: {len(self.names)} simulated drones of {self.mission.name} (pid {os.getpid()})")
        for target, name in ((self._accept, "lab-accept"), (self._record, "lab-record")):
            thread = threading.Thread(target=target, name=name, daemon=True)
            thread.start()
            self._threads.append(thread)
        return self.info

    def wait(self, timeout_s: float | None = None) -> bool:
        """Block until `close` is called or ``timeout_s`` passed; True if stopped."""
        return self._stop.wait(timeout_s)

    def close(self) -> None:
        """Stop: the lab file goes, the world powers the drones off, the log ends with the last state; idempotent."""
        if self._stop.is_set():
            return
        self._stop.set()
        try:
            if self.info is not None and read_lab(self.path).pid == os.getpid():
                self.path.unlink(missing_ok=True)
        except LabNotRunning:
            pass
        if self._listener is not None:
            try:
                self._listener.close()
            except OSError:
                pass
        for thread in self._threads:
            if thread.name == "lab-record":
                thread.join(timeout=2.0)
        if self.log is not None:
            self._event(2, "lab stopped")
        if self.server is not None:
            self.server.close()
        if self.log is not None:
            self.log.close()

    def __enter__(self) -> Lab:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def host_lag(self) -> HostLag:
        assert self.server is not None
        return self.server.host_lag()

    # ------------------------------------------------------------------------------------ ground stations

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                conn = self._listener.accept()
            except (OSError, EOFError):
                if self._stop.is_set():
                    return
                continue  # a bad key or a dropped handshake: that caller only
            thread = threading.Thread(target=self._serve, args=(conn,), name="lab-connection", daemon=True)
            thread.start()

    def _serve(self, conn: Any) -> None:
        assert self.server is not None
        key = self._truth.subscribe()
        with self._conn_lock:
            self._connections += 1
            n = self._connections
        self._event(2, f"ground station {n} connected")
        how = "closed its connection"
        try:
            with conn:
                while not self._stop.is_set():
                    try:
                        method, args = conn.recv()
                    except (EOFError, OSError):
                        how = "went away without closing (killed, or crashed)"
                        return
                    if method == "close":
                        conn.send(("ok", None))
                        return
                    if method == "truth_samples":
                        conn.send(("ok", self._truth.take(key)))
                    else:
                        conn.send(self.server.handle(method, args))
        except (OSError, EOFError):
            how = "went away without closing (killed, or crashed)"
        finally:
            self._truth.unsubscribe(key)
            if not self._stop.is_set():
                self._event(
                    3 if "without" in how else 2, f"ground station {n} {how}; the drones fly on as their firmware does"
                )

    # ------------------------------------------------------------------------------------------ recording

    def _event(self, level: int, message: str, drone: str = "") -> None:
        logger.log(logging.WARNING if level >= 3 else logging.INFO, "lab: %s%s", f"{drone}: " if drone else "", message)
        if self.log is not None:
            self.log.event(time.time_ns(), level, f"{drone}: {message}" if drone else message, name="rpf_fly.lab")

    def _record(self) -> None:
        assert self.server is not None
        world = self.server.world
        offset_ns = time.time_ns() - time.monotonic_ns()
        seen: dict[int, float] = {}
        next_host = time.monotonic()
        while True:
            stopping = self._stop.wait(RECORD_PERIOD_S)
            try:
                samples = world.truth_samples()
                self._truth.publish(samples)
                if self.log is not None:
                    for stamp, states in samples:
                        self.log.truth(
                            offset_ns + int(stamp * 1e9), {self.names.get(a, f"{a:010X}"): s for a, s in states.items()}
                        )
                    self._firmware(world, offset_ns, seen)
                if time.monotonic() >= next_host or stopping:
                    next_host += HOST_PERIOD_S
                    self._host()
            except Exception:  # noqa: BLE001 - the recorder must outlive one bad sample
                logger.exception("lab recorder")
            if stopping:
                return

    def _firmware(self, world: Any, offset_ns: int, seen: dict[int, float]) -> None:
        now_world, now_mono = world.time_s(), time.monotonic()
        for address, name in self.names.items():
            snap = world.snapshot(address)
            t_ns = offset_ns + int((now_mono - (now_world - snap.time_s)) * 1e9)
            setpoint = snap.last_crtp_setpoint_s
            self.log.message(
                f"/firmware/{name}",
                t_ns,
                t_ns,
                S.encode(
                    {
                        "timestamp": S.stamp(t_ns),
                        "powered": snap.powered and not snap.booting,
                        "supervisor": snap.supervisor_state,
                        "armed": snap.armed,
                        "motors": snap.motors_on,
                        "flying": snap.flying,
                        "locked": snap.locked,
                        "crashed": snap.crashed,
                        "emergency_stop": snap.emergency_stop_latched,
                        "commander": snap.control_source,
                        "high_level": snap.hl_state,
                        "setpoint_age_s": None if setpoint is None else max(0.0, snap.time_s - setpoint),
                        "battery_v": snap.vbat_v,
                        "boots": snap.boots,
                    }
                ),
            )
            last = seen.get(address, -1.0)
            for transition in snap.transitions:
                if transition.time_s > last:
                    level = 3 if transition.new.value in ("Exception, free fall", "Locked") else 2
                    self._event(level, f"supervisor {transition.old.value} -> {transition.new.value}", name)
                    seen[address] = transition.time_s

    def _host(self) -> None:
        lag = self.host_lag()
        if self.log is not None:
            t_ns = time.time_ns()
            self.log.message("/lab/host", t_ns, t_ns, S.encode({"timestamp": S.stamp(t_ns), **lag.as_dict()}))
        if not lag.kept_up and (self._reported_behind_s == 0 or lag.behind_s >= self._reported_behind_s + 1.0):
            self._reported_behind_s = lag.behind_s
            self._event(3, lag.sentence())


@dataclass(frozen=True)
class AfterDeath:
    """What one drone did after its ground station died, on the lab's truth (`after_ground_station`)."""

    down_after_s: float | None
    """Seconds from the death until its motors were off or it stood on the floor (None: neither by the end)."""
    moved_m: float
    """The largest horizontal distance from where it was at the death, at any later truth sample."""
    z_at_death: float
    motors_at_death: bool
    flying_at_s: dict[float, bool]
    """For each asked time after the death: above the floor (`FLOOR_Z_M`) with its motors on."""


FLOOR_Z_M = 0.05
"""A drone at or below this true height stands on the floor (its centre: 0 on the floor in the simulated world)."""


def reach_after_death_m(mission: Mission, height_m: float) -> float:
    """How far a drone of ``mission`` flying at ``height_m`` may go horizontally once its ground station died
    (`rpf_fly.flight.response.reach_after_death_m` at the mission's speed, its carrot's largest lead, the firmware's
    default gains): what `after_ground_station`'s ``moved_m`` is judged against."""
    speed = mission.flight.speed
    return response.reach_after_death_m(DEFAULT_GAINS, speed, carrot_max_lead_m(speed, DEFAULT_GAINS), height_m)


def after_ground_station(
    truth: Mapping[str, list[Any]], death_ns: int, checks_s: tuple[float, ...] = (5.0,)
) -> dict[str, AfterDeath]:
    """Judge the drones after their ground station died at ``death_ns`` (ns since the Unix epoch), from a lab's
    ``/truth/<drone>`` messages (`rpf_fly.log.reader.LogData.messages`, by drone name)."""
    out = {}
    for name, messages in truth.items():
        before = [m for m in messages if m.log_time <= death_ns]
        after = [m for m in messages if m.log_time > death_ns]
        if not before or not after:
            raise ValueError(f"{name}: the lab's truth does not cover the ground station's death")
        at = before[-1].data
        x0, y0 = at["position"]["x"], at["position"]["y"]
        down = None
        moved = 0.0
        for m in after:
            p = m.data["position"]
            moved = max(moved, ((p["x"] - x0) ** 2 + (p["y"] - y0) ** 2) ** 0.5)
            if down is None and (not m.data["motors"] or p["z"] <= FLOOR_Z_M):
                down = (m.log_time - death_ns) / 1e9
        flying = {}
        for t in checks_s:
            later = [m for m in after if m.log_time >= death_ns + int(t * 1e9)]
            if not later:
                raise ValueError(f"{name}: the lab's truth ends before {t:g} s after the ground station's death")
            d = later[0].data
            flying[t] = bool(d["motors"]) and d["position"]["z"] > FLOOR_Z_M
        out[name] = AfterDeath(down, moved, at["position"]["z"], bool(at["motors"]), flying)
    return out
