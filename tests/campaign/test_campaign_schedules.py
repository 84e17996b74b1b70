"""The campaign's schedules and missions (rpf_fly/campaign/schedules.py, missions.py): every kind the schedule
format knows has its fault here, every draw is a schedule the stack accepts, the lab kinds' runs, the mission copies
keep the mission, and a kind is checked with the kind meant."""

from __future__ import annotations

import random
from pathlib import Path

import pytest

from rpf_fly.campaign.missions import with_extpose, with_planner_kind, with_world_seed
from rpf_fly.campaign.runner import lab_runs
from rpf_fly.campaign.schedules import (
    ALL_KINDS,
    DEFAULTS,
    LAB_KINDS,
    ScheduleError,
    check_kinds,
    draw_faults,
    middle_drone_fault,
    random_fault,
    schedule,
    schedule_of,
)
from rpf_fly.flight.faults import FAULT_KINDS, parse_faults
from rpf_fly.mission import load_mission

ROOT = Path(__file__).resolve().parents[2]
LAB_3 = ROOT / "missions" / "lab-3.yaml"


def test_every_kind_of_the_schedule_format_is_in_the_campaign_and_its_default_parses():
    assert set(ALL_KINDS) == set(FAULT_KINDS) and not LAB_KINDS & set(DEFAULTS)
    mission = load_mission(LAB_3)
    for kind in DEFAULTS:
        fault = middle_drone_fault(kind, mission)
        (parsed,) = parse_faults(schedule_of([fault]), "default.yaml", mission)
        assert parsed.kind == kind and parsed.drone in (None, "cf2")


def test_every_random_draw_is_a_schedule_the_stack_accepts():
    """The random draws (every kind, many seeds) parse as fault schedules of the mission they fly, so a random run
    judges the stack, not a refused file; a start offset is drawn beyond the mission's tolerance."""
    mission = load_mission(LAB_3)
    rng = random.Random(7)
    for _ in range(20):
        for kind in DEFAULTS:
            params = random_fault(rng, kind, mission.safety.start_tolerance_m)
            (fault,) = parse_faults(schedule(kind, "cf2", params, at_s=rng.uniform(0.5, 6.0)), "random.yaml", mission)
            assert fault.kind == kind
            if kind == "start_offset":
                assert sum(v * v for v in params["offset_m"]) ** 0.5 > mission.safety.start_tolerance_m


def test_a_compound_draw_is_of_different_kinds_and_the_same_seed_draws_the_same():
    mission = load_mission(LAB_3)
    faults, draws = draw_faults(random.Random(3), mission, None, 3)
    assert len({f["kind"] for f in faults}) == 3 and len(draws) == 3
    assert parse_faults(schedule_of(faults), "compound.yaml", mission)
    assert draw_faults(random.Random(3), mission, None, 3) == (faults, draws)
    only, _ = draw_faults(random.Random(3), mission, ["gust", "occlusion"], 5)
    assert sorted(f["kind"] for f in only) == ["gust", "occlusion"]


def test_a_misspelt_kind_names_the_kind_meant():
    assert check_kinds(["gust", "reboot"]) == ["gust", "reboot"]
    with pytest.raises(ScheduleError, match=r"^--kinds: unknown fault kind 'gsut' \(did you mean 'gust'\?\)$"):
        check_kinds(["gust", "gsut"])
    with pytest.raises(ScheduleError, match="expected one of occlusion, blackout"):
        check_kinds(["zzzz"])


def test_the_lab_kinds_fly_each_phase_on_two_missions_and_every_run_parses(tmp_path):
    runs = lab_runs(sorted(LAB_KINDS), None, None, False, tmp_path)
    missions: dict[str, set[str]] = {}
    for kind, path, fault in runs:
        missions.setdefault(kind, set()).add(path.stem)
        (parsed,) = parse_faults(schedule_of([fault]), "run.yaml", load_mission(path))
        assert parsed.kind == kind
    assert missions == {"ground_station_kill": {"lab-3", "circle-8-r3"}, "dongle_unplug": {"pillars-6", "split-10"}}
    phases = sorted(f["at_phase"] for k, _, f in runs if k == "ground_station_kill")
    assert phases == sorted(["takeoff", "settle", "planning", "landing"] * 2)
    # on a mission of its own: each phase's kill, the unplug of its highest dongle
    pillars = str(ROOT / "missions" / "campaign" / "pillars-6.yaml")
    other = lab_runs(["dongle_unplug", "ground_station_kill"], [pillars], None, False, tmp_path)
    assert [(k, f.get("dongle", f.get("at_phase"))) for k, _, f in other] == [
        ("ground_station_kill", "takeoff"),
        ("ground_station_kill", "settle"),
        ("ground_station_kill", "planning"),
        ("ground_station_kill", "landing"),
        ("dongle_unplug", 1),
    ]
    assert lab_runs(["occlusion"], None, None, False, tmp_path) == []


def test_the_mission_copies_keep_the_mission_and_change_one_thing(tmp_path):
    original = load_mission(LAB_3)
    planner = load_mission(with_planner_kind(LAB_3, "rpf", tmp_path))
    assert original.planner.kind == "rpf3" and planner.planner.kind == "rpf"
    assert planner.planner.policy is not None and planner.planner.policy.name == "rpf.onnx"
    assert planner.planner.safety_radius == original.planner.safety_radius
    seeded = load_mission(with_world_seed(LAB_3, 9004, tmp_path))
    assert seeded.dry_run.seed == 9004 and original.dry_run.seed == 0
    assert seeded.planner.policy == original.planner.policy
    extpose = load_mission(with_extpose(LAB_3, tmp_path))
    assert extpose.radio.extpos == "extpose" and original.radio.extpos != "extpose"
    assert extpose.planner.policy == original.planner.policy
    for copy in (planner, seeded, extpose):
        assert copy.name == original.name and copy.drones == original.drones and copy.obstacles == original.obstacles
