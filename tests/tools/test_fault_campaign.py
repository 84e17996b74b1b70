"""The fault campaign's smoke test: one fault on one mission, run and judged exactly as the full campaign does
(its own reader of the log, the /truth topics, the exit code), so the command cannot rot between campaigns."""

from __future__ import annotations

from tool_modules import ROOT, load_tool


def load_campaign():  # type: ignore[no-untyped-def]
    return load_tool("fault_campaign")


def test_an_occlusion_on_lab_3_passes_the_campaigns_judge(tmp_path):
    """cf2 is occluded for 1 s with 0.23 m of room to an obstacle: the blind rule (docs/flight.md, "Blind") may
    land it before its estimate's possible drift could take it there; whatever it does, the others reach, the exit
    code says whether every drone did, and a landing has its reason in an event."""
    campaign = load_campaign()
    verdict = campaign.judge("occlusion", ROOT / "missions" / "lab-3.yaml", tmp_path)
    assert verdict.passed, verdict.failures
    others = {name: outcome for name, outcome in verdict.outcomes.items() if name != verdict.drone}
    assert len(others) == 2 and set(others.values()) == {"reached"}
    every_drone_reached = verdict.outcomes[verdict.drone] == "reached"
    assert verdict.exit_code == (0 if every_drone_reached else 1)
    if not every_drone_reached:
        assert any("pose_lost" in e and "landing now" in e for e in verdict.events), verdict.events
    assert any("pose_stale" in e for e in verdict.events)
    assert verdict.min_separation_m is not None and verdict.min_separation_m > 0.13


def test_the_judges_truth_checks_can_fail():
    """The judge is not a rubber stamp: two airborne drones 0.1 m apart in the truth are a contact; two drones on
    the floor with motors off are not."""
    campaign = load_campaign()

    def sample(x: float, z: float, motors: bool) -> tuple[int, dict]:
        return 0, {"position": {"x": x, "y": 0.0, "z": z}, "motors": motors, "crashed": False}

    airborne = {"cf1": [sample(0.0, 1.0, True)], "cf2": [sample(0.1, 1.0, True)]}
    assert campaign._min_separation(airborne) < campaign.CONTACT_M  # noqa: SLF001
    on_floor = {"cf1": [sample(0.0, 0.0, False)], "cf2": [sample(0.1, 0.0, False)]}
    assert campaign._min_separation(on_floor) is None  # noqa: SLF001


def test_planner_option_flies_a_copy_of_the_mission_with_that_kind_and_its_default_policy(tmp_path):
    from rpf_fly.mission import load_mission

    campaign = load_campaign()
    original = load_mission(ROOT / "missions" / "lab-3.yaml")
    copy = load_mission(campaign.with_planner_kind(ROOT / "missions" / "lab-3.yaml", "rpf", tmp_path))
    assert original.planner.kind == "rpf3" and copy.planner.kind == "rpf"
    assert copy.planner.policy is not None and copy.planner.policy.name == "rpf.onnx"
    assert copy.name == original.name and copy.drones == original.drones and copy.obstacles == original.obstacles
    assert copy.planner.safety_radius == original.planner.safety_radius


def test_every_random_draw_is_a_schedule_the_stack_accepts():
    """The random campaign's draws (every kind, many seeds) parse as fault schedules of the mission they fly, so a
    random run judges the stack, not a refused file; a start offset is drawn beyond the mission's tolerance."""
    import random

    from rpf_fly.flight.faults import parse_faults
    from rpf_fly.mission import load_mission

    campaign = load_campaign()
    mission = load_mission(ROOT / "missions" / "lab-3.yaml")
    rng = random.Random(7)
    for _ in range(20):
        for kind in campaign.DEFAULTS:
            params = campaign.random_fault(rng, kind, mission.safety.start_tolerance_m)
            text = campaign.schedule(kind, "cf2", params, at_s=rng.uniform(0.5, 6.0))
            (fault,) = parse_faults(text, "random.yaml", mission)
            assert fault.kind == kind
            if kind == "start_offset":
                assert sum(v * v for v in params["offset_m"]) ** 0.5 > mission.safety.start_tolerance_m


def test_a_compound_schedule_parses_and_each_fault_needs_its_own_warning():
    """Several faults a run (`--faults-per-run`): the schedule holds them all, and the judge asks each for its own
    warning after its own injection: one fault's warning does not stand in for another's."""
    from rpf_fly.flight.faults import parse_faults
    from rpf_fly.mission import load_mission

    campaign = load_campaign()
    mission = load_mission(ROOT / "missions" / "lab-3.yaml")
    faults = [campaign.fault_fields("occlusion", "cf1", None, 2.0), campaign.fault_fields("gust", "cf3", None, 4.0),
              campaign.fault_fields("blackout", None, None, 5.0)]
    parsed = parse_faults(campaign.schedule_of(faults), "compound.yaml", mission)
    assert [(f.kind, f.drone) for f in parsed] == [("occlusion", "cf1"), ("gust", "cf3"), ("blackout", None)]

    def event(t_s: float, level: int, file: str, message: str, name: str = "") -> tuple[int, dict]:
        return int(t_s * 1e9), {"level": level, "file": file, "message": message, "name": name}

    events = [event(2.0, 1, "fault", "injected occlusion", "cf1"), event(2.3, 3, "supervisor", "pose stale", "cf1"),
              event(4.0, 1, "fault", "injected gust", "cf3"), event(4.2, 3, "supervisor", "pose stale", "cf1"),
              event(6.5, 3, "supervisor", "mocap_lost: no fresh mocap pose", "")]
    occlusion, gust, blackout = faults
    assert [m["message"] for m in campaign._warnings_for(occlusion, events, 0)] == ["pose stale"]  # noqa: SLF001
    assert campaign._warnings_for(gust, events, 0) == []  # noqa: SLF001 - cf1's warning is not cf3's
    assert campaign._warnings_for(blackout, events, 0) is None  # noqa: SLF001 - never injected


def test_two_faults_at_once_on_lab_3_are_judged_on_the_truth(tmp_path):
    """A compound run flown and judged end to end: an occlusion of cf1 and a gust on cf3 in the same flight."""
    campaign = load_campaign()
    faults = [campaign.fault_fields("occlusion", "cf1", {"duration_s": 0.5}, 2.0),
              campaign.fault_fields("gust", "cf3", None, 3.0)]
    verdict = campaign.judge_faults(faults, ROOT / "missions" / "lab-3.yaml", tmp_path)
    assert verdict.passed, verdict.failures
    assert verdict.kind == "occlusion+gust" and verdict.drone == "cf1,cf3"
    assert verdict.outcomes["cf2"] == "reached"
    assert any("pose_" in e for e in verdict.events) and any("tracking" in e for e in verdict.events), verdict.events


def test_a_world_seed_copy_keeps_the_mission_and_its_policy(tmp_path):
    from rpf_fly.mission import load_mission

    campaign = load_campaign()
    original = load_mission(ROOT / "missions" / "lab-3.yaml")
    copy = load_mission(campaign.with_world_seed(ROOT / "missions" / "lab-3.yaml", 9004, tmp_path))
    assert copy.dry_run.seed == 9004 and original.dry_run.seed == 0
    assert copy.planner.policy == original.planner.policy and copy.drones == original.drones
    assert copy.name == original.name


def test_a_fault_on_a_drone_standing_with_its_motors_off_owes_no_warning():
    """A compound run may occlude a drone another fault kept on the floor (upside down): nothing to act on, so the
    judge does not ask for a warning; a drone flying at its injection still owes one."""
    campaign = load_campaign()
    occlusion = campaign.fault_fields("occlusion", "cf1", None, 4.0)
    events = [(int(4e9), {"level": 1, "file": "fault", "message": "injected occlusion for 1 s", "name": "cf1"})]

    def truth(z: float, motors: bool) -> dict:
        return {"cf1": [(int(3.99e9), {"position": {"x": 0.0, "y": 0.0, "z": z}, "motors": motors})]}

    assert campaign._grounded_at_injection(occlusion, events, truth(0.0, False))  # noqa: SLF001
    assert not campaign._grounded_at_injection(occlusion, events, truth(0.5, True))  # noqa: SLF001
    assert not campaign._grounded_at_injection(occlusion, events, truth(0.0, True))  # noqa: SLF001 - spinning up


def test_a_timed_fault_in_a_flight_that_rightly_never_took_off_is_not_owed():
    """Compound seed 12, run 0: solo with cf1 upside down and a blackout at 2 s of the planning phase. The only
    drone rightly stays down, so there is no planning phase and the blackout cannot be injected: nothing owed. A
    flight that never planned without such a reason, or a power-on fault never injected, still fails."""
    campaign = load_campaign()
    blackout = campaign.fault_fields("blackout", None, {"duration_s": 3.0}, 2.0)
    yaw = campaign.fault_fields("yaw_offset", "cf1", {"deg": 120.0}, 0.0)
    assert campaign._uninjectable(blackout, None, True)  # noqa: SLF001
    assert not campaign._uninjectable(blackout, None, False)  # noqa: SLF001 - nothing kept the drones down
    assert not campaign._uninjectable(blackout, int(1e9), True)  # noqa: SLF001 - it planned: the fault was due
    assert not campaign._uninjectable(yaw, None, True)  # noqa: SLF001 - a power-on fault is injected before that


def test_only_a_flying_or_spinning_drone_can_leave_the_arena():
    """Compound seed 15, run 13: a start offset put cf4 0.18 m beyond the arena's edge and its preflight rightly
    kept it there, motors off: it left nothing. The same spot airborne, or on the floor with its motors on, fails."""
    from types import SimpleNamespace

    campaign = load_campaign()
    arena = SimpleNamespace(x=(-5.0, 5.0), y=(-5.0, 5.0), z=(0.0, 3.0))

    def at(z: float, motors: bool) -> dict:
        return {"cf4": [(0, {"position": {"x": -5.18, "y": 0.0, "z": z}, "motors": motors})]}

    assert campaign._outside_arena(at(0.0, False), arena, 0.1) == []  # noqa: SLF001
    assert campaign._outside_arena(at(0.5, True), arena, 0.1) == ["cf4 0.18 m"]  # noqa: SLF001
    assert campaign._outside_arena(at(0.0, True), arena, 0.1) == ["cf4 0.18 m"]  # noqa: SLF001
    assert campaign._outside_arena(at(0.3, False), arena, 0.1) == ["cf4 0.18 m"]  # noqa: SLF001 - falling


def test_a_planner_fault_on_a_drone_that_will_never_plan_again_owes_no_warning():
    """Compound seed 15, run 14: a blackout's blind landing began 0.9 s before cf4's planner_error; its planner is
    never called again, so the fault has no effect. Injected while planning or holding, it still owes a warning."""
    campaign = load_campaign()
    error = campaign.fault_fields("planner_error", "cf4", {}, 5.38)
    injection = (int(5.38e9), {"level": 2, "file": "fault", "name": "cf4", "message": "injected planner_error"})

    def phase(t: float, message: str) -> tuple[int, dict]:
        return int(t * 1e9), {"level": 2, "file": "phase", "name": "cf4", "message": message}

    landing = [phase(4.46, "landing: no valid pose for 1.5 s"), injection]
    holding = [phase(4.46, "holding: pose stale"), injection]
    later = [injection, phase(5.5, "landing: planner fault")]
    other = [(t, {**m, "name": "cf3"}) if m["file"] == "phase" else (t, m) for t, m in landing]
    assert campaign._planner_unused_at_injection(error, landing)  # noqa: SLF001
    assert not campaign._planner_unused_at_injection(error, holding)  # noqa: SLF001
    assert not campaign._planner_unused_at_injection(error, later)  # noqa: SLF001 - its own landing came after
    assert not campaign._planner_unused_at_injection(error, other)  # noqa: SLF001 - another drone landed
    gust = campaign.fault_fields("gust", "cf4", {"duration_s": 1.0, "accel": [1.0, 0.0, 0.0]}, 5.38)
    assert not campaign._planner_unused_at_injection(gust, landing)  # noqa: SLF001 - a gust pushes a landing drone


def test_a_gust_owes_a_warning_only_when_it_could_push_its_drone_past_the_tracking_noise():
    """Compound seed 15, run 5: a gust of 1.06 m/s^2 began 0.25 s before its drone touched down (landing blind):
    at most 3 cm, owed nothing. The same gust on a drone airborne through it could push it 0.5 m: owed."""
    campaign = load_campaign()
    gust = campaign.fault_fields("gust", "cf4", {"duration_s": 1.0, "accel": [0.0, -1.06, 0.0]}, 3.6)
    events = [(int(3.6e9), {"level": 2, "file": "fault", "name": "cf4", "message": "injected gust for 1 s"})]

    def truth(touchdown_s: float) -> dict:
        samples = []
        for k in range(361, 471):  # 10 ms steps from 3.61 s to 4.70 s
            t = k / 100
            samples.append((int(t * 1e9), {"position": {"x": 0.0, "y": 0.0, "z": 0.0 if t >= touchdown_s else 0.3},
                                            "motors": True}))
        return {"cf4": samples}

    short = campaign._gust_push_bound(gust, events, truth(3.85))  # noqa: SLF001
    assert short is not None and short < campaign.TRACKING_NOISE_M
    whole = campaign._gust_push_bound(gust, events, truth(9.0))  # noqa: SLF001
    assert whole is not None and whole > 0.4
    occlusion = campaign.fault_fields("occlusion", "cf4", None, 3.6)
    assert campaign._gust_push_bound(occlusion, events, truth(3.85)) is None  # noqa: SLF001


def test_a_slow_estimator_divergence_is_owed_a_warning_from_when_it_leaves_the_tracking_noise():
    """Extpose campaign seed 16, run 9: a divergence at 0.12 m/s carried cf2 5 cm off after 0.42 s; the stack said it
    0.99 s after the injection (its thresholds are 0.07-0.10 m). The window runs 1 s from that effect: a warning at
    1.3 s is in time, one at 1.5 s is late; a fast divergence's window is barely moved."""
    campaign = load_campaign()

    def said_at(rate: float, after_s: float) -> bool:
        fault = campaign.fault_fields("estimator_divergence", "cf2", {"rate_m_s": rate}, 2.85)
        events = [(int(2.85e9), {"level": 2, "file": "fault", "name": "cf2",
                                 "message": f"injected estimator_divergence: rate_m_s {rate}"}),
                  (int((2.85 + after_s) * 1e9), {"level": 4, "file": "estimator", "name": "cf2", "message": "off"})]
        return bool(campaign._warnings_for(fault, events, 0))  # noqa: SLF001

    assert said_at(0.12, 1.3) and not said_at(0.12, 1.5)
    assert said_at(0.5, 1.05) and not said_at(0.5, 1.2)


def test_a_yaw_offset_under_extpose_owes_nothing_only_when_its_drone_flew_right():
    """Extpose campaign seed 16, run 6: with extpose the estimator takes mocap's yaw from the first pose, so the
    preflight finds nothing to correct and cf2 reached its goal: nothing owed. Without extpose, or had it not
    reached, the warning is still owed."""
    from types import SimpleNamespace

    campaign = load_campaign()
    yaw = campaign.fault_fields("yaw_offset", "cf2", {"deg": -123.8}, 0.0)

    def mission(extpos: str):  # type: ignore[no-untyped-def]
        return SimpleNamespace(radio=SimpleNamespace(extpos=extpos))

    assert campaign._corrected_by_extpose(yaw, mission("extpose"), {"cf2": True})  # noqa: SLF001
    assert not campaign._corrected_by_extpose(yaw, mission("extpose"), {"cf2": False})  # noqa: SLF001
    assert not campaign._corrected_by_extpose(yaw, mission("extpos"), {"cf2": True})  # noqa: SLF001
    gust = campaign.fault_fields("gust", "cf2", {"duration_s": 1.0, "accel": [1.0, 0.0, 0.0]}, 3.0)
    assert not campaign._corrected_by_extpose(gust, mission("extpose"), {"cf2": True})  # noqa: SLF001


def test_a_frame_fault_wholly_inside_a_loop_stall_owes_nothing_but_one_outliving_it_does():
    """A pose jump that began and ended while the loop was stalled never reached the stack (it reads only the newest
    frame when it wakes); one that outlives the stall does, and owes its warning. A pose gap is not such a fault:
    the stack says it after the fact."""
    campaign = load_campaign()
    events = [(int(3.0e9), {"level": 2, "file": "fault", "name": "flight", "message": "injected loop_stall for 1.5 s"}),
              (int(3.5e9), {"level": 2, "file": "fault", "name": "cf2",
                            "message": "injected pose_jump for 0.4 s: offset_m [0.6, 0.0, 0.0]"})]
    inside = campaign.fault_fields("pose_jump", "cf2", {"duration_s": 0.4, "offset_m": [0.6, 0.0, 0.0]}, 3.5)
    assert campaign._inside_loop_stall(inside, events)  # noqa: SLF001
    outliving = campaign.fault_fields("pose_jump", "cf2", {"duration_s": 1.2, "offset_m": [0.6, 0.0, 0.0]}, 3.5)
    assert not campaign._inside_loop_stall(outliving, events)  # noqa: SLF001
    occlusion = campaign.fault_fields("occlusion", "cf2", {"duration_s": 0.4}, 3.5)
    assert not campaign._inside_loop_stall(occlusion, events)  # noqa: SLF001


def test_a_loop_stall_that_delayed_no_tick_past_the_late_line_owes_nothing():
    """Extpose compound seed 18, run 6: a 0.12 s stall at 15 Hz began as the loop waited for its next frame and
    made one tick 59 ms late (0.126 s after the last one): under the period plus 0.1 s, the loop's own late line,
    so owed nothing. The same stall at 100 Hz holds the ticks 0.13 s apart, past 0.11 s: owed."""
    campaign = load_campaign()
    stall = campaign.fault_fields("loop_stall", None, {"duration_s": 0.12}, 4.74)
    events = [(int(4.742e9), {"level": 2, "file": "fault", "name": "flight", "message": "injected loop_stall for 0.12 s"})]

    def ticks(period: float, gap: float) -> dict:
        """Ticks every ``period`` from 4.0 s; the one after 4.742 s comes ``gap`` later; then every period."""
        before = [4.742 - k * period for k in range(12, -1, -1)]
        after = [4.742 + gap + k * period for k in range(12)]
        return {"cf1": [int(t * 1e9) for t in before + after]}

    slow = campaign._stall_within_jitter(stall, events, ticks(1 / 15, 0.126), 1 / 15)  # noqa: SLF001
    assert slow is not None and abs(slow - 0.126) < 1e-3
    assert campaign._stall_within_jitter(stall, events, ticks(0.01, 0.13), 0.01) is None  # noqa: SLF001
