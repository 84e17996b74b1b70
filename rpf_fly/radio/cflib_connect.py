"""How the cflib backend (rpf_fly/radio/cflib_backend.py) connects and configures its drones, each link on a thread of
its own with a deadline, and restarts their estimators. Why apart: connecting is the backend's one long blocking
stage, with cflib's connection callbacks and parameter writes of its own; once it is done the backend only queues
commands and reads telemetry.

:class:`CflibConnection` is a part of :class:`~rpf_fly.radio.cflib_backend.CflibBackend`: it reads and sets the
backend's attributes named in its body.
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
from collections.abc import Callable, Mapping
from functools import partial
from typing import Any

import cflib.crtp
from cflib.crazyflie.log import LogConfig
from cflib.crazyflie.swarm import CachedCfFactory, Swarm
from cflib.crtp.radiodriver import RadioDriver

from rpf_fly.radio.budget import link_uri
from rpf_fly.radio.cflib_telemetry import CflibDrone, status_variables
from rpf_fly.radio.outbox import Action, SenderPool

from .backend import CONTROLLER_PARAMS, Vec3

logger = logging.getLogger("rpf_fly.radio.cflib_backend")  # the backend's records keep their logger's name


def _link_queue(cf: Any) -> queue.Queue[Any] | None:
    """cflib's bounded out queue of ``cf``'s link (``RadioDriver.out_queue``), None for a link without one."""
    out = getattr(getattr(cf, "link", None), "out_queue", None)
    return out if isinstance(out, queue.Queue) and out.maxsize > 0 else None


def link_room(cf: Any, timeout_s: float) -> bool:
    """Wait until ``cf``'s link can take a packet without blocking: cflib's radio link holds one between the sender
    and its driver thread (``RadioDriver.out_queue``, ``Queue(1)``), freed when the driver takes it for its next
    transaction. True at once for a link without such a queue (``fake://`` takes every packet at once); False when
    ``timeout_s`` passed first (the sender then blocks in cflib's send, as it would without this)."""
    out = _link_queue(cf)
    if out is None:
        return True
    with out.not_full:  # the queue's own condition (its mutex): notified once by each of the driver's gets
        room = out.not_full.wait_for(lambda: len(out.queue) < out.maxsize, timeout_s)
        # pass the wake-up on: a get notifies one waiter, and one of cflib's own senders (parameters, logging, its
        # ping) may be blocked in put for this slot; if this sender then sends nothing (a stale extpos dropped), that
        # put would wait out its 2 s timeout on an empty queue ("Could not send packet to copter")
        out.not_full.notify()
        return room


def _read_params(cf: Any, names: tuple[str, ...]) -> dict[str, float] | None:
    """The values of ``names`` the drone's parameters hold (cflib fetched them all at connect); those its TOC lacks
    or whose value is not a number are left out; None when none is there."""
    out = {}
    for name in names:
        if cf.param.toc.get_element_by_complete_name(name) is None:
            continue
        try:
            out[name] = float(cf.param.get_value(name))
        except Exception:  # cflib raises bare Exception when its values are not there
            continue
    return out or None


INITIAL_STATE_PARAMS: tuple[str, ...] = ("kalman.initialX", "kalman.initialY", "kalman.initialZ", "kalman.initialYaw")
"""The Kalman estimator's initial state (metres, radians), used at its next reset."""

ESTIMATOR_KALMAN = 2
VARIANCE_THRESHOLD_M2 = 0.001
"""Spread of the Kalman position variance over 10 samples below which the estimate counts as settled (cflib's)."""


class CflibConnection:
    """Connecting, configuring, estimator resets; the per-drone threads they run on."""

    _cache_dir: str | None
    _use_extpose: bool
    _ext_quat_std_dev: float
    _ext_pos_std_dev: float | None
    _reset_on_connect: bool
    _status_period_ms: int
    _connect_timeout_s: float
    _connect_timeouts: dict[str, float]
    _param_timeout_s: float
    _init_drivers: bool
    _packed_extpos: bool
    _rate_limits: dict[str, int]
    _lock: threading.RLock
    _drones: dict[str, CflibDrone]
    _swarm: Swarm | None
    _pool: SenderPool
    _start_packed: Callable[[list[str]], dict[str, str]]
    _live_cf: Callable[[str], Any | None]
    _send: Callable[[CflibDrone, Action], None]
    _on_status: Callable[[str, int, dict[str, float], LogConfig], None]
    _on_quality: Callable[[str, float], None]
    _on_latency: Callable[[str, float], None]
    _on_connection_lost: Callable[[str, str, str], None]
    _on_disconnected: Callable[[str, str], None]
    _on_uplink_rate: Callable[[str, float], None]
    _on_uplink_congestion: Callable[[str, float], None]

    def connect(self, drones: Mapping[str, str]) -> dict[str, str]:
        """Connect and configure all `drones` (name -> URI) in parallel; returns name -> error for failures."""
        if self._drones:
            raise RuntimeError("connect() was already called on this backend")
        uris = list(drones.values())
        if len(set(uris)) != len(uris):
            raise ValueError("two drones share a URI")
        if self._init_drivers and not any(
            isinstance(c, type) and issubclass(c, RadioDriver) for c in cflib.crtp.CLASSES
        ):
            cflib.crtp.init_drivers()
        with self._lock:
            self._drones = {
                name: CflibDrone(name, uri, link_uri(uri, self._rate_limits.get(name))) for name, uri in drones.items()
            }
        links = [d.link_uri for d in self._drones.values()]
        self._swarm = Swarm(links, factory=CachedCfFactory(rw_cache=self._cache_dir))
        by_uri = {d.link_uri: d for d in self._drones.values()}
        self._swarm.sequential(lambda scf, uri: setattr(by_uri[uri], "scf", scf), {u: [u] for u in links})
        longest = max((self.connect_timeout_of(n) for n in self._drones), default=self._connect_timeout_s)
        errors = self._parallel(self._connect_one, list(self._drones.values()), longest + 5.0)
        for name, message in errors.items():
            if message == "timed out":  # its thread is still running: make sure it never comes up
                self._give_up(self._drones[name], "connection timed out")
        if self._packed_extpos:
            errors.update(self._start_packed([n for n in self._drones if n not in errors]))
        if self._reset_on_connect:
            live = [n for n in self._drones if n not in errors]
            errors.update(self.reset_estimators(live))
        for name, message in errors.items():
            logger.warning("drone %s: %s", name, message)
        return errors

    def _parallel(
        self, func: Callable[[CflibDrone], None], drones: list[CflibDrone], timeout_s: float
    ) -> dict[str, str]:
        """Run `func(drone)` on one thread per drone; name -> error for those that raised or overran."""
        errors: dict[str, str] = {}

        def run(drone: CflibDrone) -> None:
            try:
                func(drone)
            except Exception as exc:  # per-drone errors are reported, not raised
                with self._lock:
                    errors[drone.name] = str(exc) or type(exc).__name__

        threads = [threading.Thread(target=run, args=(d,), name=f"rpf-{d.name}", daemon=True) for d in drones]
        for thread in threads:
            thread.start()
        deadline = time.monotonic() + timeout_s
        for drone, thread in zip(drones, threads):
            thread.join(max(deadline - time.monotonic(), 0.0))
            if thread.is_alive():
                with self._lock:
                    errors.setdefault(drone.name, "timed out")
        with self._lock:  # a thread that overran may still add its error later: hand out a copy
            return dict(errors)

    def connect_timeout_of(self, name: str) -> float:
        """How long the drone's connection and configuration may take (its own, or the backend's)."""
        return self._connect_timeouts.get(name, self._connect_timeout_s)

    def _connect_one(self, drone: CflibDrone) -> None:
        assert drone.scf is not None
        cf = drone.scf.cf
        done = threading.Event()
        failure: list[str] = []

        def on_fully_connected(uri: str) -> None:
            done.set()

        def on_failed(uri: str, message: str) -> None:
            failure.append(f"connection failed: {message}")
            done.set()

        def on_lost(uri: str, message: str) -> None:
            failure.append(f"connection lost while connecting: {message}")
            done.set()

        cf.connection_lost.add_callback(partial(self._on_connection_lost, drone.name))
        cf.disconnected.add_callback(partial(self._on_disconnected, drone.name))
        temporary = (
            (cf.fully_connected, on_fully_connected),
            (cf.connection_failed, on_failed),
            (cf.connection_lost, on_lost),
        )
        for caller, callback in temporary:
            caller.add_callback(callback)
        timeout_s = self.connect_timeout_of(drone.name)
        deadline = time.monotonic() + timeout_s
        try:
            cf.open_link(drone.link_uri)
            if not done.wait(timeout_s) or failure:
                message = failure[0] if failure else "connection timed out"
                self._give_up(drone, message)
                raise RuntimeError(message)
        finally:
            for caller, callback in temporary:
                caller.remove_callback(callback)
        try:
            self._configure(drone, deadline)
        except Exception as exc:
            self._give_up(drone, f"configuration failed: {exc}")
            raise RuntimeError(f"configuration failed: {exc}") from exc

    def _configure(self, drone: CflibDrone, deadline: float) -> None:
        scf = drone.scf
        assert scf is not None  # configured once its link opened
        cf = scf.cf
        # before anything else: release a setpoint priority an earlier connection left latched (module docstring)
        cf.commander.send_notify_setpoint_stop()
        toc = cf.param.toc
        self._set_param(cf, "stabilizer.estimator", ESTIMATOR_KALMAN)
        if toc.get_element_by_complete_name("commander.enHighLevel") is not None:
            self._set_param(cf, "commander.enHighLevel", 1)
        if self._use_extpose:
            self._set_param(cf, "locSrv.extQuatStdDev", self._ext_quat_std_dev)
        if self._ext_pos_std_dev is not None:
            self._set_param(cf, "locSrv.extPosStdDev", self._ext_pos_std_dev)
        drone.controller_params = _read_params(cf, CONTROLLER_PARAMS)
        stats = cf.link_statistics
        stats.link_quality_updated.add_callback(partial(self._on_quality, drone.name))
        stats.latency_updated.add_callback(partial(self._on_latency, drone.name))
        stats.uplink_rate_updated.add_callback(partial(self._on_uplink_rate, drone.name))
        stats.uplink_congestion_updated.add_callback(partial(self._on_uplink_congestion, drone.name))
        config = LogConfig(name="rpf_status", period_in_ms=self._status_period_ms)
        for variable, ctype in status_variables(cf.log.toc):
            config.add_variable(variable, ctype)
        cf.log.add_config(config)
        config.data_received_cb.add_callback(partial(self._on_status, drone.name))
        config.error_cb.add_callback(lambda conf, msg: logger.warning("drone %s: status log: %s", drone.name, msg))
        drone.log_config = config
        config.start()
        if not drone.first_status.wait(max(deadline - time.monotonic(), 2.0)):
            raise RuntimeError("no status log data")
        with self._lock:
            if drone.closing:
                raise RuntimeError("given up while configuring")
            room = partial(link_room, cf) if _link_queue(cf) is not None else None  # fake:// takes every packet
            drone.outbox = self._pool.outbox(drone.name, partial(self._send, drone), room)
            drone.up, drone.configured, drone.error = True, True, None

    def _set_param(self, cf: Any, name: str, value: float) -> None:
        """Write one parameter and wait for the firmware's echo; raises on timeout or a different value."""
        echoed: list[str] = []
        event = threading.Event()
        group, short = name.split(".")

        def on_update(_name: str, text: str) -> None:
            echoed.append(text)
            event.set()

        cf.param.add_update_callback(group=group, name=short, cb=on_update)
        try:
            cf.param.set_value(name, value)
            if not event.wait(self._param_timeout_s):
                raise RuntimeError(f"parameter {name} not confirmed")
            if not math.isclose(float(echoed[-1]), float(value), rel_tol=1e-6, abs_tol=1e-9):
                raise RuntimeError(f"parameter {name} is {echoed[-1]}, wanted {value}")
        finally:
            cf.param.remove_update_callback(group=group, name=short, cb=on_update)

    def _give_up(self, drone: CflibDrone, message: str) -> None:
        """Mark the drone failed and close its link (it never comes up afterwards)."""
        with self._lock:
            drone.up = False
            drone.error = message
            drone.closing = True
        try:
            if drone.scf is not None:
                drone.scf.cf.close_link()  # also stops cflib's receive thread when the link already failed
        except Exception:
            logger.exception("drone %s: closing a failed link", drone.name)

    def reset_estimators(self, names: list[str] | None = None, timeout_s: float = 10.0) -> dict[str, str]:
        """Reset the Kalman estimators (`kalman.resetEstimation`) and wait until the position variance settles
        (cflib's criterion: spread under 0.001 m^2 over ten samples at 2 Hz, so at least 5 s). Blocks; runs the
        drones in parallel; returns name -> error. With mocap positioning, stream extpos meanwhile."""
        targets = [self._drones[n] for n in (names if names is not None else list(self._drones))]
        return self._parallel(partial(self._reset_one, timeout_s=timeout_s), targets, timeout_s + 2.0)

    def _reset_one(self, drone: CflibDrone, timeout_s: float) -> None:
        cf = self._live_cf(drone.name)
        if cf is None:
            raise RuntimeError("link is down")
        samples: list[tuple[float, float, float]] = []
        settled = threading.Event()

        def on_data(_ts: int, data: dict[str, float], _conf: LogConfig) -> None:
            samples.append((data["kalman.varPX"], data["kalman.varPY"], data["kalman.varPZ"]))
            window = ([(1000.0,) * 3] * 10 + samples)[-10:]
            if all(max(s[i] for s in window) - min(s[i] for s in window) < VARIANCE_THRESHOLD_M2 for i in range(3)):
                settled.set()

        self._set_param(cf, "kalman.resetEstimation", 1)
        time.sleep(0.1)
        self._set_param(cf, "kalman.resetEstimation", 0)
        config = LogConfig(name="rpf_variance", period_in_ms=500)
        for axis in ("X", "Y", "Z"):
            config.add_variable(f"kalman.varP{axis}", "float")
        cf.log.add_config(config)
        config.data_received_cb.add_callback(on_data)
        config.start()
        try:
            if not settled.wait(timeout_s):
                raise RuntimeError("estimator did not settle")
        finally:
            config.stop()
            config.delete()

    def reset_estimator(self, name: str, position: Vec3, yaw_rad: float) -> bool:
        """Restart one drone's Kalman estimate at `position` (metres) and `yaw_rad` (radians), e.g. its mocap pose.

        Why: position-only extpos does not observe yaw, so the yaw estimate stays where the estimator started
        (`kalman.initialYaw`, 0 at power-on); a drone facing elsewhere flies off under position control. Writes
        `kalman.initialX/Y/Z/Yaw`, each confirmed by the firmware's echo, then `kalman.resetEstimation` = 1 (the
        firmware resets at its next estimator step and clears the flag itself). Blocks only for those five
        confirmations (milliseconds; `param_timeout_s` each at worst), not for the variance to settle: keep
        streaming extpos, which the estimator takes almost whole after the reset. Takes no command lock, so the
        drone's setpoints and extpos keep flowing meanwhile. Returns False when the link is down, a value is not
        finite, or a write is not confirmed; never raises for a known drone."""
        try:
            values = tuple(float(v) for v in (*position, yaw_rad))
        except (TypeError, ValueError):
            values = ()
        if len(values) != 4 or not all(math.isfinite(v) for v in values):
            logger.warning("drone %s: estimator reset refused: %r, %r", name, position, yaw_rad)
            return False
        cf = self._live_cf(name)
        if cf is None:
            return False
        try:
            for param, value in zip(INITIAL_STATE_PARAMS, values):
                self._set_param(cf, param, value)
            self._set_param(cf, "kalman.resetEstimation", 1)
        except Exception as exc:  # one drone's failure must not propagate
            logger.warning("drone %s: estimator reset failed: %s", name, exc)
            return False
        return True
