"""The verdict on one faulted run, from its record alone (`rpf_fly.campaign.flights`): the process (no traceback,
its exit, the log reviews), the truth (`rpf_fly.campaign.truth`) and the stack's own word on each fault
(`rpf_fly.campaign.owed`).

A dry run (`judge_flight`): the drones no fault names reach their goals (none asked when a swarm fault is among
the faults), a drone a fault makes unsafe to fly never leaves the floor, and neither does a drone whose start or
goal is within 2r of where it stands (it could not take off or land there); each fault its own warning; exit 0 when
every drone reached, 1 otherwise. A run against a lab (`judge_lab`): the drones left without a ground station each
down (motors off or on the floor) within 1.5 s, moved at most 1 m, none flying 5 s after; a kill strikes in the
phase it names and the flight dies by SIGKILL; an unplug's flight lives on, its dongle's drones said lost within 1 s.
"""

from __future__ import annotations

import math
import signal
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

from rpf_fly.campaign.flights import EXIT_EXTRA_S, FlightRecord, LabRecord
from rpf_fly.campaign.owed import EVENT_WINDOW_S, owed_warnings, unsafe_to_fly
from rpf_fly.campaign.schedules import SWARM_KINDS
from rpf_fly.campaign.truth import ON_FLOOR_M, Truth, at_goal, truth_failures
from rpf_fly.flight.lab import after_ground_station, reach_after_death_m
from rpf_fly.radio.budget import dongle_of

DOWN_WITHIN_S = 1.5
"""A drone left without its ground station is down (motors off or on the floor) this soon (the firmware's 1 s
emergency-stop watchdog and a fall)."""
STILL_FLYING_S = 5.0
"""... and is not flying this long after."""
KILL_PHASE = {"takeoff": "takeoff", "settle": "takeoff", "planning": "flying", "landing": "landing"}
"""The swarm's phase (its ``[phase] swarm: X`` line) a kill at each ``at_phase`` strikes in."""


@dataclass
class Verdict:
    """One run's verdict, as the report shows it: what flew (kinds joined by ``+``, the mission, the drones the
    faults name), pass or not and every failure, the exit code, each drone's outcome, the warnings said (and notes
    on faults that owed none), the smallest true separation between airborne drones."""

    kind: str
    mission: str
    drone: str | None
    passed: bool = False
    exit_code: int | None = None
    seconds: float = 0.0
    outcomes: dict[str, str] = field(default_factory=dict)
    failures: list[str] = field(default_factory=list)
    events: list[str] = field(default_factory=list)
    min_separation_m: float | None = None
    params: dict[str, Any] = field(default_factory=dict)
    """A random draw (planner, world seed, the faults' parameters) or a lab fault's fields; empty: the defaults."""


def _judge_process(record: FlightRecord, verdict: Verdict) -> None:
    """What every run's flight process owes, whatever it flew against: no traceback, each drone's outcome line
    (read into the verdict), a log that reviews."""
    names = {d.name for d in record.mission.drones}
    verdict.exit_code = record.exit_code
    verdict.seconds = record.seconds
    if "Traceback" in record.stdout or "Traceback" in record.stderr:
        verdict.failures.append("traceback in the flight's output")
    for line in record.stdout.splitlines():
        name, _, rest = line.partition(": ")
        if name in names:
            verdict.outcomes[name] = rest.split(" ")[0]
    if record.review_error is not None:
        verdict.failures.append(f"the flight's log does not review: {record.review_error}")


def _truth_of(
    topics: dict[str, list[tuple[int, dict]]], names: list[str], verdict: Verdict, source: str
) -> Truth | None:
    """Every drone's ``/truth`` samples from ``topics``; None (and a failure) when a drone has none."""
    truth = {n: topics.get(f"/truth/{n}", []) for n in names}
    missing = [n for n, s in truth.items() if not s]
    if missing:
        verdict.failures.append(f"no /truth{source} for " + ", ".join(missing))
        return None
    return truth


def _reached(record: FlightRecord, truth: Truth, outcomes: dict[str, str]) -> dict[str, bool]:
    """Each drone reached its goal: it says so and its truth ended there."""
    return {d.name: outcomes.get(d.name) == "reached" and at_goal(truth[d.name], d.goal) for d in record.mission.drones}


def _finish(verdict: Verdict) -> Verdict:
    verdict.passed = not verdict.failures
    return verdict


def judge_flight(record: FlightRecord) -> Verdict:
    """The verdict on a faulted dry run (module docstring), over every fault of its schedule at once."""
    mission, faults = record.mission, record.faults
    names = [d.name for d in mission.drones]
    kinds = [f["kind"] for f in faults]
    named = sorted({f["drone"] for f in faults if f.get("drone")})
    verdict = Verdict("+".join(kinds), mission.name, ",".join(named) if named else None)
    fail = verdict.failures.append
    if record.exit_code is None:
        fail(f"did not exit within {record.limit_s:.0f} s")
        return _finish(verdict)
    _judge_process(record, verdict)
    if record.log_error is not None:
        last = (record.stderr.strip().splitlines() or [""])[-1]
        fail(f"log unreadable: {record.log_error}" + (f" (the flight's last line: {last})" if last else ""))
        return _finish(verdict)
    events = record.topics.get("/events", [])
    flying_at = next((t for t, m in events if m.get("message") == "swarm: flying"), None)
    if flying_at is not None:
        end_ns = max(t for t, _ in events)
        if (end_ns - flying_at) / 1e9 > mission.flight.timeout_s + EXIT_EXTRA_S + mission.flight.land_s + 5:
            fail(f"the flight outlasted its timeout plus {EXIT_EXTRA_S:g} s")
    truth = _truth_of(record.topics, names, verdict, "")
    if truth is None:
        return _finish(verdict)
    failures, verdict.min_separation_m = truth_failures(truth, mission.arena, mission.planner.safety_radius)
    verdict.failures += failures
    reached = _reached(record, truth, verdict.outcomes)
    # A drone kept on the floor leaves its spot occupied: a drone whose start or goal is within 2r of where it truly
    # stands could neither take off nor land there, so it stays down too (docs/flight.md, the preflight's ground
    # rule). In a circle swap that is the antipodal drone. Those are judged as the named drone is: on the floor.
    r = mission.planner.safety_radius
    unsafe = {f["drone"] for f in faults if f.get("drone") and unsafe_to_fly(f, mission)}
    kept_down: set[str] = set()
    notes: list[str] = []
    for drone in sorted(unsafe):
        spot = truth[drone][0][1]["position"]
        for d in mission.drones:
            if d.name not in unsafe and min(math.dist(p, (spot["x"], spot["y"])) for p in (d.start, d.goal)) < 2 * r:
                kept_down.add(d.name)
                notes.append(f"{d.name} kept down: its start or goal is within 2r of {drone}")
    if not any(k in SWARM_KINDS for k in kinds):
        missed = [n for n in names if n not in named and n not in kept_down and not reached[n]]
        if missed:
            fail("did not reach their goals: " + ", ".join(missed))
    for n in sorted(kept_down | unsafe):
        if max(m["position"]["z"] for _, m in truth[n]) > ON_FLOOR_M or any(m["motors"] for _, m in truth[n]):
            fail(f"{n} left the floor")
    expected = 0 if all(reached.values()) else 1
    if record.exit_code != expected:
        fail(f"exit code {record.exit_code}, expected {expected}")
    ticks = {n: [t for t, _ in record.topics.get(f"/{n}/planner", [])] for n in names}
    owed, said, owed_notes = owed_warnings(
        faults, events, truth, mission, reached, ticks, set(names) <= kept_down | unsafe
    )
    verdict.failures += owed
    verdict.events += said + notes + owed_notes
    return _finish(verdict)


def phase_at_kill(stderr: str) -> str | None:
    """The swarm's phase (its last ``[phase] swarm: X`` line) before the kill's line on the flight's stderr."""
    phase = None
    for line in stderr.splitlines():
        if "injected ground_station_kill" in line:
            return phase
        if line.startswith("[phase] swarm: "):
            phase = line.removeprefix("[phase] swarm: ").split(" ")[0]
    return phase


def judge_lab(record: LabRecord) -> Verdict:
    """The verdict on a run of a lab kind against a lab of its own (module docstring), on the lab's log."""
    mission = record.mission
    (fault,) = record.faults
    names = [d.name for d in mission.drones]
    kind = fault["kind"]
    kill = kind == "ground_station_kill"
    orphans = names if kill else [d.name for d in mission.drones if dongle_of(d.uri) == fault["dongle"]]
    verdict = Verdict(
        kind, mission.name, None if kill else ",".join(orphans), params={k: v for k, v in fault.items() if k != "kind"}
    )
    fail = verdict.failures.append
    if not record.lab_started:
        fail("the lab did not start")
        return _finish(verdict)
    verdict.failures += record.lab_problems
    if record.exit_code is None:
        fail(f"the flight did not exit within {record.limit_s:.0f} s")
        return _finish(verdict)
    _judge_process(record, verdict)
    if record.lab_log_error is not None:
        fail(f"lab log unreadable: {record.lab_log_error}")
        return _finish(verdict)
    if record.log_error is not None:
        fail(f"flight log unreadable: {record.log_error}")
    events = record.topics.get("/events", [])
    # when it struck: an unplug's injection event (the flight lives on and closes its log); a kill's line on stderr,
    # read as it came (the MCAP log is cut where the kill found it), else the process's end
    if kill:
        at_ns = record.struck_ns
        if at_ns is None:
            at_ns = record.exited_ns
            fail("no 'injected ground_station_kill' line on the flight's stderr")
    else:
        at_ns = next(
            (t for t, m in events if m.get("file") == "fault" and m.get("message", "").startswith(f"injected {kind}")),
            None,
        )
    if at_ns is None:
        fail(f"{kind} was never injected")
        return _finish(verdict)
    if kill:
        if record.exit_code != -signal.SIGKILL:
            fail(f"exit {record.exit_code}, expected death by SIGKILL ({-signal.SIGKILL})")
        phase = phase_at_kill(record.stderr)
        if phase != KILL_PHASE[fault["at_phase"]]:
            fail(f"struck in the swarm's phase {phase}, not {KILL_PHASE[fault['at_phase']]}")
        if fault["at_phase"] == "takeoff" and "take-off commanded" not in record.stderr:
            fail("struck before the take-off was commanded")
    elif record.exit_code != (1 if orphans else 0):
        fail(f"exit code {record.exit_code}, expected {1 if orphans else 0}")
    truth = _truth_of(record.lab_topics, names, verdict, " in the lab log")
    if truth is None:
        return _finish(verdict)
    failures, verdict.min_separation_m = truth_failures(truth, mission.arena, mission.planner.safety_radius)
    verdict.failures += failures
    _judge_orphans(record, verdict, truth, orphans, at_ns, events)
    return _finish(verdict)


def _judge_orphans(
    record: LabRecord, verdict: Verdict, truth: Truth, orphans: list[str], at_ns: int, events: list[tuple[int, dict]]
) -> None:
    """The drones the fault left without a ground station (`rpf_fly.flight.lab.after_ground_station`), and for an
    unplug the others at their goals and each orphan said lost."""
    kind = record.faults[0]["kind"]
    fail = verdict.failures.append
    try:
        after = after_ground_station(
            {n: [SimpleNamespace(log_time=t, data=m) for t, m in truth[n]] for n in orphans}, at_ns, (STILL_FLYING_S,)
        )
    except ValueError as err:
        fail(str(err))
        return
    airborne = [n for n, d in after.items() if d.motors_at_death and d.z_at_death > ON_FLOOR_M]
    if not airborne:
        fail(f"no drone airborne at the {kind}: nothing was tested")
    for n, d in after.items():
        if d.down_after_s is None or d.down_after_s > DOWN_WITHIN_S:
            fail(
                f"{n} not down within {DOWN_WITHIN_S:g} s of the {kind} "
                f"({'never' if d.down_after_s is None else f'{d.down_after_s:.2f} s'})"
            )
        reach = reach_after_death_m(record.mission, d.z_at_death)  # ... and moved no further than the firmware lets it
        if d.moved_m > reach:
            fail(f"{n} moved {d.moved_m:.2f} m after the {kind} (> {reach:.2f} m: its reach at its speed and height)")
        if d.flying_at_s[STILL_FLYING_S]:
            fail(f"{n} still flying {STILL_FLYING_S:g} s after the {kind}")
    down = [d.down_after_s for n, d in after.items() if n in airborne and d.down_after_s is not None]
    verdict.events.append(
        f"{len(airborne)} of {len(after)} airborne at the {kind.replace('_', ' ')}"
        + (f"; down {min(down):.2f}-{max(down):.2f} s after" if down else "")
        + f"; moved at most {max(d.moved_m for d in after.values()):.2f} m"
    )
    behind = [
        m.get("message", "")
        for _, m in record.lab_topics.get("/events", [])
        if "could not keep up" in m.get("message", "")
    ]
    if behind:  # the lab's world fell behind its own time: what the drones did is the host's as much as the stack's
        verdict.events.append(f"lab: {behind[-1]}")
    if kind == "ground_station_kill":
        return
    reached = _reached(record, truth, verdict.outcomes)
    missed = [d.name for d in record.mission.drones if d.name not in orphans and not reached[d.name]]
    if missed:
        fail("did not reach their goals: " + ", ".join(missed))
    for n in orphans:
        said = [
            m
            for t, m in events
            if at_ns <= t <= at_ns + EVENT_WINDOW_S * 1e9 and m.get("level", 0) >= 3 and m.get("name") == n
        ]
        if not said and not after[n].motors_at_death and after[n].z_at_death <= ON_FLOOR_M:
            verdict.events.append(f"{n} on the floor, motors off, at the unplug: no link of a flight to lose")
            continue
        if not said:
            fail(f"no warning naming {n} within {EVENT_WINDOW_S:g} s of the unplug")
        elif n == orphans[0]:
            verdict.events.append(f"{said[0].get('file')}: {said[0].get('message', '').splitlines()[0]}")
