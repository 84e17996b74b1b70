"""``FlightLog``: the MCAP flight log, written by one background thread so the flight loop never waits on disk.

Callers (flight loop, mocap thread, radio callbacks; any number of threads) only append a small tuple to a queue:
the message is built and serialised to JSON on the writer thread, which drains the queue every 50 ms into zstd
chunks and closes the open chunk about once a second (``flush``), so a SIGKILL or power cut loses at most about
one second: the file is then unfinished but :func:`rpf_fly.log.reader.read_log` reads every complete chunk and
:func:`rpf_fly.log.reader.salvage` rewrites it into a finished file.

Queue policy (docs/log-format.md): the queue is bounded (``max_queue`` messages, default 50 000, several seconds of
a 10-drone flight). When it is full a new high-rate message (pose, setpoint, planner step, status, tf, truth) is
dropped, never blocking the caller; events and scene updates still enter up to twice the bound. A batch call
(:meth:`FlightLog.poses`, :meth:`FlightLog.setpoints`, :meth:`FlightLog.planner_steps`, :meth:`FlightLog.truth`: one
queue entry for one tick of every drone; about half the caller's cost a message, hot) counts as its messages and
enters or drops whole. Drops are counted (:attr:`FlightLog.dropped`), leave a gap in the topic's ``sequence``
(sequences are drawn at the call), are reported with a Python ``logging`` warning and as a warning on ``/events``
at most once per flush, and are summarised on ``/events`` at close. Calls after :meth:`FlightLog.close` are
ignored (and counted as dropped). A write error (disk full) is logged once, kept in :attr:`FlightLog.error`, and
the log stops writing; nothing is raised into the flight loop.

Arguments are serialised later on the writer thread: do not mutate them after the call (pass tuples, floats,
fresh arrays). Timestamps are integer nanoseconds since the Unix epoch: ``t_ns`` is the message's publish time
(when the data was created: mocap frame time, planner tick); the log time is the ``clock()`` at the call (when
recorded), or ``t_ns`` itself with ``clock=None`` (simulated runs) and for ``/truth`` (its samples arrive in
batches).

A ``sink`` (the live view, :mod:`rpf_fly.log.live`) sees every message the writer wrote, right after it went into
the file, on the writer thread: ``sink(topic, log_time, data)`` with the very bytes of the file. So whatever else
serves the flight shows what the log holds (no second encoding), and the flight loop never waits on it.
"""

from __future__ import annotations

import atexit
import collections
import itertools
import json
import logging
import threading
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, BinaryIO

from mcap.writer import CompressionType, Writer

from rpf_fly.log import schemas as S
from rpf_fly.log.encoding import encode, planner_json, pose_json, tf_json, truth_json
from rpf_fly.log.messages import drone_status, log_message, radio_load, scene_update, yaw_quaternion

logger = logging.getLogger(__name__)

DEFAULT_MAX_QUEUE = 50_000
FLUSH_INTERVAL_S = 1.0
POLL_INTERVAL_S = 0.05
CHUNK_SIZE = 1 << 20

Sink = Callable[[str, int, bytes], None]
"""``sink(topic, log_time_ns, data)``: called on the writer thread for each message written (see :class:`FlightLog`)."""

Out = Callable[[str, int, int, bytes], None]
"""``out(topic, log_time_ns, publish_time_ns, data)``: where a :class:`FlightLog` built with ``out`` sends each
message instead of a file (a distributed flight's worker publishes them on Zenoh: rpf_fly/runtime/bus.py)."""


class _OutWriter:
    """The part of ``mcap.writer.Writer`` that :class:`FlightLog` uses, handing each message to ``out``."""

    def __init__(self, out: Out):
        self._out = out
        self._topics: list[str] = []

    def start(self, **_: object) -> None: ...
    def add_metadata(self, *_: object) -> None: ...
    def flush(self) -> None: ...
    def finish(self) -> None: ...

    def register_schema(self, *_: object) -> int:
        return 0

    def register_channel(self, topic: str, *_: object) -> int:
        self._topics.append(topic)
        return len(self._topics) - 1

    def add_message(self, channel: int, log_time: int, data: bytes, publish_time: int, sequence: int = 0) -> None:
        self._out(self._topics[channel], log_time, publish_time, data)


class _NoFile:
    def close(self) -> None: ...


def _strings(meta: Mapping[str, Any]) -> dict[str, str]:
    """Metadata values as strings (MCAP metadata is string to string): non-strings as JSON."""
    return {str(k): v if isinstance(v, str) else json.dumps(v) for k, v in meta.items()}


def _raw_message(t_ns: int, data: bytes) -> bytes:
    return data


def _status_message(t_ns: int, fields: dict[str, Any]) -> dict[str, Any]:
    return drone_status(t_ns, **fields)


def _setpoint_message(t_ns: int, position: Any, yaw: float) -> bytes:
    return pose_json(t_ns, position, yaw_quaternion(yaw))


def _scene_message(t_ns: int, fields: dict[str, Any]) -> dict[str, Any]:
    return scene_update(t_ns, **fields)


class FlightLog:
    """An MCAP flight log being written (context manager). See the module docstring for the threading and the
    queue policy and docs/log-format.md for the topics.

    ``mission_meta`` and ``scenario_meta`` become the ``mission`` and ``scenario`` metadata records (string values;
    other values are stored as JSON); build them with :func:`rpf_fly.log.metadata.mission_metadata` and
    :func:`rpf_fly.log.metadata.scenario_metadata`. Opening the file happens here, so a bad path raises at once
    (``OSError``), before the flight.

    ``clock``: the log-time source (ns since the Unix epoch; None: log time = ``t_ns``). ``block_when_full``:
    wait for room instead of dropping, for offline writers (simulated runs) only, never in a flight.
    ``poll_interval_s``: how often the writer drains the queue by itself (see :meth:`drain_soon`).
    ``sink``: called on the writer thread with each message written, ``(topic, log_time, data)``, the bytes of the
    file (the live view). It must not block: it runs between writes. An exception it raises loses that message for
    the sink only (counted in :attr:`sink_failed`, the first one logged), never the log. Messages the queue dropped,
    and everything after a write error, never reach it.
    """

    def __init__(
        self,
        path: str | Path,
        mission_meta: Mapping[str, Any],
        scenario_meta: Mapping[str, Any],
        *,
        clock: Callable[[], int] | None = time.time_ns,
        max_queue: int = DEFAULT_MAX_QUEUE,
        flush_interval_s: float = FLUSH_INTERVAL_S,
        chunk_size: int = CHUNK_SIZE,
        name: str = "rpf_fly",
        block_when_full: bool = False,
        poll_interval_s: float = POLL_INTERVAL_S,
        sink: Sink | None = None,
        out: Out | None = None,
    ):
        from rpf_fly import __version__

        self.path = Path(path)
        self.name = name
        self.max_queue = int(max_queue)
        self.block_when_full = bool(block_when_full)
        self.flush_interval_s = float(flush_interval_s)
        self.poll_interval_s = float(poll_interval_s)
        self.error: BaseException | None = None
        self.written = 0
        self.failed = 0
        self.sink_failed = 0
        self._sink = sink
        self.writer_cpu_s = 0.0
        self.queue_peak = 0
        self._clock = clock
        self._dropped = 0
        self._drop_lock = threading.Lock()
        self._reported_drops = 0
        self._queue: collections.deque = collections.deque()
        self._pushed = 0  # messages queued so far (a batch entry holds several), under _push_lock
        self._push_lock = threading.Lock()
        self._popped = 0  # messages taken off the queue so far (writer thread only)
        self._closed = False
        self._close_lock = threading.Lock()
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._poses: dict[str, tuple[str, Any]] = {}
        self._setpoints: dict[str, tuple[str, Any]] = {}
        self._planner: dict[str, tuple[str, Any]] = {}
        self._status: dict[str, tuple[str, Any]] = {}
        self._truth: dict[str, tuple[str, Any]] = {}
        self._radio: dict[str, tuple[str, Any]] = {}
        self._fixed = {name: (name, itertools.count()) for name in ("/scene", "/tf", "/events")}
        self._raw: dict[str, tuple[str, Any]] = {}
        self._channels: dict[str, int] = {}
        self._schema_ids: dict[str, int] = {}
        self._file: BinaryIO | _NoFile = _NoFile()
        try:
            if out is not None:
                self._writer: Any = _OutWriter(out)
            else:
                self._file = file = open(self.path, "wb")
                self._writer = Writer(file, chunk_size=chunk_size, compression=CompressionType.ZSTD)
            self._writer.start(profile="", library=f"rpf_fly {__version__}")
            self._writer.add_metadata("mission", _strings(mission_meta))
            self._writer.add_metadata("scenario", _strings(scenario_meta))
            self._writer.flush()
        except BaseException:
            self._file.close()
            raise
        self._thread = threading.Thread(target=self._run, name=f"flight-log:{self.path.name}", daemon=True)
        self._thread.start()
        atexit.register(self.close)

    # ------------------------------------------------------------------ context manager

    def __enter__(self) -> FlightLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ the public calls (any thread, never block)

    @property
    def dropped(self) -> int:
        """Messages refused because the queue was full or the log was closed."""
        return self._dropped

    @property
    def closed(self) -> bool:
        return self._closed

    def pose(
        self, drone: str, t_ns: int, position_xyz: Sequence[float], quaternion_xyzw: Sequence[float] | None = None
    ) -> None:
        """``/mocap/<drone>``: the pose as received (frame ``world``; quaternion ``(qx, qy, qz, qw)``, None:
        identity). ``t_ns``: the mocap frame time."""
        self._put(
            self._poses.get(drone) or self._topic(self._poses, "/mocap/{}", drone),
            t_ns,
            pose_json,
            (position_xyz, quaternion_xyzw),
        )

    def poses(self, t_ns: int, poses: Mapping[str, tuple[Sequence[float], Sequence[float] | None]]) -> None:
        """``/mocap/<drone>`` of several drones at one frame time ``{drone: (position, quaternion)}``: the same
        messages as :meth:`pose` per drone, queued as one entry (a flight logs every frame of every drone)."""
        self._put_batch(self._poses, "/mocap/{}", [(d, t_ns, v) for d, v in poses.items()], pose_json)

    def setpoints(self, setpoints: Iterable[tuple[str, int, Sequence[float], float]]) -> None:
        """``/<drone>/setpoint`` of several drones, ``(drone, t_ns, position, yaw)`` each (each its own send time):
        the same messages as :meth:`setpoint` per drone, queued as one entry."""
        self._put_batch(
            self._setpoints, "/{}/setpoint", [(d, t, (p, yaw)) for d, t, p, yaw in setpoints], _setpoint_message
        )

    def planner_steps(
        self, t_ns: int, steps: Mapping[str, Any], build: Callable[[int, Any], bytes | dict] = planner_json
    ) -> None:
        """``/<drone>/planner`` of several drones at one tick, queued as one entry. ``steps``: ``{drone: value}``;
        ``build(t_ns, value)`` makes each message on the writer thread (default: ``value`` is the fields mapping of
        :meth:`planner_step`). A flight's recorder passes its own ``build`` so that the loop thread only hands
        over references (rpf_fly/flight/recording.py)."""
        self._put_batch(self._planner, "/{}/planner", [(d, t_ns, (v,)) for d, v in steps.items()], build)

    def truth(
        self, t_ns: int, states: Mapping[str, tuple[Sequence[float], float, bool, bool, Sequence[float]]]
    ) -> None:
        """``/truth/<drone>`` of every drone at one sample of a dry run's simulated world, queued as one entry:
        ``{drone: (position, yaw, motors, crashed, estimate)}`` (metres, radians; see
        :func:`rpf_fly.log.messages.truth_state`). ``t_ns``: when the world was in that state. Log time = ``t_ns``
        (not the clock at the call): the samples reach the flight's process in batches (docs/log-format.md)."""
        self._put_batch(
            self._truth, "/truth/{}", [(d, t_ns, v) for d, v in states.items()], truth_json, log_at_publish=True
        )

    def setpoint(self, drone: str, t_ns: int, position_xyz: Sequence[float], yaw_rad: float = 0.0) -> None:
        """``/<drone>/setpoint``: the position setpoint sent, with its yaw (radians) as the orientation."""
        self._put(
            self._setpoints.get(drone) or self._topic(self._setpoints, "/{}/setpoint", drone),
            t_ns,
            _setpoint_message,
            (position_xyz, yaw_rad),
        )

    def planner_step(self, drone: str, t_ns: int, **fields: Any) -> None:
        """``/<drone>/planner``: one planning tick (fields of :func:`rpf_fly.log.messages.planner_step`: tick,
        position, goal, mode, eta, lam or lambda, f_a, f_r, f_in, direction, heading, neighbours,
        obstacle_distance, goal_distance)."""
        self._put(
            self._planner.get(drone) or self._topic(self._planner, "/{}/planner", drone), t_ns, planner_json, (fields,)
        )

    def status(self, drone: str, t_ns: int, **fields: Any) -> None:
        """``/<drone>/status``: state, battery_v, link_quality, latency_ms, outcome."""
        self._put(
            self._status.get(drone) or self._topic(self._status, "/{}/status", drone), t_ns, _status_message, (fields,)
        )

    def radio(self, t_ns: int, dongle: int, **fields: Any) -> None:
        """``/radio/<dongle>``: one window of a dongle's measured load (fields of
        :func:`rpf_fly.log.messages.radio_load`: drones, window_s, packets, transactions, planned_per_s,
        budget_per_s, optionally setpoints_superseded). Once a second per dongle: never dropped for a full queue
        (as events)."""
        topic = self._radio.get(str(dongle)) or self._topic(self._radio, "/radio/{}", str(dongle))
        self._put(
            topic,
            t_ns,
            radio_load,
            (
                dongle,
                *(
                    fields[k]
                    for k in ("drones", "window_s", "packets", "transactions", "planned_per_s", "budget_per_s")
                ),
                float(fields.get("setpoints_superseded", 0.0)),
            ),
            priority=True,
        )

    def scene(
        self,
        t_ns: int,
        obstacles: Sequence[Mapping[str, Any]] = (),
        goals: Mapping[str, Any] | None = None,
        arena: Mapping[str, Sequence[float]] | None = None,
        height: float = 0.0,
    ) -> None:
        """``/scene``: obstacles (``{shape, center, radius}`` / ``{shape, min, max}``), goals ``{name: (x, y)}``,
        arena ``{x, y, z}`` ranges, goal markers at ``height``."""
        fields = {"obstacles": list(obstacles), "goals": dict(goals or {}), "arena": arena, "height": height}
        self._put(self._fixed["/scene"], t_ns, _scene_message, (fields,), priority=True)

    def tf(self, t_ns: int, poses: Mapping[str, tuple[Sequence[float], Sequence[float] | None]]) -> None:
        """``/tf``: transforms world -> each drone, ``{drone: (position, quaternion)}``."""
        self._put(self._fixed["/tf"], t_ns, tf_json, (dict(poses),))

    def event(self, t_ns: int, level: int, message: str, name: str = "rpf_fly", file: str = "", line: int = 0) -> None:
        """``/events``: a ``foxglove.Log`` (level 1 debug, 2 info, 3 warning, 4 error, 5 fatal)."""
        self._put(self._fixed["/events"], t_ns, log_message, (level, message, name, file, line), priority=True)

    def message(self, topic: str, t_ns: int, log_time: int, data: bytes) -> None:
        """A message already encoded (the logger of a distributed flight: the bytes a worker published), with its
        own publish and log times; its topic's sequence is this log's."""
        entry = self._raw.get(topic) or self._raw.setdefault(topic, (topic, itertools.count()))
        sequence = next(entry[1])
        if self._closed or not self._room(1, topic == "/events"):
            self._count_drop()
            return
        self._enqueue(1, (topic, sequence, int(t_ns), int(log_time), _raw_message, (data,)))

    def metadata(self, name: str, values: Mapping[str, Any]) -> None:
        """A metadata record written by the writer thread in queue order (values as in ``mission_meta``)."""
        if self._closed:
            return
        self._enqueue(1, (None, 0, 0, 0, None, (name, _strings(values))))

    def drain_soon(self) -> None:
        """Wake the writer thread to drain the queue now rather than at its next poll.

        The writer holds the GIL while it drains (a few ms for 50 ms of a 10-drone flight); a flight loop calls
        this right after a planning tick so that burst falls in the loop's idle gap instead of between a mocap
        frame and its setpoints (with a long ``poll_interval_s``, the poll is only a fallback)."""
        self._wake.set()

    def close(self) -> None:
        """Drain the queue, finish the file (summary and footer) and join the writer thread. Idempotent."""
        with self._close_lock:
            if self._closed:
                return
            self._closed = True
        atexit.unregister(self.close)
        self._stop.set()
        self._wake.set()
        if self._thread is not threading.current_thread():
            self._thread.join()
        with self._push_lock:
            leftover = self._pending()
            self._popped = self._pushed
            self._queue.clear()
        if leftover:
            self._count_drop(leftover)

    # ------------------------------------------------------------------ internals

    @staticmethod
    def _topic(table: dict[str, tuple[str, Any]], pattern: str, drone: str) -> tuple[str, Any]:
        """The (name, sequence counter) of a drone's topic, made on first use (setdefault: thread-safe)."""
        return table.setdefault(drone, (pattern.format(drone), itertools.count()))

    def _count_drop(self, n: int = 1) -> None:
        with self._drop_lock:
            self._dropped += n

    def _pending(self) -> int:
        return self._pushed - self._popped

    def _room(self, n: int, priority: bool) -> bool:
        """Whether ``n`` more messages may enter the queue (``block_when_full``: wait for room instead)."""
        bound = self.max_queue * (2 if priority else 1)
        if self._pending() + n <= bound or not self._pending():
            return True
        if not self.block_when_full:
            return False
        while self._pending() + n > bound and self._pending() and self._thread.is_alive():  # offline writers only
            self._wake.set()
            time.sleep(0.0005)
        return True

    def _enqueue(self, n: int, entry: tuple) -> None:
        with self._push_lock:
            self._pushed += n
            self._queue.append(entry)

    def _put(
        self, topic: tuple[str, Any], t_ns: int, build: Callable[..., bytes | dict], args: tuple, priority: bool = False
    ) -> None:
        sequence = next(topic[1])
        if self._closed:
            self._count_drop()
            return
        if self._pushed - self._popped >= self.max_queue and not self._room(1, priority):
            self._count_drop()
            return
        log_time = t_ns if self._clock is None else self._clock()
        self._enqueue(1, (topic[0], sequence, t_ns, log_time, build, args))

    def _put_batch(
        self,
        table: dict[str, tuple[str, Any]],
        pattern: str,
        items: list[tuple[str, int, Any]],
        build: Callable[..., bytes | dict],
        log_at_publish: bool = False,
    ) -> None:
        """Queue one message per ``(drone, t_ns, args)`` as one entry; ``build(t_ns, *args)`` runs on the writer.
        ``log_at_publish``: each message's log time is its ``t_ns`` instead of the clock at the call."""
        if not items:
            return
        topics, sequences = [], []
        for drone, _, _ in items:
            topic = table.get(drone) or self._topic(table, pattern, drone)
            topics.append(topic[0])
            sequences.append(next(topic[1]))
        n = len(items)
        if self._closed or not self._room(n, False):
            self._count_drop(n)
            return
        log_time = None if self._clock is None or log_at_publish else self._clock()
        self._enqueue(n, (topics, sequences, None, log_time, build, items))

    def _channel(self, topic: str) -> int:
        channel = self._channels.get(topic)
        if channel is None:
            schema_name = S.topic_schema(topic)
            schema = self._schema_ids.get(schema_name)
            if schema is None:
                schema = self._writer.register_schema(schema_name, S.SCHEMA_ENCODING, S.schema_bytes(schema_name))
                self._schema_ids[schema_name] = schema
            channel = self._writer.register_channel(topic, S.MESSAGE_ENCODING, schema)
            self._channels[topic] = channel
        return channel

    def _write(self, topic: str, sequence: int, t_ns: int, log_time: int, message: dict | bytes) -> None:
        if self.error is not None:
            return
        data = message if isinstance(message, bytes) else encode(message)
        try:
            self._writer.add_message(self._channel(topic), int(log_time), data, int(t_ns), sequence)
            self.written += 1
        except Exception as err:  # noqa: BLE001 - disk full, closed file: stop writing, never raise
            self._fail(err)
            return
        if self._sink is not None:
            self._tee(self._sink, topic, int(log_time), data)

    def _tee(self, sink: Sink, topic: str, log_time: int, data: bytes) -> None:
        """Hand one written message to the sink; its failure loses the message for the sink only."""
        try:
            sink(topic, log_time, data)
        except Exception as err:  # noqa: BLE001 - the live view must never stop the log
            self.sink_failed += 1
            if self.sink_failed == 1:
                logger.warning("flight log %s: the sink failed on a %s message: %s", self.path, topic, err)

    def _fail(self, err: BaseException) -> None:
        if self.error is None:
            self.error = err
            logger.error("flight log %s: writing failed, logging stopped: %s", self.path, err)

    def _drain(self) -> None:
        queue = self._queue
        self.queue_peak = max(self.queue_peak, self._pending())
        pop = queue.popleft
        channels = self._channels
        add = self._writer.add_message
        sink = self._sink
        written = 0
        try:
            while self.error is None:
                try:
                    topic, sequence, t_ns, log_time, build, args = pop()
                except IndexError:
                    return
                if topic is None:  # a metadata record (:meth:`metadata`)
                    self._popped += 1
                    try:
                        self._writer.add_metadata(*args)
                    except Exception as err:  # noqa: BLE001 - a closed file: stop writing, never raise
                        self._fail(err)
                    continue
                if type(topic) is str:
                    self._popped += 1
                    items: Any = ((topic, sequence, t_ns, args),)
                else:  # a batch: [topic], [sequence], None, log time (None: each t_ns), build, [(drone, t_ns, args)]
                    self._popped += len(topic)
                    items = zip(topic, sequence, (item[1] for item in args), (item[2] for item in args))
                for topic, sequence, t_ns, args in items:
                    try:
                        if type(t_ns) is not int:
                            t_ns = int(t_ns)
                        data = build(t_ns, *args)
                        if type(data) is not bytes:
                            data = encode(data)
                    except Exception as err:  # noqa: BLE001 - a bad argument loses one message, not the log
                        self._malformed(topic, err)
                        continue
                    try:
                        at = int(t_ns if log_time is None else log_time)
                        add(channels.get(topic) or self._channel(topic), at, data, t_ns, sequence)
                        written += 1
                    except Exception as err:  # noqa: BLE001 - disk full, closed file: stop writing, never raise
                        self._fail(err)
                        break
                    if sink is not None:
                        self._tee(sink, topic, at, data)
            with self._push_lock:  # logging stopped after an error: discard, never grow
                self._popped = self._pushed
                queue.clear()
        finally:
            self.written += written

    def _malformed(self, topic: str, err: Exception) -> None:
        self.failed += 1
        if self.failed == 1:
            logger.warning("flight log %s: dropped a malformed %s message: %s", self.path, topic, err)

    def _report_drops(self, final: bool = False) -> None:
        dropped = self._dropped
        if dropped == self._reported_drops and not (final and dropped):
            return
        self._reported_drops = dropped
        text = f"flight log queue full: {dropped} messages dropped so far"
        if final:
            text = f"flight log: {dropped} messages dropped (queue full or logged after close)"
        logger.warning("%s: %s", self.path, text)
        now = time.time_ns() if self._clock is None else self._clock()
        topic, counter = self._fixed["/events"]
        self._write(topic, next(counter), now, now, log_message(now, 3, text, self.name))

    def _flush(self) -> None:
        if self.error is not None:
            return
        try:
            self._writer.flush()
        except Exception as err:  # noqa: BLE001
            self._fail(err)

    def _run(self) -> None:
        last_flush = time.monotonic()
        try:
            while True:
                stopping = self._stop.is_set()
                self._drain()
                now = time.monotonic()
                if stopping:
                    break
                if now - last_flush >= self.flush_interval_s:
                    self._report_drops()
                    self._flush()
                    last_flush = now
                self._wake.wait(self.poll_interval_s)
                self._wake.clear()
            self._drain()
            self._report_drops(final=True)
            if self.error is None:
                try:
                    self._writer.finish()
                except Exception as err:  # noqa: BLE001
                    self._fail(err)
        finally:
            try:
                self._file.close()
            except Exception as err:  # noqa: BLE001
                self._fail(err)
            self.writer_cpu_s = time.thread_time()
