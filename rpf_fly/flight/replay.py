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

import math
import time
from collections.abc import Callable
from pathlib import Path

from rpf_fly.flight.agent import DroneAgent, PlannerFault, PlannerLike
from rpf_fly.flight.phases import DronePhase
from rpf_fly.flight.poses import PoseTracker
from rpf_fly.flight.replay_inputs import (
    FRAME_SLACK_NS,
    PLANNING_MODES,
    LoggedRow,
    ReplayError,
    TrackerClock,
    batching_switched_off_ns,
    logged_ticks,
    missing_sequences,
    mocap_frame,
    phase_of_mode,
    reacquisitions,
)
from rpf_fly.flight.replay_mission import ReplaySetup, logged_mission, shipped_policy
from rpf_fly.flight.replay_result import DroneReplay, ReplayResult, TickComparison
from rpf_fly.flight.swarm_plan import Neighbourhood, SwarmPlanner, in_the_way
from rpf_fly.log.mocap_frames import mocap_frames
from rpf_fly.log.reader import LogData
from rpf_fly.mission.model import Drone, Mission
from rpf_fly.planning.wall_following import MODE_NAMES

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


def replay_log(
    data: LogData,
    mission: Mission,
    planner_factory: Callable[[Drone], PlannerLike],
    *,
    tolerance: float = FIXED_GAINS_TOLERANCE,
    planner: str = "",
    policy: Path | None = None,
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
        raise ReplayError(
            f"{log}: no planner rows (/<drone>/planner) for any drone of mission "
            f"{mission.name!r}: nothing to replay (the flight never reached its planning phase?)"
        )
    frames = mocap_frames(data, names)
    if not frames:
        raise ReplayError(f"{log}: no mocap poses (/mocap/<drone>): the views cannot be rebuilt")
    last_pose_log_ns = max(f.log_time_ns for f in frames)
    ticks, torn = logged_ticks(data, names, last_pose_log_ns)
    if torn:
        warnings.append(f"{torn} final tick(s) left out: the log ends before the frame that fired them")
    offset = meta.get("monotonic_offset_ns")
    times = TrackerClock(int(offset) if offset not in (None, "") else None, frames[0].t_ns)
    if not times.exact:
        warnings.append(
            "the log has no mission.monotonic_offset_ns (written before rpf-fly replay existed): "
            "its pose times are not the tracker's, so neighbour velocities are rebuilt only "
            "approximately: a guide, not a check (two such dry runs differed by up to 2e-4 and 0.12 "
            "from their third tick on, docs/replay.md)"
        )
    for topic in [f"/mocap/{n}" for n in names] + [f"/{n}/planner" for n in names]:
        missing = missing_sequences(data, topic)
        if missing:
            warnings.append(
                f"{topic}: {missing} message(s) dropped by the flight's log queue: the replay may "
                "differ from the flight from there"
            )
    if any(
        "reference" not in (m.data or {})
        for n in names
        for m in data.topics.get(f"/{n}/planner", ())[:1]
        if isinstance(m.data, dict) and m.data.get("mode") in PLANNING_MODES
    ):
        warnings.append(
            "planner rows without `reference` (a log from before rpf-fly replay): each planning "
            "stretch restarts from the drone's pose one frame before, not the reference the flight "
            "restarted from (exact for the take-off, a guess after a hold)"
        )

    inf = math.inf
    agents = {d.name: DroneAgent.for_mission(d, planner_factory(d), mission, budget_s=inf) for d in mission.drones}
    shadow = {d.name: DroneAgent.for_mission(d, agents[d.name].planner, mission, budget_s=inf) for d in mission.drones}
    if simulated_first_order(meta):  # as the flight's loop set them at connect
        for agent in (*agents.values(), *shadow.values()):
            agent.set_controller(None, first_order=True)
    swarm = SwarmPlanner(mission.planner.sensing_range, inf, hang_s=REPLAY_HANG_S)
    tracker = PoseTracker({n: n for n in names})
    results = {n: DroneReplay(n, tolerance) for n in names}
    for n in rowless:
        note = f"no planner rows (/{n}/planner) in the log: not replayed "
        results[n].note = note + "(its poses still count as a neighbour, by height)"
    last_planned: dict[str, LoggedRow] = {}
    previous_mode: dict[str, str] = {}
    batching_off_ns = batching_switched_off_ns(data)
    reacquired = reacquisitions(data, frames)
    height = mission.flight.height
    next_frame = 0
    before: dict[str, complex] = {}
    started = clock()
    try:
        for tick in ticks:
            while next_frame < len(frames) and frames[next_frame].t_ns <= tick.t_ns + FRAME_SLACK_NS:
                before = {n: p.xy for n, p in tracker.poses.items()}
                tracker.update(mocap_frame(next_frame + 1, frames[next_frame], times), reacquired.get(next_frame, ()))
                next_frame += 1
            if batching_off_ns is not None and tick.t_ns > batching_off_ns:
                swarm.batching = False
            phases = {n: phase_of_mode(r.mode) for n, r in tick.rows.items()}
            now_s = times.seconds(tick.t_ns)
            airborne = {
                n: p
                for n, p in tracker.poses.items()  # no row: by its height alone (on the floor:
                if in_the_way(phases.get(n, UNKNOWN_PHASE), p.position[2], height, now_s - p.stamp_s)
            }  # waiting, failed)
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
                    TickComparison(row.tick, row.t_ns, row.mode, row.direction, mode, direction)
                )
    finally:
        for agent in agents.values():
            agent.close()
    seconds = clock() - started
    compared = sum(1 for t in ticks if any(r.mode in PLANNING_MODES for r in t.rows.values()))
    return ReplayResult(
        planner=planner or mission.planner.kind,
        policy=policy,
        flown_planner=meta.get("planner", ""),
        same_as_flown=same_as_flown,
        tolerance=tolerance,
        drones=results,
        ticks=compared,
        seconds=seconds,
        exact_times=times.exact,
        warnings=warnings,
    )


def simulated_first_order(meta: dict) -> bool:
    """Whether the log's drones were a dry run's (or a lab's) first-order simulated drones: their neighbours were
    predicted by speed alone (`DroneAgent.set_controller`)."""
    from rpf_fly.log.review_tracking import logged_dynamics

    return meta.get("source") in ("dry-run", "lab") and logged_dynamics(meta) != "firmware"


RESTART_OFF_M = 1e-4
"""A logged reference further than this from where the flight's previous step moved it marks a restart (a restart puts
the reference back on the measured pose: centimetres off the carrot). Within it, the step is the flight's own: a
logged direction off by a rounding, or by a tampered 1e-4 rad (5 um at 0.5 m/s), is a divergence of that tick alone,
not a restart (a restart also turns the heading to the goal, and the ticks after it would differ too)."""


def _restarts(row: LoggedRow, last: LoggedRow | None, previous_mode: str | None, shadow: DroneAgent) -> bool:
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
    return abs(moved_to - row.reference) > RESTART_OFF_M


def replay_setup(
    data: LogData, kind: str | None = None, policy: Path | None = None, tolerance: float | None = None
) -> ReplaySetup:
    """The logged mission with ``kind`` and ``policy`` (None: the flight's own, from the mission metadata) and
    the planner factory the flight loop would have used. Raises :class:`ReplayError` (one line)."""
    from rpf_fly.log.metadata import file_sha256
    from rpf_fly.mission import MissionError, with_planner
    from rpf_fly.mission.model import POLICY_KINDS
    from rpf_fly.planning.factory import UnsupportedPlanner, mission_planner
    from rpf_fly.planning.gains import FixedGains
    from rpf_fly.planning.onnx_policy import PolicyError
    from rpf_fly.planning.planner import Planner
    from rpf_fly.sim.scenario import obstacle_set

    log = data.path
    meta = data.metadata.get("mission")
    if not meta or not meta.get("yaml"):
        raise ReplayError(
            f"{log}: metadata mission.yaml: missing: the replay needs the mission the flight flew "
            "(a log written by rpf-fly fly)"
        )
    if meta.get("source") == "sim":
        raise ReplayError(
            f"{log}: metadata mission.source: 'sim': a simulation log has no flight loop views to "
            "rebuild; replay a flight or dry-run log (rpf-fly fly [--dry-run] --log)"
        )
    flown_kind = meta.get("planner", "")
    flown_sha = meta.get("policy_sha256", "")
    mission = logged_mission(meta, log, kind, policy)
    warnings: list[str] = []
    kind = kind or flown_kind or mission.planner.kind
    if policy is None and kind != mission.planner.kind and kind in POLICY_KINDS:
        policy = shipped_policy(kind, log)
    try:
        mission = with_planner(mission, kind, policy)
    except MissionError as err:
        raise ReplayError(f"{err.field}: {err.message}") from None
    sha = file_sha256(mission.planner.policy)
    same = kind == flown_kind and sha == flown_sha
    if kind == flown_kind and sha != flown_sha and policy is None:
        warnings.append(
            f"the policy found for the flight's planner ({mission.planner.policy}, sha256 {sha[:12]}...) "
            f"is not the one flown (sha256 {flown_sha[:12] or 'none'}...): the replay is not the "
            "flight's own planner; give --policy with the flown file"
        )
    obstacles = obstacle_set(mission.obstacles)
    try:
        probe = mission_planner(mission, obstacles=obstacles)
    except (UnsupportedPlanner, PolicyError) as err:
        raise ReplayError(f"{'--policy' if policy is not None else 'planner.policy'}: {err}") from None
    fixed = isinstance(probe, Planner) and isinstance(probe.gains, FixedGains)
    default_tolerance = FIXED_GAINS_TOLERANCE if fixed or mission.planner.policy is None else ONNX_TOLERANCE
    settings = mission.planner
    return ReplaySetup(
        mission,
        lambda drone: mission_planner(mission, settings, obstacles),
        same,
        default_tolerance if tolerance is None else tolerance,
        warnings,
    )
