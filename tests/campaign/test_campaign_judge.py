"""The campaign's judge on made-up run records (nothing flies): a record of a good flight passes, and each thing a
flight must not do, changed into that record alone, fails it with its own reason; the truth checks themselves."""

from __future__ import annotations

import copy
import signal
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace

import pytest

from rpf_fly.campaign.flights import FlightRecord, LabRecord
from rpf_fly.campaign.judge import judge_flight, judge_lab, phase_at_kill
from rpf_fly.campaign.schedules import fault_fields
from rpf_fly.campaign.truth import CONTACT_M, min_separation, outside_arena
from rpf_fly.mission import load_mission

ROOT = Path(__file__).resolve().parents[2]
LAB_3 = load_mission(ROOT / "missions" / "lab-3.yaml")
S = 1_000_000_000
T0 = 1_700_000_000 * S
"""The made-up flight's clock: log times in ns since the Unix epoch, planning from T0 + 3 s."""


def state(x: float, y: float, z: float, motors: bool, crashed: bool = False) -> dict:
    return {"position": {"x": x, "y": y, "z": z}, "motors": motors, "crashed": crashed}


def flown(start: tuple[float, float], end: tuple[float, float], height: float, land_at_s: float) -> list:
    """A drone's /truth every 0.1 s for 12 s: on the floor, up at 1 s, across from 3 s to ``land_at_s`` (where it
    stops), down and motors off 1 s later."""
    samples = []
    for k in range(121):
        t = k / 10
        f = min(max((t - 3.0) / 6.0, 0.0), 1.0) if t < land_at_s else min(max((land_at_s - 3.0) / 6.0, 0.0), 1.0)
        x, y = start[0] + f * (end[0] - start[0]), start[1] + f * (end[1] - start[1])
        airborne = 1.0 <= t < land_at_s + 1.0
        samples.append((T0 + int(t * S), state(x, y, height if airborne else 0.0, airborne)))
    return samples


def event(t_s: float, level: int, file: str, message: str, name: str = "") -> tuple[int, dict]:
    return T0 + int(t_s * S), {"level": level, "file": file, "message": message, "name": name}


def good_record() -> FlightRecord:
    """cf2 occluded for 1 s at 3 s into the planning, said at once, lands early; the three cross the lab's middle
    at once, 0.3 m apart in height, and cf1 and cf3 reach their goals; exit 1 as not every drone reached."""
    d = {x.name: x for x in LAB_3.drones}
    truth = {
        name: flown(d[name].start, d[name].goal, height, land_at_s)
        for name, height, land_at_s in (("cf1", 0.6, 9.5), ("cf2", 0.9, 6.3), ("cf3", 1.2, 9.5))
    }
    events = [
        event(3.0, 2, "phase", "swarm: flying"),
        event(6.0, 2, "fault", "injected occlusion for 1 s", "cf2"),
        event(6.25, 3, "supervisor", "pose_stale: pose 250 ms old: holding", "cf2"),
        event(11.5, 2, "phase", "end"),
    ]
    return FlightRecord(
        LAB_3,
        [fault_fields("occlusion", "cf2", {"duration_s": 1.0})],
        exit_code=1,
        limit_s=130.0,
        seconds=14.0,
        stdout="cf1: reached\ncf2: landed_early (pose lost)\ncf3: reached\n",
        topics={"/events": events, **{f"/truth/{n}": s for n, s in truth.items()}},
    )


def set_truth(name: str, k: int, **changes: object) -> Callable[[FlightRecord], None]:
    def change(r: FlightRecord) -> None:
        t, m = r.topics[f"/truth/{name}"][k]
        pos = {**m["position"], **{a: v for a, v in changes.items() if a in "xyz"}}
        r.topics[f"/truth/{name}"][k] = (
            t,
            {**m, "position": pos, **{a: v for a, v in changes.items() if a not in "xyz"}},
        )

    return change


def hover_at_end(r: FlightRecord) -> None:
    for k in range(105, 121):
        set_truth("cf3", k, z=0.6, motors=True)(r)


def near_miss(r: FlightRecord) -> None:
    """cf3 flies at cf1's height: they cross at the middle of the lab together."""
    r.topics["/truth/cf3"] = [
        (t, {**m, "position": {**m["position"], "z": 0.6 if m["position"]["z"] else 0.0}})
        for t, m in r.topics["/truth/cf3"]
    ]


def silent(r: FlightRecord) -> None:
    r.topics["/events"] = [e for e in r.topics["/events"] if e[1]["level"] < 3]


FAILING: dict[str, tuple[Callable[[FlightRecord], None], str]] = {
    "crash": (set_truth("cf1", 60, crashed=True), "crashed: cf1"),
    "contact": (near_miss, "two airborne drones 0.000 m apart"),
    "not down": (hover_at_end, "cf3 not down at the end (motors True, z 0.60 m)"),
    "out of the arena": (set_truth("cf1", 50, x=2.5), "outside the arena by more than r: cf1 0.50 m"),
    "no warning": (silent, "no warning naming cf2 within 1 s of its occlusion"),
    "did not reach": (
        lambda r: setattr(r, "stdout", r.stdout.replace("cf3: reached", "cf3: landed_early")),
        "did not reach their goals: cf3",
    ),
    "exit code": (lambda r: setattr(r, "exit_code", 0), "exit code 0, expected 1"),
    "traceback": (
        lambda r: setattr(r, "stderr", "Traceback (most recent call last):\n"),
        "traceback in the flight's output",
    ),
    "review": (
        lambda r: setattr(r, "review_error", "log cut short"),
        "the flight's log does not review: log cut short",
    ),
    "never exited": (lambda r: setattr(r, "exit_code", None), "did not exit within 130 s"),
    "log unreadable": (lambda r: setattr(r, "log_error", "bad magic"), "log unreadable: bad magic"),
}


def test_a_good_flights_record_passes():
    verdict = judge_flight(good_record())
    assert verdict.passed, verdict.failures
    assert verdict.kind == "occlusion" and verdict.drone == "cf2" and verdict.exit_code == 1
    assert verdict.outcomes == {"cf1": "reached", "cf2": "landed_early", "cf3": "reached"}
    assert verdict.events == ["supervisor: pose_stale: pose 250 ms old: holding"]
    assert verdict.min_separation_m is not None and abs(verdict.min_separation_m - 0.3) < 1e-6


@pytest.mark.parametrize("what", sorted(FAILING))
def test_the_judge_fails_a_flight_that_did_what_no_flight_may(what):
    change, reason = FAILING[what]
    record = copy.deepcopy(good_record())
    change(record)
    verdict = judge_flight(record)
    assert not verdict.passed
    assert any(f.startswith(reason) for f in verdict.failures), verdict.failures


def test_a_drone_a_fault_keeps_down_must_stay_on_the_floor():
    """upside_down on cf2: its preflight must keep it down; a record where it flew anyway fails."""
    record = good_record()
    record.faults = [fault_fields("upside_down", "cf2", {})]
    record.topics["/events"] = [e for e in record.topics["/events"] if e[1]["file"] != "fault"]
    record.topics["/events"].insert(0, event(0.5, 4, "phase", "failed: preflight failed: tumbled", "cf2"))
    verdict = judge_flight(record)
    assert "cf2 left the floor" in verdict.failures
    standing = [(t, state(-1.5, 0.0, 0.0, False)) for t, _ in record.topics["/truth/cf2"]]
    record.topics["/truth/cf2"] = standing
    record.stdout = record.stdout.replace("cf2: landed_early (pose lost)", "cf2: not_flown")
    assert judge_flight(record).passed, judge_flight(record).failures


def kill_record(down_after_s: float) -> LabRecord:
    """The ground station killed 3 s into the planning: every drone airborne then, down ``down_after_s`` later."""
    killed = T0 + 6 * S
    truth = {}
    for d in LAB_3.drones:
        samples = []
        for k in range(151):
            t = T0 + k * S // 10
            up = S <= t - T0 and t < killed + int(down_after_s * S)
            samples.append((t, state(d.start[0], d.start[1], 0.6 if up else 0.0, up)))
        truth[f"/truth/{d.name}"] = samples
    stderr = (
        "[takeoff] take-off commanded: 3 drone(s)\n[phase] swarm: flying\n"
        "[fault] injected ground_station_kill at planning + 3 s: SIGKILL of this ground station\n"
    )
    return LabRecord(
        LAB_3,
        [{"kind": "ground_station_kill", "at_phase": "planning", "at_s": 3.0}],
        exit_code=-signal.SIGKILL,
        limit_s=130.0,
        stderr=stderr,
        lab_topics=truth,
        struck_ns=killed,
        exited_ns=killed,
    )


def test_the_lab_judge_passes_drones_down_in_time_and_fails_them_later():
    good = judge_lab(kill_record(0.9))
    assert good.passed, good.failures
    assert good.events[0].startswith("3 of 3 airborne at the ground station kill; down 0.90-0.90 s after")
    late = judge_lab(kill_record(2.0))
    assert not late.passed
    assert "cf1 not down within 1.5 s of the ground_station_kill (2.00 s)" in late.failures
    lived = kill_record(0.9)
    lived.exit_code = 0
    assert f"exit 0, expected death by SIGKILL ({-signal.SIGKILL})" in judge_lab(lived).failures


def test_the_phase_a_kill_struck_in_is_read_from_the_flights_stderr():
    stderr = (
        "[phase] swarm: takeoff\n[takeoff] take-off commanded: 3 drone(s)\n[phase] swarm: flying\n"
        "[phase] swarm: landing (mission complete)\n[fault] injected ground_station_kill at landing + 0.7 s\n"
    )
    assert phase_at_kill(stderr) == "landing"
    assert phase_at_kill(stderr.replace("[phase] swarm: landing (mission complete)\n", "")) == "flying"


def test_the_truth_checks_can_fail():
    """Two airborne drones 0.1 m apart are a contact; two drones on the floor with motors off are not. A drone
    standing beyond the arena's edge with its motors off left nothing; the same spot airborne, or spinning, did."""
    airborne = {"cf1": [(0, state(0.0, 0.0, 1.0, True))], "cf2": [(0, state(0.1, 0.0, 1.0, True))]}
    assert min_separation(airborne) < CONTACT_M
    on_floor = {"cf1": [(0, state(0.0, 0.0, 0.0, False))], "cf2": [(0, state(0.1, 0.0, 0.0, False))]}
    assert min_separation(on_floor) is None
    arena = SimpleNamespace(x=(-5.0, 5.0), y=(-5.0, 5.0), z=(0.0, 3.0))

    def at(z: float, motors: bool) -> dict:
        return {"cf4": [(0, state(-5.18, 0.0, z, motors))]}

    assert outside_arena(at(0.0, False), arena, 0.1) == []
    assert outside_arena(at(0.5, True), arena, 0.1) == ["cf4 0.18 m"]
    assert outside_arena(at(0.0, True), arena, 0.1) == ["cf4 0.18 m"]
    assert outside_arena(at(0.3, False), arena, 0.1) == ["cf4 0.18 m"]  # falling
