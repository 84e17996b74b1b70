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
    copy = load_mission(campaign.with_planner_kind(ROOT / "missions" / "lab-3.yaml", "rpf3", tmp_path))
    assert original.planner.kind == "rpf" and copy.planner.kind == "rpf3"
    assert copy.planner.policy is not None and copy.planner.policy.name == "rpf3.onnx"
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
