"""Which warning each fault owes: an event of level warning or above naming its drone (or ``mocap``, ``loop`` for a
swarm fault) within 1 s of its effect, or before the planning phase for a power-on fault, and when it owes none.

A fault that had nothing to act on owes nothing: a flight-time fault on a drone whose motors are off (on the
floor, or falling after another fault stopped it), a planner fault on a drone that never plans again, a frame fault
wholly inside a loop stall, a loop stall within the loop's normal jitter, a yaw offset that extpose corrected, a gust
too short to push its drone past a real drone's tracking noise. Each of these rules was a failure of the judge's,
not the stack's, in some campaign; each is narrow enough that a fault the stack should have said still fails.
"""

from __future__ import annotations

import math
from typing import Any

from rpf_fly.campaign.schedules import POWER_ON, SWARM_KINDS
from rpf_fly.campaign.truth import ON_FLOOR_M, Truth
from rpf_fly.mission.model import Mission

Events = list[tuple[int, dict]]
"""The flight log's ``/events``: [(log time ns, event)], each event with level, file, name and message."""

EVENT_WINDOW_S = 1.0
"""A fault's warning comes within this of its effect."""
TRACKING_NOISE_M = 0.05
"""A real Crazyflie's normal tracking error under mocap: a push smaller than this is not a fault anyone can see."""
LATE_TICK_S = 0.1
"""A planning tick this much later than the mission's period: the drones flew that much longer on an old setpoint
(the flight loop's own line, `FlightLoop.LATE_TICK_S`). Under it a stall is the loop's normal jitter."""
UNSAFE_TO_FLY = frozenset({"start_offset", "upside_down", "motor_fault"})
"""Kinds whose drone must stay on the floor (a start offset only beyond the mission's tolerance)."""
PLANNER_KINDS = frozenset({"planner_error", "planner_hang"})
NOT_PLANNING_AGAIN = frozenset({"landing", "landed", "failed", "link_lost", "emergency"})
"""Drone phases (`rpf_fly.flight.phases.DronePhase`) after which a drone's planner is never called again."""
FRAME_KINDS = frozenset({"pose_jump", "orientation_flip", "mocap_delay"})
"""Faults that only change what the mocap frames say (not whether a body is tracked): a loop that reads no frame
of them never sees them."""


def unsafe_to_fly(fault: dict[str, Any], mission: Mission) -> bool:
    """The fault must keep its drone on the floor (a start offset only beyond the mission's tolerance: within it the
    drone flies from where it stands)."""
    if fault["kind"] == "start_offset":
        return math.hypot(*fault["offset_m"][:2]) > mission.safety.start_tolerance_m
    return fault["kind"] in UNSAFE_TO_FLY


def target(fault: dict[str, Any]) -> str:
    """What a fault's warning must name: its drone, or ``mocap`` / ``loop`` for a swarm fault."""
    return fault.get("drone") or ("loop" if fault["kind"] == "loop_stall" else "mocap")


def injected_at(fault: dict[str, Any], events: Events) -> int | None:
    """When the fault's own injection event came (naming its drone, unless a swarm fault); None: never injected."""
    drone = fault.get("drone")
    return next(
        (
            t
            for t, m in events
            if m.get("file") == "fault"
            and m.get("message", "").startswith(f"injected {fault['kind']}")
            and (fault["kind"] in SWARM_KINDS or m.get("name") == drone)
        ),
        None,
    )


def warnings_for(fault: dict[str, Any], events: Events, flying_at: int | None) -> list[dict] | None:
    """The warnings (level >= warning) naming the fault's target: before the planning phase for a power-on fault,
    else within `EVENT_WINDOW_S` of the fault's effect (its own injection event; for an estimator divergence, the
    moment it has carried the drone `TRACKING_NOISE_M` off); None when it was never injected."""
    drone, name = fault.get("drone"), target(fault)

    def names_target(m: dict) -> bool:
        if fault["kind"] not in SWARM_KINDS:
            return m.get("name") == drone
        return name in m.get("file", "") or name in m.get("message", "").lower()

    if fault["kind"] in POWER_ON:
        window = [m for t, m in events if flying_at is None or t <= flying_at]
    else:
        injected = injected_at(fault, events)
        if injected is None:
            return None
        effect = injected
        if fault["kind"] == "estimator_divergence":
            # the drone follows its estimate away at rate_m_s: no stack (nor mocap) tells that from a real drone's
            # tracking noise before it is TRACKING_NOISE_M off
            effect += TRACKING_NOISE_M / fault["rate_m_s"] * 1e9
        window = [m for t, m in events if injected <= t <= effect + EVENT_WINDOW_S * 1e9]
    return [m for m in window if m.get("level", 0) >= 3 and names_target(m)]


def uninjectable(fault: dict[str, Any], flying_at: int | None, all_kept_down: bool) -> bool:
    """A flight-time fault (its ``at_s`` counts from the planning phase) in a flight with no planning phase because
    other faults rightly kept every drone on the floor: it could not be injected, and nothing is owed for it.
    Without such a reason a missing injection stays a failure."""
    return flying_at is None and all_kept_down and fault["kind"] not in POWER_ON


def past_the_flight(fault: dict[str, Any], flying_at: int | None, events: Events) -> bool:
    """A flight-time fault whose ``at_s`` (from the planning phase) falls after the flight's last event: the stack's
    answer to another fault ended the flight first (a mocap blackout lands or stops every drone, and the flight is
    over in two seconds), so it could not be injected and nothing is owed for it. A flight still going at that
    moment keeps a missing injection a failure."""
    if flying_at is None or fault.get("at_s") is None or fault["kind"] in POWER_ON or fault.get("at_phase"):
        return False
    last = max((t for t, _ in events), default=None)
    return last is not None and flying_at + float(fault["at_s"]) * 1e9 > last


def motors_off_at_injection(fault: dict[str, Any], events: Events, truth: Truth) -> bool:
    """A drone's flight-time fault injected while its truth has its motors off: on the floor (kept down by another
    fault, or already landed) or falling after its firmware or the stack stopped it (another fault's emergency):
    it has no flight left to act on, so no warning is owed. A drone spinning up or flying still owes one."""
    drone = fault.get("drone")
    if drone is None or fault["kind"] in POWER_ON or fault["kind"] in SWARM_KINDS:
        return False
    injected = injected_at(fault, events)
    samples = truth.get(drone) or []
    if injected is None or not samples:
        return False
    _, m = min(samples, key=lambda s: abs(s[0] - injected))
    return not m["motors"]


def planner_unused_at_injection(fault: dict[str, Any], events: Events) -> bool:
    """A planner fault injected on a drone whose last phase before it is one it never plans in again (landing,
    landed, failed, link_lost, emergency: each one-way): the faulty planner is never called, so the fault has no
    effect and owes no warning. A drone holding or planning at its injection still owes one."""
    if fault["kind"] not in PLANNER_KINDS or fault.get("drone") is None:
        return False
    injected = injected_at(fault, events)
    if injected is None:
        return False
    phases = [
        m.get("message", "")
        for t, m in events
        if t <= injected and m.get("file") == "phase" and m.get("name") == fault["drone"]
    ]
    return bool(phases) and phases[-1].split(":")[0] in NOT_PLANNING_AGAIN


def inside_loop_stall(fault: dict[str, Any], events: Events) -> bool:
    """A frame fault (`FRAME_KINDS`) that began and ended while the flight loop was stalled: the loop reads only the
    newest frame when it wakes, made after the fault ended, so the fault never reached the stack or the drones (the
    stall's own warning is said). A pose gap inside a stall is different: the NatNet client saw it in the frames it
    drained, and the stack says it after the fact."""
    if fault["kind"] not in FRAME_KINDS:
        return False
    injected = injected_at(fault, events)
    if injected is None:
        return False
    end = injected + (fault.get("duration_s") or 0.0) * 1e9
    for t, m in events:
        message = m.get("message", "")
        if m.get("file") == "fault" and message.startswith("injected loop_stall for "):
            stall_s = float(message.split(" for ")[1].split(" s")[0])
            if t <= injected and end < t + stall_s * 1e9:
                return True
    return False


def stall_within_jitter(
    fault: dict[str, Any], events: Events, ticks: dict[str, list[int]], period_s: float
) -> float | None:
    """For a loop stall: the longest gap between two planning ticks of any drone around it (from a period before its
    injection to a period after its end), when that is at most the period plus `LATE_TICK_S`, else None. A stall
    that began while the loop waited for its next frame delays that tick by less than its length; no stack can tell
    that from its normal jitter, and no drone felt it."""
    if fault["kind"] != "loop_stall":
        return None
    injected = injected_at(fault, events)
    if injected is None:
        return None
    lo, hi = injected - period_s * 1e9, injected + (fault["duration_s"] + period_s) * 1e9
    longest = 0.0
    for stamps in ticks.values():
        inside = [t for t in stamps if lo <= t <= hi]
        after = next((t for t in stamps if t > hi), None)
        if after is not None:
            inside.append(after)
        longest = max([longest] + [(b - a) / 1e9 for a, b in zip(inside, inside[1:])])
    return longest if longest <= period_s + LATE_TICK_S else None


def corrected_by_extpose(fault: dict[str, Any], mission: Any, reached: dict[str, bool]) -> bool:
    """A yaw offset at power-on under ``radio.extpos: extpose``: the estimator takes mocap's orientation with every
    pose, so its yaw is right before the preflight looks and the stack has nothing to say; owed nothing when the
    drone then reached its goal (it flew right). With position-only extpos the offset stays until the preflight
    resets the estimator, and that warning is owed."""
    return (
        fault["kind"] == "yaw_offset"
        and mission.radio.extpos == "extpose"
        and reached.get(fault.get("drone") or "", False)
    )


def gust_push_bound(fault: dict[str, Any], events: Events, truth: Truth) -> float | None:
    """The most a gust could have moved its drone: 0.5 |a| t^2 over the time its truth was airborne within the gust
    (no controller fighting it, so an upper bound; on the floor a gust moves nothing). None for other kinds."""
    if fault["kind"] != "gust" or fault.get("drone") is None:
        return None
    injected = injected_at(fault, events)
    if injected is None:
        return None
    end = injected + fault["duration_s"] * 1e9
    samples = [(t, m) for t, m in truth.get(fault["drone"], []) if injected <= t <= end]
    airborne = sum((b[0] - a[0]) / 1e9 for a, b in zip(samples, samples[1:]) if a[1]["position"]["z"] > ON_FLOOR_M)
    return 0.5 * math.hypot(*fault["accel"]) * airborne**2


def owed_warnings(
    faults: list[dict[str, Any]],
    events: Events,
    truth: Truth,
    mission: Mission,
    reached: dict[str, bool],
    ticks: dict[str, list[int]],
    all_kept_down: bool,
) -> tuple[list[str], list[str], list[str]]:
    """Each fault's own warning, so one fault's warning cannot stand in for another's: (failures, the warnings said
    (at most 3 a fault), notes on the faults that owed nothing and why)."""
    flying_at = next((t for t, m in events if m.get("message") == "swarm: flying"), None)
    failures: list[str] = []
    said: list[str] = []
    notes: list[str] = []
    for f in faults:
        found = warnings_for(f, events, flying_at)
        if found is None:
            if uninjectable(f, flying_at, all_kept_down):
                notes.append(f"{f['kind']} not injected: no drone took off, so no planning phase for its at_s")
            elif past_the_flight(f, flying_at, events):
                notes.append(f"{f['kind']} not injected: the flight was over before its at_s ({f['at_s']:g} s)")
            else:
                failures.append(f"{f['kind']} was never injected")
            continue
        if not found:
            note = _owes_nothing(f, events, truth, mission, reached, ticks)
            if note is not None:
                notes.append(note)
                continue
            failures.append(f"no warning naming {target(f)} within {EVENT_WINDOW_S:g} s of its {f['kind']}")
            continue
        said += [f"{m.get('file')}: {m.get('message')}" for m in found][:3]
    return failures, said, notes


def _owes_nothing(
    fault: dict[str, Any],
    events: Events,
    truth: Truth,
    mission: Mission,
    reached: dict[str, bool],
    ticks: dict[str, list[int]],
) -> str | None:
    """Why a fault that left no warning owed none (the note the report shows), or None: it owed one."""
    if motors_off_at_injection(fault, events, truth):
        return f"{fault['drone']} motors off (down or stopped) at its {fault['kind']}: nothing for it to act on"
    if planner_unused_at_injection(fault, events):
        return (
            f"{fault['drone']} no longer planning at its {fault['kind']} (landing or down): its planner is never "
            "called again"
        )
    if (gap := stall_within_jitter(fault, events, ticks, mission.flight.dt)) is not None:
        return (
            f"its loop_stall delayed no planning tick past the period plus {LATE_TICK_S:g} s (longest gap "
            f"{gap:.3f} s): within the loop's normal jitter, no drone felt it"
        )
    if inside_loop_stall(fault, events):
        return f"{fault['kind']} began and ended inside a loop stall: the loop never read a frame of it"
    if corrected_by_extpose(fault, mission, reached):
        return (
            f"{fault['drone']} stood rotated with extpose: its estimator took mocap's yaw and it reached its goal: "
            "nothing to act on"
        )
    if (push := gust_push_bound(fault, events, truth)) is not None and push < TRACKING_NOISE_M:
        return (
            f"{fault['drone']} airborne too little of its gust to be pushed more than {push:.3f} m, under a real "
            f"drone's {TRACKING_NOISE_M:g} m tracking noise"
        )
    return None
