"""Replay a flight log through the planners, tick by tick, each drone on the view it had (``rpf-fly replay``).

Why: a log says what each drone's planner decided (``/<drone>/planner``: direction, mode) and what the mocap saw
(``/mocap/<drone>``). Feeding the poses back through the flight loop's own code answers two questions offline:
did the planner decide what it should have (with the flight's own planner and policy the replay must give the
logged directions and modes back, to the last bit on the machine that flew), and what would another planner (or
another policy) have decided at the same moments, open loop: the poses stay the logged ones.

Nothing here re-implements the loop. The views are built by the loop's own pieces, in the loop's order:

- the logged frames go, in order, into a :class:`~rpf_fly.flight.poses.PoseTracker` (positions, validity, the
  low-pass velocities), at the receive times the flight's tracker used (the log carries them exactly: the tracker's
  stamps are on a 1 us grid and ``mission.monotonic_offset_ns`` turns the log's nanoseconds back into the loop's
  monotonic seconds);
- at each logged tick, the frames received up to that tick are in the tracker; who is in the others' way is
  :func:`~rpf_fly.flight.swarm_plan.in_the_way` of each drone's phase at that tick (read from its logged row) and its
  tracked height; :meth:`Neighbourhood.of <rpf_fly.flight.swarm_plan.Neighbourhood.of>` and
  :class:`~rpf_fly.flight.swarm_plan.SwarmPlanner` (batched exactly where the flight batched) build each drone's view
  and plan it, through each drone's :class:`~rpf_fly.flight.agent.DroneAgent` (its reference, its heading, its
  tracking lag);
- the drones planned at a tick are the ones the flight planned then (their logged mode is ``apf``, ``wall`` or
  ``soft``): arrival, holds and landings are the flight's decisions, on the same poses;
- a drone's planning restarts (``DroneAgent.begin_planning``) where the flight's did: at the first tick of each
  planning stretch, or wherever the logged ``reference`` is not where the flight's previous step left it (a hold
  and its resume between two ticks), from the logged reference.

Each replay agent keeps its OWN reference and heading from then on (integrated from the replayed directions), so a
different planner is flown on its own carrot, within 0.3 m of the logged pose as the flight's agent is. What a
replay cannot show: anything closed-loop (the drones would have moved elsewhere had they flown the other
decisions; the supervisor's holds and the arrivals stay the flight's). docs/replay.md.
"""

from __future__ import annotations

import bisect
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Optional

from rpf_fly.flight.agent import DroneAgent, PlannerFault, PlannerLike
from rpf_fly.flight.phases import DronePhase
from rpf_fly.flight.poses import PoseTracker, stamp_from_us
from rpf_fly.flight.swarm_plan import Neighbourhood, SwarmPlanner, in_the_way
from rpf_fly.log.mocap_frames import LoggedFrame, mocap_frames
from rpf_fly.log.reader import LogData
from rpf_fly.mission.model import Drone, Mission
from rpf_fly.mocap.frame import MocapFrame, RigidBodyPose
from rpf_fly.planning.wall_following import MODE_NAMES

PLANNING_MODES = frozenset({"apf", "wall", "soft"})
"""Logged modes of a tick on which the drone planned (the others are what it did instead)."""

UNKNOWN_PHASE = DronePhase.HOLDING
"""The phase assumed for a tracked drone without a row at a tick: in the others' way by its height alone. The
loop writes a row for every drone past its preflight that has a pose, so one without is waiting, ready or failed:
on the floor, out of everyone's way by height too. A drone whose rows are missing altogether (a damaged log) still
counts as a neighbour wherever it flew."""

FIXED_GAINS_TOLERANCE = 1e-6
"""Default divergence threshold on the direction difference for planners without a learned policy."""

ONNX_TOLERANCE = 1e-5
"""Default threshold for planners with an ONNX policy: the export's parity tolerance (rtol 1e-5 on the action,
docs/learning.md), since another machine's onnxruntime may round differently. On the machine that flew, a
replay of the flight's own policy is bit-exact (docs/replay.md has the measurement)."""

REPLAY_HANG_S = 30.0
"""Wall-clock deadline of an isolated planner's call in a replay: nothing streams, so a slow call is not a fault."""

FRAME_SLACK_NS = 1000
"""A frame counts as received before a tick when its time is at most this much after the tick's: the tracker
rounds receive times to the microsecond, which may put a frame's stamp up to 0.5 us after the loop's clock reading
that fired the tick on it; the next frame is read only after the tick's planning (hundreds of microseconds)."""


class ReplayError(ValueError):
    """The log cannot be replayed; ``str()`` is one line naming the file and what is missing."""


@dataclass(frozen=True)
class LoggedRow:
    """One ``/<drone>/planner`` message, as the replay needs it."""

    tick: int
    t_ns: int
    log_time_ns: int
    mode: str
    direction: complex
    position: tuple[float, float, float]
    reference: Optional[complex]


@dataclass
class TickComparison:
    """One planning tick of one drone: what the flight logged and what the replay decided."""

    tick: int
    t_ns: int
    logged_mode: str
    logged_direction: complex
    replayed_mode: str
    replayed_direction: complex

    @property
    def direction_diff(self) -> float:
        """``|d_replay - d_log|``: the distance of the two planar direction vectors (each a unit vector or zero;
        for two unit vectors ``2 sin(angle / 2)``, the angle itself to 1e-7 below 1e-2 rad)."""
        return abs(self.replayed_direction - self.logged_direction)

    @property
    def angle_diff_rad(self) -> Optional[float]:
        """The angle between the two directions (radians), None when either is zero (a stalled or faulted step)."""
        if abs(self.replayed_direction) == 0 or abs(self.logged_direction) == 0:
            return None
        a, b = self.logged_direction, self.replayed_direction
        return abs(math.atan2(a.real * b.imag - a.imag * b.real, a.real * b.real + a.imag * b.imag))


@dataclass
class DroneReplay:
    """Every compared tick of one drone, and what the replay had to say about it."""

    name: str
    tolerance: float
    ticks: list[TickComparison] = field(default_factory=list)
    restarts: int = 0
    """Planning (re)starts taken from the log (take-off, resumes after holds)."""
    skipped: int = 0
    """Logged planning ticks the replay could not plan: the drone had no tracked pose in the log then."""
    pose_mismatches: int = 0
    """Planning ticks where the rebuilt pose is not the logged one (a refused jump, a dropped frame)."""
    note: str = ""

    def diverges(self, c: TickComparison) -> bool:
        return c.replayed_mode != c.logged_mode or not c.direction_diff <= self.tolerance

    @property
    def first_divergence_tick(self) -> Optional[int]:
        return next((c.tick for c in self.ticks if self.diverges(c)), None)

    @property
    def max_direction_diff(self) -> float:
        return max((c.direction_diff for c in self.ticks), default=0.0)

    @property
    def max_angle_diff_rad(self) -> float:
        return max((a for c in self.ticks if (a := c.angle_diff_rad) is not None), default=0.0)

    @property
    def mode_changes(self) -> int:
        """Ticks on which the replayed mode is not the logged one."""
        return sum(c.replayed_mode != c.logged_mode for c in self.ticks)

    @property
    def divergent_ticks(self) -> int:
        return sum(self.diverges(c) for c in self.ticks)

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "ticks": len(self.ticks),
            "first_divergence_tick": self.first_divergence_tick,
            "max_direction_diff": self.max_direction_diff,
            "mode_changes": self.mode_changes,
            "max_angle_diff_rad": self.max_angle_diff_rad,
            "divergent_ticks": self.divergent_ticks,
            "restarts": self.restarts,
            "skipped_ticks": self.skipped,
            "pose_mismatches": self.pose_mismatches,
        }
        if self.note:
            out["note"] = self.note
        return out


@dataclass
class ReplayResult:
    """A whole replay: the planner replayed, per drone the comparison, the cost, and the warnings to print."""

    planner: str
    policy: Optional[Path]
    flown_planner: str
    same_as_flown: bool
    tolerance: float
    drones: dict[str, DroneReplay]
    ticks: int
    seconds: float
    exact_times: bool
    warnings: list[str] = field(default_factory=list)

    @property
    def seconds_per_tick(self) -> float:
        return self.seconds / self.ticks if self.ticks else 0.0

    def to_json(self) -> dict[str, Any]:
        """The JSON contract of ``rpf-fly replay --json`` (docs/replay.md)."""
        return {
            "planner": self.planner,
            "policy": str(self.policy) if self.policy is not None else None,
            "flown_planner": self.flown_planner,
            "same_as_flown": self.same_as_flown,
            "direction_diff": "unit-vector distance |d_replay - d_log| (0..2; ~ the angle in rad when small)",
            "tolerance": self.tolerance,
            "exact_times": self.exact_times,
            "ticks": self.ticks,
            "seconds_per_tick": self.seconds_per_tick,
            "drones": {name: d.to_json() for name, d in self.drones.items()},
            "warnings": list(self.warnings),
        }


# ---------------------------------------------------------------------------------------------------- the log


def _row(message: Any) -> Optional[LoggedRow]:
    d = message.data
    try:
        direction = complex(float(d["direction"]["x"]), float(d["direction"]["y"]))
        p = d["position"]
        position = (float(p["x"]), float(p["y"]), float(p["z"]))
        ref = d.get("reference")
        reference = complex(float(ref["x"]), float(ref["y"])) if ref is not None else None
        return LoggedRow(int(d["tick"]), message.publish_time, message.log_time, str(d["mode"]), direction, position,
                         reference)
    except (KeyError, TypeError, ValueError):
        return None


def phase_of_mode(mode: str) -> DronePhase:
    """The phase a drone was in at a tick, from its logged mode (as far as :func:`in_the_way` can tell them
    apart): a planning mode is planning, ``arrived`` arrived, ``hold`` holding, a phase name that phase."""
    if mode in PLANNING_MODES:
        return DronePhase.PLANNING
    if mode == "arrived":
        return DronePhase.ARRIVED
    try:
        return DronePhase(mode)
    except ValueError:
        return DronePhase.HOLDING  # hold, stalled: airborne, in the others' way


def _batching_off_ns(data: LogData) -> Optional[int]:
    """When the flight switched batching off for good (event ``planner_batch``: a batched call over budget)."""
    for message in data.topics.get("/events", ()):
        d = message.data
        if isinstance(d, dict) and d.get("file") == "planner_batch" and "from now on" in str(d.get("message", "")):
            return message.publish_time
    return None


def _reacquisitions(data: LogData, frames: list[LoggedFrame]) -> dict[int, set[str]]:
    """Frame index -> drones whose sample in that frame ended a pose glitch. The flight's tracker refused the
    jumped samples (they are not in the log) and gave the sample that ended the glitch no velocity; the
    supervisor's ``pose_glitch`` event "consistent again" comes in the same loop iteration, right after that
    frame, so the sample is the drone's last logged one up to the event."""
    out: dict[int, set[str]] = {}
    times = [f.t_ns for f in frames]
    for message in data.topics.get("/events", ()):
        d = message.data
        if not (isinstance(d, dict) and d.get("file") == "pose_glitch"
                and str(d.get("message", "")).startswith("mocap track consistent again")):
            continue
        name = str(d.get("name", ""))
        i = bisect.bisect_right(times, message.publish_time + FRAME_SLACK_NS) - 1
        while i >= 0 and name not in frames[i].poses:
            i -= 1
        if i >= 0:
            out.setdefault(i, set()).add(name)
    return out


def _missing_sequences(data: LogData, topic: str) -> int:
    seqs = {m.sequence for m in data.topics.get(topic, ())}
    return max(seqs) + 1 - len(seqs) if seqs else 0


# -------------------------------------------------------------------------------------------------- the replay


@dataclass
class _Tick:
    tick: int
    t_ns: int
    rows: dict[str, LoggedRow]


def _ticks(data: LogData, names: list[str], last_pose_log_ns: int) -> tuple[list[_Tick], int]:
    """The logged ticks in order, and how many were left out at a torn end: a tick is kept only when a mocap
    message was logged after its rows (so the frame that fired it, logged right after them, is in the log)."""
    ticks: dict[int, _Tick] = {}
    for name in names:
        for message in data.topics.get(f"/{name}/planner", ()):
            row = _row(message)
            if row is None:
                continue
            tick = ticks.setdefault(row.tick, _Tick(row.tick, row.t_ns, {}))
            tick.rows[name] = row
    ordered = sorted(ticks.values(), key=lambda t: (t.t_ns, t.tick))
    kept = [t for t in ordered if max(r.log_time_ns for r in t.rows.values()) <= last_pose_log_ns]
    return kept, len(ordered) - len(kept)


class _Clock:
    """Log nanoseconds back to the loop's monotonic seconds as the flight's tracker held them."""

    def __init__(self, offset_ns: Optional[int], first_ns: int):
        self.exact = offset_ns is not None
        self.offset_ns = offset_ns if offset_ns is not None else first_ns

    def seconds(self, t_ns: int) -> float:
        delta = t_ns - self.offset_ns
        if self.exact and delta % 1000 == 0:
            return stamp_from_us(delta // 1000)
        return delta / 1e9


def _mocap_frame(number: int, frame: LoggedFrame, clock: _Clock) -> MocapFrame:
    t = clock.seconds(frame.t_ns)
    bodies = {name: RigidBodyPose(name, i + 1, position, quaternion, True)
              for i, (name, (position, quaternion)) in enumerate(frame.poses.items())}
    return MocapFrame(number, t, t, None, bodies)


def replay_log(
    data: LogData,
    mission: Mission,
    planner_factory: Callable[[Drone], PlannerLike],
    *,
    tolerance: float = FIXED_GAINS_TOLERANCE,
    planner: str = "",
    policy: Optional[Path] = None,
    same_as_flown: bool = True,
    clock: Callable[[], float] = time.perf_counter,
) -> ReplayResult:
    """Replay ``data`` (a flight or dry-run log of ``mission``) with each drone's planner from ``planner_factory``
    (the flight loop's factory signature), and compare every planning tick with the log. Raises
    :class:`ReplayError` (one line) when there is nothing to replay."""
    log = data.path
    meta = data.metadata.get("mission", {})
    warnings: list[str] = []
    names = [d.name for d in mission.drones]
    rowless = [n for n in names if not data.topics.get(f"/{n}/planner")]
    if len(rowless) == len(names):
        raise ReplayError(f"{log}: no planner rows (/<drone>/planner) for any drone of mission "
                          f"{mission.name!r}: nothing to replay (the flight never reached its planning phase?)")
    frames = mocap_frames(data, names)
    if not frames:
        raise ReplayError(f"{log}: no mocap poses (/mocap/<drone>): the views cannot be rebuilt")
    last_pose_log_ns = max(f.log_time_ns for f in frames)
    ticks, torn = _ticks(data, names, last_pose_log_ns)
    if torn:
        warnings.append(f"{torn} final tick(s) left out: the log ends before the frame that fired them")
    offset = meta.get("monotonic_offset_ns")
    times = _Clock(int(offset) if offset not in (None, "") else None, frames[0].t_ns)
    if not times.exact:
        warnings.append("the log has no mission.monotonic_offset_ns (written before rpf-fly replay existed): "
                        "its pose times are not the tracker's, so neighbour velocities are rebuilt only "
                        "approximately: a guide, not a check (two such dry runs differed by up to 2e-4 and 0.12 "
                        "from their third tick on, docs/replay.md)")
    for topic in [f"/mocap/{n}" for n in names] + [f"/{n}/planner" for n in names]:
        missing = _missing_sequences(data, topic)
        if missing:
            warnings.append(f"{topic}: {missing} message(s) dropped by the flight's log queue: the replay may "
                            "differ from the flight from there")
    if any("reference" not in (m.data or {}) for n in names for m in data.topics.get(f"/{n}/planner", ())[:1]
           if isinstance(m.data, dict) and m.data.get("mode") in PLANNING_MODES):
        warnings.append("planner rows without `reference` (a log from before rpf-fly replay): each planning "
                        "stretch restarts from the drone's pose one frame before, not the reference the flight "
                        "restarted from (exact for the take-off, a guess after a hold)")

    inf = math.inf
    agents = {d.name: DroneAgent.for_mission(d, planner_factory(d), mission, budget_s=inf) for d in mission.drones}
    shadow = {d.name: DroneAgent.for_mission(d, agents[d.name].planner, mission, budget_s=inf)
              for d in mission.drones}
    swarm = SwarmPlanner(mission.planner.sensing_range, inf, hang_s=REPLAY_HANG_S)
    tracker = PoseTracker({n: n for n in names})
    results = {n: DroneReplay(n, tolerance) for n in names}
    for n in rowless:
        results[n].note = (f"no planner rows (/{n}/planner) in the log: not replayed (its poses still count as a "
                           "neighbour, by height)")
    last_planned: dict[str, LoggedRow] = {}
    previous_mode: dict[str, str] = {}
    batching_off_ns = _batching_off_ns(data)
    reacquired = _reacquisitions(data, frames)
    height = mission.flight.height
    next_frame = 0
    before: dict[str, complex] = {}
    started = clock()
    try:
        for tick in ticks:
            while next_frame < len(frames) and frames[next_frame].t_ns <= tick.t_ns + FRAME_SLACK_NS:
                before = {n: p.xy for n, p in tracker.poses.items()}
                tracker.update(_mocap_frame(next_frame + 1, frames[next_frame], times),
                               reacquired.get(next_frame, ()))
                next_frame += 1
            if batching_off_ns is not None and tick.t_ns > batching_off_ns:
                swarm.batching = False
            phases = {n: phase_of_mode(r.mode) for n, r in tick.rows.items()}
            airborne = {n: p for n, p in tracker.poses.items()  # no row: by its height alone (on the floor:
                        if in_the_way(phases.get(n, UNKNOWN_PHASE), p.position[2], height)}  # waiting, failed)
            requests: list[tuple[DroneAgent, complex]] = []
            for name in names:
                row = tick.rows.get(name)
                if row is None or row.mode not in PLANNING_MODES:
                    if row is not None:
                        previous_mode[name] = row.mode
                    continue
                pose = tracker.get(name)
                if pose is None:
                    results[name].skipped += 1
                    previous_mode[name] = row.mode
                    continue
                if pose.position != row.position:
                    results[name].pose_mismatches += 1
                agent = agents[name]
                if _restarts(row, last_planned.get(name), previous_mode.get(name), shadow[name]):
                    # A log without references: the take-off's restart planned from the pose before the frame
                    # that fired this tick (the loop begins planning, then its first tick fires on the next frame).
                    start = row.reference if row.reference is not None else before.get(name, pose.xy)
                    agent.begin_planning(start, 0.0)
                    results[name].restarts += 1
                requests.append((agent, pose.xy))
                last_planned[name] = row
                previous_mode[name] = row.mode
            if not requests:
                continue
            outcomes = swarm.plan(requests, Neighbourhood.of(airborne))
            swarm.notes.clear()
            for agent, _ in requests:
                row = tick.rows[agent.name]
                outcome = outcomes[agent.name]
                if isinstance(outcome, PlannerFault):
                    mode, direction = "fault", 0j
                else:
                    step = outcome.step
                    mode, direction = MODE_NAMES.get(int(step.mode), "apf"), complex(step.direction)
                results[agent.name].ticks.append(
                    TickComparison(row.tick, row.t_ns, row.mode, row.direction, mode, direction))
    finally:
        for agent in agents.values():
            agent.close()
    seconds = clock() - started
    compared = sum(1 for t in ticks if any(r.mode in PLANNING_MODES for r in t.rows.values()))
    return ReplayResult(
        planner=planner or mission.planner.kind, policy=policy, flown_planner=meta.get("planner", ""),
        same_as_flown=same_as_flown, tolerance=tolerance, drones=results, ticks=compared, seconds=seconds,
        exact_times=times.exact, warnings=warnings,
    )


def _restarts(row: LoggedRow, last: Optional[LoggedRow], previous_mode: Optional[str], shadow: DroneAgent) -> bool:
    """Whether the flight (re)started this drone's planning before ``row`` (``DroneAgent.begin_planning``: the
    reference back on the measured pose, the heading towards the goal): at its first planning tick, and wherever
    the logged reference is not where the flight's previous step moved it (after a hold, also one that began and
    ended between two ticks). That step is redone on ``shadow`` with the loop's own ``advance``, on the logged
    values, so the test is exact. A log without references: at the first tick after ticks it did not plan."""
    if last is None:
        return True
    if row.reference is None or last.reference is None:
        return previous_mode not in PLANNING_MODES
    shadow.reference = last.reference
    moved_to = shadow.advance(last.direction, complex(last.position[0], last.position[1]))
    return moved_to != row.reference


# ------------------------------------------------------------------------------------------ mission and planner


@dataclass
class ReplaySetup:
    """The mission to replay with (the logged one, its planner possibly replaced), the planner factory, and what
    the replay must say about them."""

    mission: Mission
    factory: Callable[[Drone], PlannerLike]
    same_as_flown: bool
    tolerance: float
    warnings: list[str] = field(default_factory=list)


def _with_policy(text: str, policy: Optional[Path]) -> str:
    """The mission text with ``planner.policy`` set to ``policy`` (absolute), or without a policy at all (kind
    ``apf``, for a replay that names its own planner). Only used when the logged policy path does not resolve:
    it was relative to the mission's folder, which the log does not record."""
    import yaml

    doc = yaml.safe_load(text)
    planner = doc.get("planner") if isinstance(doc, dict) else None
    if not isinstance(planner, dict):
        return text
    if policy is None:
        planner.pop("policy", None)
        planner["kind"] = "apf"
    else:
        planner["policy"] = str(policy)
    return yaml.safe_dump(doc, sort_keys=False)


def find_flown_policy(text: str, kind: str, log: Path, sha256: str) -> Optional[Path]:
    """The flown policy file, found by its SHA-256 (``mission.policy_sha256``): the mission's ``planner.policy``
    (or ``policies/<kind>.onnx``) next to the log or here, then a file of that name in ``policies/`` here, next to
    the log, above it, or in this checkout. None if no file there has that hash."""
    import yaml

    from rpf_fly.log.metadata import file_sha256

    if not sha256:
        return None
    try:
        doc = yaml.safe_load(text)
        raw = str(doc["planner"].get("policy") or f"policies/{kind}.onnx")
    except (yaml.YAMLError, KeyError, TypeError, AttributeError):
        raw = f"policies/{kind}.onnx"
    name = Path(raw).name
    here, beside = Path.cwd(), log.parent
    checkout = Path(__file__).resolve().parents[2]
    candidates = [beside / raw, here / raw] + [d / name for d in (here / "policies", beside, beside / "policies",
                                                                  beside.parent / "policies", checkout / "policies")]
    for candidate in candidates:
        try:
            if candidate.is_file() and file_sha256(candidate) == sha256:
                return candidate.resolve()
        except OSError:
            continue
    return None


def _shipped_policy(kind: str, log: Path) -> Optional[Path]:
    """``policies/<kind>.onnx`` for a policy kind named with ``--planner`` alone: here, next to the log, or in
    this checkout (None: let the mission loader say where it looked)."""
    checkout = Path(__file__).resolve().parents[2]
    for folder in (Path.cwd(), log.parent, checkout):
        candidate = folder / "policies" / f"{kind}.onnx"
        if candidate.is_file():
            return candidate.resolve()
    return None


def _logged_mission(meta: dict[str, str], log: Path, kind: Optional[str], policy: Optional[Path]) -> Mission:
    """The mission of the log's metadata, its policy resolved (see :func:`find_flown_policy`)."""
    from rpf_fly.mission import MissionError, parse_mission

    text = meta["yaml"]
    flown_sha = meta.get("policy_sha256", "")
    try:
        try:
            return parse_mission(text, log)  # a relative policy is looked up next to the log first, then here
        except MissionError as err:
            if err.field != "planner.policy":
                raise
            found = find_flown_policy(text, meta.get("planner", ""), log, flown_sha)
            if found is None and kind is None and policy is None:
                raise
            return parse_mission(_with_policy(text, found), log)
    except MissionError as err:
        hint = ""
        if err.field == "planner.policy":
            hint = "; give --policy PATH" + (f" (the flown policy had sha256 {flown_sha[:12]}...)" if flown_sha else "")
        raise ReplayError(f"{log}: metadata mission.yaml line {err.line}: {err.field}: {err.message}{hint}") from None


def replay_setup(data: LogData, kind: Optional[str] = None, policy: Optional[Path] = None,
                 tolerance: Optional[float] = None) -> ReplaySetup:
    """The logged mission with ``kind`` and ``policy`` (None: the flight's own, from the mission metadata) and
    the planner factory the flight loop would have used. Raises :class:`ReplayError` (one line)."""
    from rpf_fly.log.metadata import file_sha256
    from rpf_fly.mission import MissionError, with_planner
    from rpf_fly.mission.model import POLICY_KINDS
    from rpf_fly.planning.gains import FixedGains
    from rpf_fly.planning.onnx_policy import PolicyError
    from rpf_fly.planning.planner import Planner
    from rpf_fly.sim.planners import UnsupportedPlanner, mission_planner
    from rpf_fly.sim.scenario import obstacle_set

    log = data.path
    meta = data.metadata.get("mission")
    if not meta or not meta.get("yaml"):
        raise ReplayError(f"{log}: metadata mission.yaml: missing: the replay needs the mission the flight flew "
                          "(a log written by rpf-fly fly)")
    if meta.get("source") == "sim":
        raise ReplayError(f"{log}: metadata mission.source: 'sim': a simulation log has no flight loop views to "
                          "rebuild; replay a flight or dry-run log (rpf-fly fly [--dry-run] --log)")
    flown_kind = meta.get("planner", "")
    flown_sha = meta.get("policy_sha256", "")
    mission = _logged_mission(meta, log, kind, policy)
    warnings: list[str] = []
    kind = kind or flown_kind or mission.planner.kind
    if policy is None and kind != mission.planner.kind and kind in POLICY_KINDS:
        policy = _shipped_policy(kind, log)
    try:
        mission = with_planner(mission, kind, policy)
    except MissionError as err:
        raise ReplayError(f"{err.field}: {err.message}") from None
    sha = file_sha256(mission.planner.policy)
    same = kind == flown_kind and sha == flown_sha
    if kind == flown_kind and sha != flown_sha and policy is None:
        warnings.append(f"the policy found for the flight's planner ({mission.planner.policy}, sha256 {sha[:12]}...) "
                        f"is not the one flown (sha256 {flown_sha[:12] or 'none'}...): the replay is not the "
                        "flight's own planner; give --policy with the flown file")
    obstacles = obstacle_set(mission.obstacles)
    try:
        probe = mission_planner(mission, obstacles=obstacles)
    except (UnsupportedPlanner, PolicyError) as err:
        raise ReplayError(f"{'--policy' if policy is not None else 'planner.policy'}: {err}") from None
    fixed = isinstance(probe, Planner) and isinstance(probe.gains, FixedGains)
    default_tolerance = FIXED_GAINS_TOLERANCE if fixed or mission.planner.policy is None else ONNX_TOLERANCE
    settings = mission.planner
    return ReplaySetup(mission, lambda drone: mission_planner(mission, settings, obstacles), same,
                       default_tolerance if tolerance is None else tolerance, warnings)
