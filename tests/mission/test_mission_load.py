"""Valid missions load into the right dataclasses; formations expand; policies resolve; with_planner re-validates."""

from __future__ import annotations

import math
import os
from pathlib import Path

import pytest

from rpf_fly.mission import (
    Arena,
    BoxObstacle,
    CircleObstacle,
    Drone,
    FlightSettings,
    Formation,
    Mission,
    MissionError,
    MocapSettings,
    PlannerSettings,
    RadioSettings,
    SimSettings,
    expand_formation,
    load_mission,
    parse_mission,
    parse_uri,
    with_planner,
)
from rpf_fly.mission.policy_paths import PROJECT_POLICIES

BASE = """\
arena: {x: [-2, 2], y: [-2, 2], z: [0, 1.5]}
drones:
  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [-1.5, 0], goal: [1.5, 0]}
  - {name: cf2, uri: radio://0/80/2M/E7E7E7E702, start: [1.5, 1], goal: [-1.5, 1]}
"""

FULL = """\
name: lab-3
arena: {x: [-2.0, 2.0], y: [-2.0, 2.0], z: [0.0, 1.5]}     # geofence
flight: {height: 0.6, speed: 0.5, rate_hz: 20, goal_tolerance: 0.1, takeoff_s: 2.0, land_s: 2.0, timeout_s: 60}
planner: {kind: rpf, policy: policies/rpf.onnx, sensing_range: 6.0, safety_radius: 0.1, influence_range: 10.0,
          wall_following: false, wall_threshold: 0.5, preset: paper, neighbour_aggregate: mean, eta: 0.04,
          lambda: 1.5}
mocap: {kind: natnet, server: 10.0.0.10, local_ip: 10.0.0.2, multicast: true, multicast_group: 239.255.42.99,
        command_port: 1510, data_port: 1511, up_axis: y, noise_m: 0.001, latency_s: 0.01, rate_hz: 120,
        dropout: 0.05, timeout_s: 0.3}
radio: {kind: cflib, min_battery_v: 3.6, extpos: extpose}
sim: {time_limit_s: 60, start_jitter_m: 0.05, angle_jitter_deg: 5}
obstacles:
  - {shape: circle, center: [0.0, 0.5], radius: 0.1}
  - {shape: box, min: [1.0, -0.5], max: [1.2, 0.5]}
drones:
  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, rigid_body: cf1, start: [-1.5, 0.0], goal: [1.5, 1.0]}
  - {name: cf_2, uri: "fake://0/80/250K/e7e7e7e702?rate_limit=100", rigid_body: Body 2, start: [-1.5, 1.0],
     goal: [1.5, -1.0]}
"""


def write(path: Path, text: str = "") -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


# ----------------------------------------------------------------------------------------- round trip


def test_full_mission_round_trips(workdir):
    policy = write(workdir / "policies" / "rpf.onnx")
    path = write(workdir / "m.yaml", FULL)
    mission = load_mission(path)
    assert mission == Mission(
        name="lab-3",
        arena=Arena(x=(-2.0, 2.0), y=(-2.0, 2.0), z=(0.0, 1.5)),
        flight=FlightSettings(
            height=0.6, speed=0.5, rate_hz=20.0, goal_tolerance=0.1, takeoff_s=2.0, land_s=2.0, timeout_s=60.0
        ),
        planner=PlannerSettings(
            kind="rpf",
            policy=policy.resolve(),
            sensing_range=6.0,
            safety_radius=0.1,
            influence_range=10.0,
            wall_following=False,
            wall_threshold=0.5,
            preset="paper",
            neighbour_aggregate="mean",
            eta=0.04,
            lam=1.5,
        ),
        mocap=MocapSettings(
            kind="natnet",
            server="10.0.0.10",
            local_ip="10.0.0.2",
            multicast=True,
            multicast_group="239.255.42.99",
            command_port=1510,
            data_port=1511,
            up_axis="y",
            noise_m=0.001,
            latency_s=0.01,
            rate_hz=120.0,
            dropout=0.05,
            timeout_s=0.3,
        ),
        radio=RadioSettings(kind="cflib", min_battery_v=3.6, extpos="extpose"),
        sim=SimSettings(time_limit_s=60.0, start_jitter_m=0.05, angle_jitter_deg=5.0),
        obstacles=(CircleObstacle(center=(0.0, 0.5), radius=0.1), BoxObstacle(min=(1.0, -0.5), max=(1.2, 0.5))),
        drones=(
            Drone("cf1", "radio://0/80/2M/E7E7E7E701", "cf1", (-1.5, 0.0), (1.5, 1.0)),
            Drone("cf_2", "fake://0/80/250K/e7e7e7e702?rate_limit=100", "Body 2", (-1.5, 1.0), (1.5, -1.0)),
        ),
        formation=None,
        source=path,
        text=FULL,
    )
    assert mission.text == FULL
    assert mission.flight.dt == pytest.approx(0.05)


def test_minimal_mission_takes_the_dataclass_defaults(load):
    mission = load(BASE)
    assert mission.name == "m"
    assert mission.source == Path("m.yaml")
    assert mission.arena == Arena(x=(-2.0, 2.0), y=(-2.0, 2.0), z=(0.0, 1.5))
    assert mission.flight == FlightSettings()
    # the default planner is RPF-3, with the shipped policy found for it (the product's default, docs/bench/rpf3.md)
    assert mission.planner == PlannerSettings(policy=PROJECT_POLICIES.resolve() / "rpf3.onnx")
    assert mission.planner.kind == "rpf3"
    assert mission.mocap == MocapSettings()
    assert mission.radio == RadioSettings()
    assert mission.sim == SimSettings()
    assert mission.obstacles == ()
    assert mission.formation is None
    assert [d.rigid_body for d in mission.drones] == ["cf1", "cf2"]


def test_the_default_planners_missing_policy_is_one_line_naming_the_default(tmp_path, monkeypatch):
    """Without the shipped policies (a wheel install, a copy of rpf_fly alone), a mission that names no planner,
    or names kind rpf3 without a policy, fails at load with the file, the field and where it looked."""
    import rpf_fly.mission.policy_paths as policy_paths

    monkeypatch.setattr(policy_paths, "PROJECT_POLICIES", tmp_path / "nowhere")
    monkeypatch.chdir(tmp_path)
    path = tmp_path / "m.yaml"
    path.write_text(BASE)
    with pytest.raises(MissionError) as err:
        load_mission(path)
    text = str(err.value)
    assert "\n" not in text and text.startswith(
        f"{path}:1: planner.policy: the default planner kind 'rpf3' needs a policy"
    )
    assert "policies/rpf3.onnx" in text and "planner.kind" in text
    path.write_text(BASE + "planner: {kind: rpf3}\n")
    with pytest.raises(MissionError, match=r"m.yaml:\d+: planner.policy: planner kind 'rpf3' needs a policy"):
        load_mission(path)
    path.write_text(BASE + "planner: {kind: apf}\n")
    assert load_mission(path).planner.kind == "apf"


def test_numbers_are_floats_and_arena_z_defaults(load):
    mission = load("arena: {x: [-2, 2], y: [-2, 2]}\n" + BASE.split("\n", 1)[1])
    assert mission.arena.z == Arena(x=(0, 1), y=(0, 1)).z
    assert all(type(v) is float for d in mission.drones for v in (*d.start, *d.goal))
    assert type(mission.arena.x[0]) is float


def test_exponent_without_a_dot_is_a_number(load):
    mission = load(BASE + "mocap: {noise_m: 1e-3, latency_s: 2.5E-2}\n")
    assert (mission.mocap.noise_m, mission.mocap.latency_s) == (0.001, 0.025)


def test_empty_obstacle_list(load):
    assert load(BASE + "obstacles: []\n").obstacles == ()


def test_block_style_and_comments(load):
    mission = load("""\
        # lab layout
        name: block
        arena:
          x: [-2, 2]   # metres
          y: [-2, 2]
        drones:
          - name: a1
            uri: radio://0/80/2M/E7E7E7E701
            rigid_body: "7"
            start: [0, 0]
            goal:
              - 1
              - 1
        """)
    assert mission.name == "block"
    assert mission.drones == (Drone("a1", "radio://0/80/2M/E7E7E7E701", "7", (0.0, 0.0), (1.0, 1.0)),)


def test_anchors_and_merge_keys(load):
    mission = load("""\
        arena: {x: [-2, 2], y: [-2, 2]}
        planner: &p {kind: apf, eta: 0.03}
        flight:
          <<: {speed: 0.4, height: 0.5}
          height: 0.7
        drones:
          - {name: a, uri: radio://0/80/2M/E7E7E7E701, start: &s [0, 0], goal: [1, 1]}
          - {name: b, uri: radio://0/80/2M/E7E7E7E702, start: [1, 0], goal: *s}
        """)
    assert mission.planner.eta == 0.03
    assert (mission.flight.speed, mission.flight.height) == (0.4, 0.7)
    assert mission.drones[1].goal == (0.0, 0.0)


def test_date_like_name_stays_text(load):
    assert load("name: 2024-05-01\n" + BASE).name == "2024-05-01"


def test_parse_mission_without_a_source():
    mission = parse_mission(BASE)
    assert (mission.name, mission.source, mission.text) == ("mission", None, BASE)


def test_parse_mission_with_a_source_names_it(tmp_path):
    with pytest.raises(MissionError) as info:
        parse_mission("arena: 1\n" + BASE.split("\n", 1)[1], source=tmp_path / "x.yaml")
    assert str(info.value).startswith(f"{tmp_path / 'x.yaml'}:1: arena: expected a mapping, got number 1")


def test_utf8_bom_is_ignored(workdir):
    (workdir / "m.yaml").write_bytes(b"\xef\xbb\xbf" + BASE.encode())
    assert load_mission("m.yaml").text == BASE


# -------------------------------------------------------------------------------------------- formations


def test_formation_expansion(load):
    mission = load("""\
        arena: {x: [-5, 5], y: [-5, 5]}
        formation: {kind: circle_swap, count: 12, radius: 3, center: [1, -0.5], phase_deg: 90,
                    uri_base: radio://1/90/1M/E7E7E7E7, name_prefix: uav}
        """)
    f = Formation(
        kind="circle_swap",
        count=12,
        radius=3.0,
        center=(1.0, -0.5),
        uri_base="radio://1/90/1M/E7E7E7E7",
        name_prefix="uav",
        phase_deg=90.0,
    )
    assert mission.formation == f
    assert len(mission.drones) == 12
    assert [d.name for d in mission.drones] == [f"uav{i}" for i in range(1, 13)]
    assert mission.drones[9].uri == "radio://1/90/1M/E7E7E7E70A"
    assert mission.drones[11].uri == "radio://1/90/1M/E7E7E7E70C"
    for i, d in enumerate(mission.drones):
        t = math.pi / 2 + 2 * math.pi * i / 12
        assert d.start == pytest.approx((1 + 3 * math.cos(t), -0.5 + 3 * math.sin(t)))
        assert d.goal == pytest.approx((1 - 3 * math.cos(t), -0.5 - 3 * math.sin(t)))
        assert d.rigid_body == d.name
        assert parse_uri(d.uri).address == f"E7E7E7E7{i + 1:02X}"
    assert mission.drones[0].start == pytest.approx((1.0, 2.5))  # phase 90: the first drone on top
    assert mission.drones[0].goal == pytest.approx((1.0, -3.5))


def test_formation_defaults(load):
    mission = load("arena: {x: [-4, 4], y: [-4, 4]}\nformation: {kind: circle_swap, count: 8, radius: 3.0}\n")
    assert mission.formation == Formation(kind="circle_swap", count=8, radius=3.0)
    assert mission.drones[0] == Drone("cf1", "radio://0/80/2M/E7E7E7E701", "cf1", (3.0, 0.0), (-3.0, 0.0))
    assert mission.drones[2].start == pytest.approx((0.0, 3.0))
    assert mission.drones == expand_formation(mission.formation)


def test_single_drone_formation(load):
    mission = load("arena: {x: [-4, 4], y: [-4, 4]}\nformation: {kind: circle_swap, count: 1, radius: 1}\n")
    assert mission.drones == (Drone("cf1", "radio://0/80/2M/E7E7E7E701", "cf1", (1.0, 0.0), (-1.0, 0.0)),)


# ----------------------------------------------------------------------------------------------- URIs


def test_parse_uri():
    uri = parse_uri("fake://3/125/250K/e7e7e7e7aa?rate_limit=100&x=1")
    assert uri == ("fake", 3, 125, "250K", "E7E7E7E7AA", "rate_limit=100&x=1")
    assert uri.link == (125, "E7E7E7E7AA")
    assert parse_uri("radio://0/0/1M/0000000000").query == ""


# ----------------------------------------------------------------------------------------- policy paths


def test_policy_absolute_path(workdir):
    policy = write(workdir / "elsewhere" / "p.onnx")
    write(workdir / "missions" / "m.yaml", BASE + f"planner: {{kind: rpf, policy: '{policy}'}}\n")
    assert load_mission("missions/m.yaml").planner.policy == policy.resolve()


def test_policy_relative_to_the_mission_wins_over_the_current_directory(workdir):
    beside = write(workdir / "missions" / "policies" / "p.onnx")
    write(workdir / "policies" / "p.onnx")
    write(workdir / "missions" / "m.yaml", BASE + "planner: {kind: ppo, policy: policies/p.onnx}\n")
    mission = load_mission("missions/m.yaml")
    assert mission.planner.policy == beside.resolve()
    assert mission.planner.policy.is_absolute()


def test_policy_relative_to_the_current_directory(workdir):
    here = write(workdir / "policies" / "p.onnx")
    write(workdir / "missions" / "m.yaml", BASE + "planner: {kind: rpf, policy: policies/p.onnx}\n")
    assert load_mission("missions/m.yaml").planner.policy == here.resolve()


def test_default_policy_for_a_policy_kind(workdir):
    default = write(workdir / "missions" / "policies" / "rpf-mean.onnx")
    write(workdir / "missions" / "m.yaml", BASE + "planner: {kind: rpf-mean}\n")
    assert load_mission("missions/m.yaml").planner.policy == default.resolve()


def test_default_policy_from_the_current_directory(workdir):
    default = write(workdir / "policies" / "ppo.onnx")
    write(workdir / "missions" / "m.yaml", BASE + "planner: {kind: ppo}\n")
    assert load_mission("missions/m.yaml").planner.policy == default.resolve()


def test_kind_without_policy_keeps_a_given_policy(workdir):
    gains = write(workdir / "gains.onnx")
    write(workdir / "m.yaml", BASE + "planner: {kind: apf, policy: gains.onnx}\n")
    assert load_mission("m.yaml").planner.policy == gains.resolve()


def test_policy_directory_is_not_a_policy(workdir, fail, no_shipped_policies):
    (workdir / "policies" / "rpf.onnx").mkdir(parents=True)
    fail(BASE + "planner: {kind: rpf}\n", "m.yaml:5: planner.policy: planner kind 'rpf' needs a policy")


def test_policy_resolution_does_not_depend_on_the_directory_it_was_loaded_from(workdir):
    policy = write(workdir / "missions" / "policies" / "rpf.onnx")
    path = write(workdir / "missions" / "m.yaml", BASE + "planner: {kind: rpf}\n")
    os.chdir(workdir / "missions" / "policies")
    assert load_mission(path.resolve()).planner.policy == policy.resolve()


# ----------------------------------------------------------------------------------------- with_planner


@pytest.fixture
def lab(workdir) -> Mission:
    write(workdir / "missions" / "policies" / "rpf.onnx")
    write(workdir / "missions" / "m.yaml", BASE + "planner: {kind: rpf, eta: 0.04}\n")
    return load_mission("missions/m.yaml")


def test_with_planner_switches_to_a_kind_without_a_policy(lab):
    apf = with_planner(lab, "apf-paper")
    assert apf.planner.kind == "apf-paper"
    assert apf.planner.policy is None
    assert apf.planner.eta == 0.04
    assert apf.drones == lab.drones and apf.text == lab.text


def test_with_planner_same_kind_keeps_the_policy(lab):
    assert with_planner(lab, "rpf").planner.policy == lab.planner.policy


def test_with_planner_no_wall_following(lab):
    mission = with_planner(lab, lab.planner.kind, wall_following=False)
    assert mission.planner.wall_following is False
    assert lab.planner.wall_following is True


def test_with_planner_unknown_kind(lab):
    with pytest.raises(MissionError) as info:
        with_planner(lab, "rfp")
    assert str(info.value).startswith("missions/m.yaml:0: --planner: unknown planner kind 'rfp' (did you mean 'rpf'?)")


def test_with_planner_policy_kind_without_a_default(lab, no_shipped_policies):
    with pytest.raises(MissionError) as info:
        with_planner(lab, "ppo")
    assert str(info.value).startswith("missions/m.yaml:0: --planner: planner kind 'ppo' needs a policy: give --policy")


def test_with_planner_policy_from_the_current_directory(lab, workdir):
    mine = write(workdir / "mine.onnx")
    assert with_planner(lab, "ppo", policy="mine.onnx").planner.policy == mine.resolve()


def test_with_planner_policy_missing(lab, workdir):
    with pytest.raises(MissionError) as info:
        with_planner(lab, "ppo", policy=Path("nope.onnx"))
    message = str(info.value)
    assert message.startswith("missions/m.yaml:0: --policy: policy file 'nope.onnx' not found (looked in ")
    assert message.index(str(workdir / "nope.onnx")) < message.index(str(workdir / "missions" / "nope.onnx"))


def test_with_planner_checks_override_values(lab):
    with pytest.raises(MissionError) as info:
        with_planner(lab, "rpf", sensing_range=-1.0)
    assert str(info.value) == "missions/m.yaml:0: --sensing-range: must be positive, got -1.0"
    with pytest.raises(MissionError) as info:
        with_planner(lab, "rpf", wall_following="no")
    assert str(info.value) == "missions/m.yaml:0: --wall-following: expected true or false, got string 'no'"


def test_with_planner_override_rechecks_the_layout(lab):
    with pytest.raises(MissionError) as info:
        with_planner(lab, "rpf", safety_radius=0.9)
    assert str(info.value).startswith("missions/m.yaml:0: --safety-radius: drones[1].goal: ")


def test_with_planner_override_keeps_the_plausible_range(lab):
    with pytest.raises(MissionError) as info:
        with_planner(lab, "rpf", safety_radius=10)
    assert str(info.value).startswith("missions/m.yaml:0: --safety-radius: 10 m: above 1 m")
    assert str(info.value).endswith("lengths are in m (10 cm is 0.1 m)")


def test_with_planner_unknown_override_is_a_programming_error(lab):
    with pytest.raises(TypeError, match="unknown planner override 'colour'"):
        with_planner(lab, "rpf", colour="red")


def test_with_planner_lambda_override(lab):
    assert with_planner(lab, "apf", lam=1.0).planner.lam == 1.0


def test_safety_section_defaults_and_values(tmp_path):
    from rpf_fly.mission import SafetySettings, parse_mission

    base = (
        "arena: {x: [-2, 2], y: [-2, 2]}\n"
        "drones:\n  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [0, 0], goal: [1, 0]}\n"
    )
    assert parse_mission(base).safety == SafetySettings()
    m = parse_mission(
        base + "safety: {pose_timeout_s: 0.5, on_separation: land, arrival_hold_s: 0}\nradio: {extpos_rate_hz: 50}\n"
    )
    assert m.safety.pose_timeout_s == 0.5 and m.safety.on_separation == "land" and m.radio.extpos_rate_hz == 50


def test_safety_section_rejects_unknown_response():
    import pytest as _pytest

    from rpf_fly.mission import MissionError, parse_mission

    text = (
        "arena: {x: [-2, 2], y: [-2, 2]}\n"
        "safety: {on_obstacle: panic}\n"
        "drones:\n  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [0, 0], goal: [1, 0]}\n"
    )
    with _pytest.raises(MissionError, match=r"<string>:2: safety.on_obstacle: .*panic"):
        parse_mission(text)


# ------------------------------------------------------------------------------- guidance and margin


@pytest.mark.parametrize(
    "kind, guidance, margin",
    [
        ("apf", "path", 0.05),
        ("orca", "none", 0.05),
        ("apf-paper", "none", 0.0),
        ("rpf", "none", 0.0),
        ("rpf-mean", "none", 0.0),
        ("ppo", "none", 0.0),
        ("rpf3", "path", 0.05),
    ],
)
def test_guidance_and_margin_default_by_kind(kind, guidance, margin):
    """On for the product's planner; the paper's planners stay as the paper wrote them."""
    from rpf_fly.mission.model import PlannerSettings

    settings = PlannerSettings(kind=kind)
    assert settings.guidance_mode == guidance and settings.margin_m == margin
    assert PlannerSettings(kind="apf", preset="paper").guidance_mode == "none"


def test_guidance_and_margin_keys(load):
    mission = load(
        """\
        arena: {x: [-2, 2], y: [-2, 2]}
        planner: {kind: apf-paper, guidance: path, margin: 0.1}
        drones:
          - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [-1.5, 0], goal: [1.5, 0]}
        """
    )
    assert mission.planner.guidance_mode == "path" and mission.planner.margin_m == 0.1
    from rpf_fly.mission.load import with_planner

    other = with_planner(mission, "apf", guidance="none", margin=0)
    assert other.planner.guidance_mode == "none" and other.planner.margin_m == 0
