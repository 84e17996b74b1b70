"""Every validation error: each one names the file, the line of the offending value and the field."""

from __future__ import annotations

import pytest

from rpf_fly.flight.blind import BLIND_DRIFT_M_S2

# Two drones crossing a 4 m arena; the tests rely on its line numbers (drones[0] on line 3, drones[1] on line 4).
BASE = """\
arena: {x: [-2, 2], y: [-2, 2], z: [0, 1.5]}
drones:
  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [-1.5, 0], goal: [1.5, 0]}
  - {name: cf2, uri: radio://0/80/2M/E7E7E7E702, start: [1.5, 1], goal: [-1.5, 1]}
"""
ARENA = "arena: {x: [-2, 2], y: [-2, 2], z: [0, 1.5]}\n"


def drone(name="cf3", uri="radio://0/80/2M/E7E7E7E703", start="[0, -1]", goal="[0, 1.5]", extra=""):
    return f"  - {{name: {name}, uri: {uri}, start: {start}, goal: {goal}{extra}}}\n"


# ------------------------------------------------------------------------------------ drones / formation


def test_missing_drones(fail):
    fail("# lab\n" + ARENA, "m.yaml:2: drones: missing: give a `drones` list or a `formation`")


def test_missing_arena(fail):
    fail(BASE.replace(ARENA, "name: x\n"), "m.yaml:1: arena: missing required key")


def test_empty_drones_list(fail):
    fail(ARENA + "drones: []\n", "m.yaml:2: drones: empty list: a mission needs at least one drone")


def test_drones_and_formation(fail):
    fail(
        BASE + "formation: {kind: circle_swap, count: 4, radius: 1}\n",
        "m.yaml:5: formation: give either `drones` or `formation`, not both",
    )


def test_drones_not_a_list(fail):
    fail(
        ARENA + "drones: {cf1: radio://0/80/2M/E7E7E7E701}\n",
        "m.yaml:2: drones: expected a list of drones, got a mapping",
    )


def test_drone_not_a_mapping(fail):
    fail(BASE + "  - cf3\n", "m.yaml:5: drones[2]: expected a drone mapping {name, uri, start, goal}, got string 'cf3'")


def test_drone_missing_uri(fail):
    fail(
        BASE + "  - name: cf3\n    start: [0, -1]\n    goal: [0, 1.5]\n",
        "m.yaml:5: drones[2].uri: missing required key",
    )


def test_duplicate_drone_names(fail):
    fail(BASE + drone(name="cf1"), "m.yaml:5: drones[2].name: duplicate drone name 'cf1' (also drones[0].name, line 3)")


def test_duplicate_uri_ignores_case(fail):
    fail(
        BASE + drone(uri="radio://0/80/2M/e7e7e7e701"),
        "m.yaml:5: drones[2].uri: duplicate URI 'radio://0/80/2M/e7e7e7e701'",
        "same channel 80 and address E7E7E7E701 as drones[0].uri",
    )


def test_duplicate_uri_other_dongle_same_crazyflie(fail):
    fail(
        BASE + drone(uri="'radio://1/80/2M/E7E7E7E702?rate_limit=100'"),
        "m.yaml:5: drones[2].uri: duplicate URI",
        "both would reach the same Crazyflie",
    )


def test_same_address_on_another_channel_is_another_drone(load):
    mission = load(BASE + drone(uri="radio://0/90/2M/E7E7E7E701"))
    assert len(mission.drones) == 3


def test_duplicate_rigid_body(fail):
    fail(
        BASE + drone(extra=", rigid_body: cf2"),
        "m.yaml:5: drones[2].rigid_body: duplicate rigid_body 'cf2': also the rigid body of drones[1] (line 4)",
    )


def test_duplicate_rigid_body_defaulted_from_name(fail):
    text = (
        ARENA
        + "drones:\n"
        + drone(name="cf1", uri="radio://0/80/2M/E7E7E7E701", extra=", rigid_body: cf2")
        + drone(name="cf2", uri="radio://0/80/2M/E7E7E7E702", start="[1, 1]")
    )
    fail(
        text,
        "m.yaml:4: drones[1].rigid_body: duplicate rigid_body 'cf2' (defaulted from the name)",
        "drones[0] (line 3)",
    )


@pytest.mark.parametrize(
    "uri, part",
    [
        ("http://0/80/2M/E7E7E7E703", "expected radio://DONGLE/CHANNEL/RATE/ADDRESS"),
        ("radio://0/80/E7E7E7E703", "3 path parts instead of 4"),
        ("radio://0/80/2M/E7E7E7E703/x", "5 path parts instead of 4"),
        ("radio://a/80/2M/E7E7E7E703", "dongle 'a'"),
        ("radio://0/126/2M/E7E7E7E703", "channel '126' in 'radio://0/126/2M/E7E7E7E703' must be an integer 0-125"),
        ("radio://0/-1/2M/E7E7E7E703", "channel '-1'"),
        ("radio://0/80/3M/E7E7E7E703", "data rate '3M' in 'radio://0/80/3M/E7E7E7E703' must be one of 250K, 1M, 2M"),
        ("radio://0/80/2m/E7E7E7E703", "data rate '2m'"),
        ("radio://0/80/2M/E7E7E7E7", "address 'E7E7E7E7' in 'radio://0/80/2M/E7E7E7E7' must be 10 hex digits"),
        ("radio://0/80/2M/E7E7E7E7ZZ", "address 'E7E7E7E7ZZ'"),
        ("'radio://0/80/2M/E7E7E7E703?rate_limit'", "query 'rate_limit'"),  # a '?' needs quotes in {...}
        ("RADIO://0/80/2M/E7E7E7E703", "expected radio://"),
    ],
)
def test_malformed_uri(fail, uri, part):
    fail(BASE + drone(uri=uri), "m.yaml:5: drones[2].uri: ", part)


def test_uri_not_a_string(fail):
    fail(BASE + drone(uri="42"), "m.yaml:5: drones[2].uri: expected a string, got number 42")


@pytest.mark.parametrize("name", ["3cf", "'cf 3'", "cf/3", "cf.3", "_cf3", "'é3'"])
def test_bad_drone_name(fail, name):
    fail(BASE + drone(name=name), "m.yaml:5: drones[2].name: drone name ", "must start with a letter")


def test_empty_drone_name(fail):
    fail(BASE + drone(name="''"), "m.yaml:5: drones[2].name: must not be empty")


# ------------------------------------------------------------------------------------------ wrong types


def test_string_where_number(fail):
    fail(
        BASE + "flight:\n  height: 0.6\n  speed: fast\n", "m.yaml:7: flight.speed: expected a number, got string 'fast'"
    )


def test_bool_where_number(fail):
    fail(BASE + "flight: {speed: true}\n", "m.yaml:5: flight.speed: expected a number, got boolean true")


def test_yes_is_a_bool_not_a_number(fail):
    fail(BASE + "planner: {eta: yes}\n", "m.yaml:5: planner.eta: expected a number, got boolean yes")


def test_null_where_number(fail):
    fail(BASE + "flight:\n  speed:\n", "m.yaml:6: flight.speed: expected a number, got null")


def test_number_where_list(fail):
    fail(BASE + drone(start="3"), "m.yaml:5: drones[2].start: expected a list of 2 numbers [x, y], got number 3")


def test_list_of_wrong_length(fail):
    fail(
        BASE + drone(goal="[0, 1, 0.5]"),
        "m.yaml:5: drones[2].goal: expected a list of 2 numbers [x, y], got a list of 3 items",
    )


def test_string_inside_a_point(fail):
    fail(BASE + drone(start="[0, one]"), "m.yaml:5: drones[2].start[1]: expected a number, got string 'one'")


def test_mapping_where_list(fail):
    fail(
        BASE + "obstacles: {shape: circle, center: [0, 0], radius: 0.1}\n",
        "m.yaml:5: obstacles: expected a list of obstacles (write [] for none), got a mapping",
    )


def test_null_obstacles(fail):
    fail(BASE + "obstacles:\n", "m.yaml:5: obstacles: expected a list of obstacles", "got null")


def test_list_where_mapping(fail):
    fail(BASE + "flight: [0.6, 0.5]\n", "m.yaml:5: flight: expected a mapping, got a list of 2 items")


def test_string_where_bool(fail):
    fail(
        BASE + "planner: {wall_following: 'no'}\n",
        "m.yaml:5: planner.wall_following: expected true or false, got string 'no'",
    )


def test_float_where_integer(fail):
    fail(
        ARENA + "formation: {kind: circle_swap, count: 2.5, radius: 1}\n",
        "m.yaml:2: formation.count: expected an integer, got number 2.5",
    )


def test_bool_where_integer(fail):
    fail(BASE + "mocap: {data_port: true}\n", "m.yaml:5: mocap.data_port: expected an integer, got boolean true")


def test_number_where_string(fail):
    fail(BASE + "name: 12\n", "m.yaml:5: name: expected a string, got number 12")


def test_yaml_boolean_where_string_suggests_quotes(fail):
    fail(
        BASE + drone(extra=", rigid_body: off"),
        "m.yaml:5: drones[2].rigid_body: expected a string, got boolean off (quote it to make it text: 'off')",
    )


def test_range_of_wrong_type(fail):
    fail(
        "arena: {x: 4, y: [-2, 2]}\n" + BASE[len(ARENA) :],
        "m.yaml:1: arena.x: expected a list of 2 numbers [lo, hi], got number 4",
    )


# ---------------------------------------------------------------------------------------- NaN and inf


def test_nan_speed(fail):
    fail(BASE + "flight: {speed: .nan}\n", "m.yaml:5: flight.speed: expected a finite number, got .nan")


def test_inf_in_a_start(fail):
    fail(BASE + drone(start="[.inf, 0]"), "m.yaml:5: drones[2].start[0]: expected a finite number, got .inf")


def test_negative_inf_in_the_arena(fail):
    fail(
        "arena: {x: [-.inf, 2], y: [-2, 2]}\n" + BASE[len(ARENA) :],
        "m.yaml:1: arena.x[0]: expected a finite number, got -.inf",
    )


def test_huge_exponent_is_inf(fail):
    fail(BASE + "flight: {speed: 1e400}\n", "m.yaml:5: flight.speed: expected a finite number, got 1e400")


def test_quoted_number_is_text(fail):
    fail(BASE + "flight: {speed: '0.5'}\n", "m.yaml:5: flight.speed: expected a number, got string '0.5'")


def test_nan_obstacle_radius(fail):
    fail(
        BASE + "obstacles:\n  - {shape: circle, center: [0, 0], radius: .NaN}\n",
        "m.yaml:6: obstacles[0].radius: expected a finite number, got .NaN",
    )


# ------------------------------------------------------------------------------------------ value ranges


@pytest.mark.parametrize(
    "section, key, value, bound",
    [
        ("flight", "height", "0", "positive"),
        ("flight", "speed", "0", "positive"),
        (
            "flight",
            "rate_hz",
            "-10",
            "at least 7.5 Hz, so the loop watchdog acts before the Crazyflie's "
            "0.5 s setpoint watchdog levels the drones out",
        ),
        (
            "flight",
            "rate_hz",
            "5",
            "at least 7.5 Hz, so the loop watchdog acts before the Crazyflie's "
            "0.5 s setpoint watchdog levels the drones out",
        ),
        ("flight", "goal_tolerance", "0", "positive"),
        ("flight", "takeoff_s", "0", "positive"),
        ("flight", "land_s", "-1", "positive"),
        ("flight", "timeout_s", "0", "positive"),
        ("planner", "sensing_range", "0", "positive"),
        ("planner", "safety_radius", "0", "positive"),
        ("planner", "influence_range", "-1", "positive"),
        ("planner", "wall_threshold", "-0.5", "non-negative"),
        ("planner", "eta", "-0.01", "non-negative"),
        ("planner", "lambda", "-2", "non-negative"),
        ("mocap", "rate_hz", "0", "positive"),
        ("mocap", "timeout_s", "0", "positive"),
        ("mocap", "noise_m", "-0.001", "non-negative"),
        ("mocap", "latency_s", "-1", "non-negative"),
        ("mocap", "dropout", "1", "in [0, 1)"),
        ("radio", "min_battery_v", "0", "positive"),
        ("sim", "time_limit_s", "0", "positive"),
        ("sim", "start_jitter_m", "-0.1", "non-negative"),
        ("sim", "angle_jitter_deg", "-1", "non-negative"),
    ],
)
def test_value_out_of_range(fail, section, key, value, bound):
    fail(BASE + f"{section}:\n  {key}: {value}\n", f"m.yaml:6: {section}.{key}: must be {bound}, got {value}")


def test_obstacle_radius_not_positive(fail):
    fail(
        BASE + "obstacles:\n  - {shape: circle, center: [0, 0], radius: 0}\n",
        "m.yaml:6: obstacles[0].radius: must be positive, got 0",
    )


def test_formation_count_not_positive(fail):
    fail(
        ARENA + "formation: {kind: circle_swap, count: 0, radius: 1}\n",
        "m.yaml:2: formation.count: must be positive, got 0",
    )


def test_formation_count_above_one_address_byte(fail):
    fail(
        "arena: {x: [-200, 200], y: [-200, 200]}\nformation: {kind: circle_swap, count: 256, radius: 100}\n",
        "m.yaml:2: formation.count: must be at most 255, got 256",
    )


def test_formation_radius_not_positive(fail):
    fail(
        ARENA + "formation:\n  kind: circle_swap\n  count: 4\n  radius: -1\n",
        "m.yaml:5: formation.radius: must be positive, got -1",
    )


@pytest.mark.parametrize("port", ["0", "65536"])
def test_port_out_of_range(fail, port):
    fail(BASE + f"mocap: {{command_port: {port}}}\n", "m.yaml:5: mocap.command_port: must be ")


def test_ports_equal(fail):
    fail(BASE + "mocap: {command_port: 1511}\n", "m.yaml:5: mocap.command_port: command_port and data_port must differ")


def test_local_ip_not_an_address(fail):
    fail(BASE + "mocap: {local_ip: my-laptop}\n", "m.yaml:5: mocap.local_ip: expected an IP address, got 'my-laptop'")


def test_multicast_group_not_multicast(fail):
    fail(BASE + "mocap: {multicast_group: 10.0.0.1}\n", "m.yaml:5: mocap.multicast_group: expected a multicast address")


def test_server_with_spaces(fail):
    fail(BASE + "mocap: {server: 'motive pc'}\n", "m.yaml:5: mocap.server: expected a host name or IP address")


# ---------------------------------------------------------------------------------------- inverted ranges


def test_inverted_arena_range(fail):
    fail(
        "arena: {x: [2, -2], y: [-2, 2]}\n" + BASE[len(ARENA) :],
        "m.yaml:1: arena.x: inverted range [2, -2]: expected [lo, hi] with lo < hi",
    )


def test_empty_arena_range(fail):
    fail(
        "arena:\n  x: [-2, 2]\n  y: [-2, 2]\n  z: [1, 1]\n" + BASE[len(ARENA) :],
        "m.yaml:4: arena.z: inverted range [1, 1]",
    )


def test_inverted_box(fail):
    fail(
        BASE + "obstacles:\n  - shape: box\n    min: [1, 0.5]\n    max: [0.5, 1]\n",
        "m.yaml:8: obstacles[0].max: inverted box: min (1, 0.5) must be below max (0.5, 1) in x",
    )


# --------------------------------------------------------------------------------------- unknown keys


def test_unknown_planner_key_suggests_spelling(fail):
    fail(
        BASE + "planner:\n  kind: apf\n  sensing_rang: 5\n",
        "m.yaml:7: planner.sensing_rang: unknown key (did you mean 'sensing_range'?)",
    )


def test_lam_suggests_lambda(fail):
    fail(BASE + "planner: {lam: 2}\n", "m.yaml:5: planner.lam: unknown key (did you mean 'lambda'?)")


def test_unknown_top_level_key(fail):
    fail(BASE + "obstacle: []\n", "m.yaml:5: obstacle: unknown key (did you mean 'obstacles'?)")


def test_unknown_key_without_a_near_spelling_lists_the_keys(fail):
    fail(
        BASE + "radio: {colour: red}\n",
        "m.yaml:5: radio.colour: unknown key; expected one of 'kind', 'min_battery_v', 'extpos'",
    )


def test_unknown_drone_key(fail):
    fail(
        BASE + drone(extra=", rigidbody: cf3"),
        "m.yaml:5: drones[2].rigidbody: unknown key (did you mean 'rigid_body'?)",
    )


def test_unknown_arena_key(fail):
    fail(
        "arena: {x: [-2, 2], y: [-2, 2], zz: [0, 1]}\n" + BASE[len(ARENA) :],
        "m.yaml:1: arena.zz: unknown key (did you mean 'z'?)",
    )


def test_key_of_the_other_obstacle_shape(fail):
    fail(
        BASE + "obstacles:\n  - {shape: circle, center: [0, 0], radius: 0.1, max: [1, 1]}\n",
        "m.yaml:6: obstacles[0].max: unknown key",
    )


def test_unknown_formation_key(fail):
    fail(
        ARENA + "formation: {kind: circle_swap, count: 4, radius: 1, centre: [0, 0]}\n",
        "m.yaml:2: formation.centre: unknown key (did you mean 'center'?)",
    )


# ------------------------------------------------------------------------------------- kinds and enums


def test_unknown_planner_kind(fail):
    fail(
        BASE + "planner: {kind: rfp}\n",
        "m.yaml:5: planner.kind: unknown planner kind 'rfp' (did you mean 'rpf'?); "
        "known: apf, apf-paper, rpf, rpf-mean, ppo",
    )


def test_unknown_planner_kind_case(fail):
    fail(BASE + "planner: {kind: APF}\n", "m.yaml:5: planner.kind: unknown planner kind 'APF' (did you mean 'apf'?)")


@pytest.mark.parametrize(
    "section, key, value, choices",
    [
        ("planner", "preset", "robus", "expected one of 'robust', 'paper', got 'robus' (did you mean 'robust'?)"),
        ("planner", "neighbour_aggregate", "average", "expected one of 'sum', 'mean', got 'average'"),
        ("mocap", "up_axis", "x", "expected one of 'y', 'z', got 'x'"),
        (
            "mocap",
            "kind",
            "vicon",
            "expected one of 'natnet', 'sim', 'motioncapture', got 'vicon' (vicon is a type of the "
            "motioncapture package: kind: motioncapture, type: vicon)",
        ),
        ("mocap", "kind", "vrpm", "expected one of 'natnet', 'sim', 'motioncapture', got 'vrpm'"),
        ("radio", "kind", "crazyradio", "expected one of 'cflib', got 'crazyradio'"),
        ("radio", "extpos", "pose", "expected one of 'extpos', 'extpose', 'packed', got 'pose'"),
    ],
)
def test_unknown_enum_value(fail, section, key, value, choices):
    fail(BASE + f"{section}: {{{key}: {value}}}\n", f"m.yaml:5: {section}.{key}: {choices}")


def test_enum_of_wrong_type(fail):
    fail(BASE + "planner: {preset: 1}\n", "m.yaml:5: planner.preset: expected one of 'robust', 'paper', got number 1")


def test_unknown_obstacle_shape(fail):
    fail(
        BASE + "obstacles:\n  - {shape: sphere, center: [0, 0], radius: 0.1}\n",
        "m.yaml:6: obstacles[0].shape: unknown obstacle shape 'sphere'; known: circle, box",
    )


def test_obstacle_without_shape(fail):
    fail(BASE + "obstacles:\n  - {center: [0, 0], radius: 0.1}\n", "m.yaml:6: obstacles[0].shape: missing required key")


def test_unknown_formation_kind(fail):
    fail(
        ARENA + "formation: {kind: circle-swap, count: 4, radius: 1}\n",
        "m.yaml:2: formation.kind: unknown formation kind 'circle-swap' (did you mean 'circle_swap'?)",
    )


def test_formation_missing_radius(fail):
    fail(ARENA + "formation:\n  kind: circle_swap\n  count: 4\n", "m.yaml:2: formation.radius: missing required key")


def test_formation_bad_uri_base(fail):
    fail(
        ARENA + "formation:\n  kind: circle_swap\n  count: 4\n  radius: 1\n  uri_base: radio://0/80/2M/E7E7E7\n",
        "m.yaml:6: formation.uri_base: 'radio://0/80/2M/E7E7E7' followed by the drone number",
        "must be 10 hex digits",
    )


def test_formation_bad_name_prefix(fail):
    fail(
        ARENA + "formation: {kind: circle_swap, count: 4, radius: 1, name_prefix: '9'}\n",
        "m.yaml:2: formation.name_prefix: name_prefix '9' must start with a letter",
    )


# ------------------------------------------------------------------------------------------- policies


def test_missing_policy_file(fail, workdir):
    (workdir / "missions").mkdir()
    err = fail(
        BASE + "planner:\n  kind: rpf\n  policy: policies/nope.onnx\n",
        "missions/m.yaml:7: planner.policy: policy file 'policies/nope.onnx' not found",
        name="missions/m.yaml",
    )
    assert str(workdir / "missions" / "policies" / "nope.onnx") in err.message
    assert str(workdir / "policies" / "nope.onnx") in err.message


def test_missing_default_policy(fail, workdir, no_shipped_policies):
    err = fail(
        BASE + "planner: {kind: rpf-mean}\n",
        "m.yaml:5: planner.policy: planner kind 'rpf-mean' needs a policy and none is given; "
        "the default 'policies/rpf-mean.onnx' was not found",
    )
    assert str(workdir / "policies" / "rpf-mean.onnx") in err.message


def test_missing_policy_for_a_kind_without_one_is_still_checked(fail):
    fail(
        BASE + "planner: {kind: apf, policy: gains.onnx}\n",
        "m.yaml:5: planner.policy: policy file 'gains.onnx' not found",
    )


def test_policy_of_wrong_type(fail):
    fail(
        BASE + "planner: {kind: rpf, policy: [a.onnx]}\n",
        "m.yaml:5: planner.policy: expected a string, got a list of 1 item",
    )


# ------------------------------------------------------------------------------- layout (second stage)


def test_start_outside_the_arena(fail):
    fail(
        BASE + drone(start="[2.5, 0]"),
        "m.yaml:5: drones[2].start: (2.5, 0) is outside the arena: x 2.5 not in arena.x [-2, 2]",
    )


def test_goal_outside_the_arena_in_y(fail):
    fail(
        BASE + "  - name: cf3\n    uri: radio://0/80/2M/E7E7E7E703\n    start: [0, -1]\n    goal: [0, -2.01]\n",
        "m.yaml:8: drones[2].goal: (0, -2.01) is outside the arena: y -2.01 not in arena.y [-2, 2]",
    )


def test_start_inside_a_circle(fail):
    fail(
        BASE + drone(start="[0, -1]") + "obstacles:\n  - {shape: circle, center: [0.05, -1], radius: 0.2}\n",
        "m.yaml:5: drones[2].start: (0, -1) is inside obstacles[0] (circle at (0.05, -1) radius 0.2)",
    )


def test_start_too_close_to_a_circle(fail):
    fail(
        BASE + drone(start="[0, -1]") + "obstacles:\n  - {shape: circle, center: [0.25, -1], radius: 0.2}\n",
        "m.yaml:5: drones[2].start: (0, -1) is 0.05 m from the surface of obstacles[0] (circle at (0.25, -1) "
        "radius 0.2), less than planner.safety_radius 0.1 m",
    )


def test_goal_inside_a_box(fail):
    fail(
        BASE + drone(goal="[0, 1.5]") + "obstacles:\n  - {shape: box, min: [-0.5, 1.2], max: [0.5, 1.6]}\n",
        "m.yaml:5: drones[2].goal: (0, 1.5) is inside obstacles[0] (box (-0.5, 1.2)-(0.5, 1.6))",
    )


def test_goal_too_close_to_a_box_corner(fail):
    fail(
        BASE + drone(goal="[0, 1.5]") + "obstacles:\n  - {shape: box, min: [0.03, 1.54], max: [0.5, 1.8]}\n",
        "m.yaml:5: drones[2].goal: (0, 1.5) is 0.05 m from the surface of obstacles[0]",
    )


def test_safety_radius_sets_the_obstacle_clearance(load, fail):
    text = BASE + drone(start="[0, -1]") + "obstacles:\n  - {shape: circle, center: [0.35, -1], radius: 0.2}\n"
    load(text)  # 0.15 m clear, more than the default 0.1 m
    fail(text + "planner: {safety_radius: 0.2}\n", "m.yaml:5: drones[2].start: (0, -1) is 0.15 m from the surface")


def test_start_equals_goal(fail):
    fail(
        BASE + drone(start="[0, -1]", goal="[0.05, -1]"),
        "m.yaml:5: drones[2].start: start (0, -1) and goal (0.05, -1) are 0.05 m apart, "
        "less than flight.goal_tolerance 0.1 m",
    )


def test_starts_too_close(fail):
    fail(
        BASE + drone(start="[-1.4, 0.05]"),
        "m.yaml:5: drones[2].start: start (-1.4, 0.05) is 0.111803 m from the start of drones[0] (cf1), "
        "less than 2 x planner.safety_radius = 0.2 m",
    )


def test_goals_too_close(fail):
    fail(
        BASE + drone(goal="[-1.5, 0.7]"),
        "m.yaml:5: drones[2].goal: goal (-1.5, 0.7) is 0.3 m from the goal of drones[1] (cf2), "
        "less than 4 x planner.safety_radius = 0.4 m",
        "held as an obstacle of radius 0.1 m",
    )


def test_spacing_exactly_at_the_limit_is_fine(load):
    assert len(load(BASE + drone(start="[-1.5, -0.2]", goal="[-1.5, 0.6]")).drones) == 3


def test_flight_height_above_the_arena(fail):
    fail(BASE + "flight:\n  height: 1.6\n", "m.yaml:6: flight.height: 1.6 is outside arena.z [0, 1.5]")


def test_default_flight_height_outside_the_arena_points_at_arena_z(fail):
    fail(
        "arena:\n  x: [-2, 2]\n  y: [-2, 2]\n  z: [0, 0.5]\n" + BASE[len(ARENA) :],
        "m.yaml:4: flight.height: 0.6 is outside arena.z [0, 0.5]",
    )


# ------------------------------------------------------------------ plausible ranges: what the firmware and arena allow


def test_speed_in_cm_s_names_the_firmware_limit_and_the_slip(fail):
    fail(
        BASE + "flight:\n  speed: 40\n",
        "m.yaml:6: flight.speed: 40 m/s: above the firmware's 1 m/s velocity "
        "limit (posCtlPid.xVelMax); speeds are in m/s (40 cm/s is 0.4 m/s)",
    )


def test_speed_just_above_the_firmware_limit(fail, load):
    fail(
        BASE + "flight: {speed: 1.5}\n",
        "m.yaml:5: flight.speed: 1.5 m/s: above the firmware's 1 m/s velocity "
        "limit (posCtlPid.xVelMax); speeds are in m/s",
    )
    assert load(BASE + "flight: {speed: 1.0}\n").flight.speed == 1.0


def test_height_in_cm_says_so(fail):
    fail(
        BASE + "flight:\n  height: 60\n",
        "m.yaml:6: flight.height: 60 is outside arena.z [0, 1.5]; heights are in m (60 cm is 0.6 m)",
    )
    fail(
        BASE + "flight:\n  height: 600\n",
        "m.yaml:6: flight.height: 600 is outside arena.z [0, 1.5]; heights are in m (600 mm is 0.6 m)",
    )


@pytest.mark.parametrize(
    "section, key, value, message",
    [
        (
            "planner",
            "safety_radius",
            "10",
            "10 m: above 1 m, implausible for a drone's radius (the default is 0.1 m; a "
            "Crazyflie 2.x is 92 mm across); lengths are in m (10 cm is 0.1 m)",
        ),
        (
            "planner",
            "margin",
            "5",
            "5 m: above 1 m, implausible for a clearance beyond contact (the default is 0.05 m; a "
            "Crazyflie 2.x is 92 mm across); lengths are in m (5 cm is 0.05 m)",
        ),
        (
            "planner",
            "capture_radius",
            "30",
            "30 m: above 1 m, implausible for the capture radius (the default is 0.3 m; a "
            "Crazyflie 2.x is 92 mm across); lengths are in m (30 cm is 0.3 m)",
        ),
        (
            "flight",
            "goal_tolerance",
            "10",
            "10 m: above 1 m, implausible for a goal tolerance (the default is 0.1 m; a "
            "Crazyflie 2.x is 92 mm across); lengths are in m (10 cm is 0.1 m)",
        ),
        (
            "flight",
            "rate_hz",
            "200",
            "200 Hz: above the firmware's 100 Hz position loop (POSITION_RATE), which never "
            "acts on a faster stream; rates are in Hz",
        ),
        (
            "flight",
            "rate_hz",
            "0.1",
            "must be at least 7.5 Hz, so the loop watchdog acts before the Crazyflie's 0.5 s "
            "setpoint watchdog levels the drones out, got 0.1 (a period of 0.1 s is 10 Hz)",
        ),
        (
            "mocap",
            "rate_hz",
            "5000",
            "5000 Hz: above the Crazyflie's 1000 Hz main loop (RATE_MAIN_LOOP), which could use "
            "no faster poses; rates are in Hz",
        ),
    ],
)
def test_implausible_values_one_line_each(fail, section, key, value, message):
    fail(BASE + f"{section}:\n  {key}: {value}\n", f"m.yaml:6: {section}.{key}: {message}")


def test_mocap_slower_than_the_pose_timeout(fail):
    fail(
        BASE + "mocap:\n  rate_hz: 2\n",
        "m.yaml:6: mocap.rate_hz: 2 Hz: a pose every 0.5 s, not within safety.pose_timeout_s (0.25 s), so every "
        "drone would hold between frames; rates are in Hz",
    )
    fail(BASE + "mocap:\n  rate_hz: 0.01\n", "m.yaml:6: mocap.rate_hz: 0.01 Hz: ", "(a period of 0.01 s is 100 Hz)")
    fail(
        BASE + "safety:\n  pose_timeout_s: 0.005\n",
        "m.yaml:6: mocap.rate_hz: 100 Hz: a pose every 0.01 s, not within safety.pose_timeout_s (0.005 s)",
    )


def test_obstacle_wider_than_the_arena(fail):
    fail(
        BASE + "obstacles:\n  - {shape: circle, center: [0, -1], radius: 10}\n",
        "m.yaml:6: obstacles[0].radius: 10 m: a circle 20 m across, wider than the arena (arena.x [-2, 2], "
        "arena.y [-2, 2]); lengths are in m (10 cm is 0.1 m)",
    )


def test_formation_radius_in_cm(fail):
    fail(
        "arena: {x: [-3, 3], y: [-3, 3]}\nformation:\n  kind: circle_swap\n  count: 8\n  radius: 200\n",
        "m.yaml:5: formation.radius: 200 m: the circle around (0, 0) leaves the arena (arena.x [-3, 3], "
        "arena.y [-3, 3]); lengths are in m (200 cm is 2 m)",
    )


def test_the_shipped_missions_are_plausible():
    from pathlib import Path

    from rpf_fly.mission import load_mission

    missions = sorted((Path(__file__).resolve().parents[2] / "missions").rglob("*.yaml"))
    assert len(missions) >= 10
    for path in missions:
        load_mission(path)


def test_formation_errors_point_at_the_formation(fail):
    fail(
        "# an 8 m circle does not fit a 6 m arena\narena: {x: [-3, 3], y: [-3, 3]}\n"
        "formation:\n  kind: circle_swap\n  count: 8\n  radius: 4\n",
        "m.yaml:3: formation: drones[0].start (cf1): (4, 0) is outside the arena: x 4 not in arena.x [-3, 3]",
    )


def test_crowded_formation(fail):
    fail(
        "arena: {x: [-3, 3], y: [-3, 3]}\nformation: {kind: circle_swap, count: 100, radius: 2}\n",
        "m.yaml:2: formation: drones[1].start (cf2): start",
        "less than 2 x planner.safety_radius",
    )


def test_formation_start_inside_an_obstacle(fail):
    fail(
        "arena: {x: [-3, 3], y: [-3, 3]}\nobstacles: [{shape: box, min: [-0.2, 0.9], max: [0.2, 1.1]}]\n"
        "formation: {kind: circle_swap, count: 4, radius: 1}\n",
        "m.yaml:3: formation: drones[1].start (cf2): (6.12323e-17, 1) is inside obstacles[0]",
    )


def test_guidance_choice(fail):
    fail(
        BASE + "planner: {guidance: astar}\n", "m.yaml:5: planner.guidance: expected one of 'none', 'path', got 'astar'"
    )


def test_margin_not_negative(fail):
    fail(BASE + "planner: {margin: -0.1}\n", "m.yaml:5: planner.margin: must be non-negative, got -0.1")


def test_field_line_finds_a_field_written_in_block_or_flow_style_or_its_parent(tmp_path):
    """Where a problem found after loading (a mocap.server that does not resolve) is reported: the field's line."""
    from rpf_fly.mission import field_line

    path = tmp_path / "m.yaml"
    path.write_text("name: x\nmocap:\n  kind: natnet\n\n  server: lab-pc\n")
    assert field_line(path, "mocap.server") == 5
    path.write_text("name: x\nmocap: {kind: natnet}\n")
    assert field_line(path, "mocap.server") == 2  # the default: the section that leaves it out
    assert field_line(path, "radio.kind") == 0
    path.write_text("mocap: [\n")
    assert field_line(path, "mocap.server") == 0  # no longer YAML
    assert field_line(tmp_path / "gone.yaml", "mocap.server") == 0


# ------------------------------------------------------------------------------------ dry_run


def test_dry_run_settings_are_read_and_default_to_the_emulators(load):
    mission = load(BASE + "dry_run: {seed: 7, mocap_noise_m: 0.001, mocap_dropout: 0.01}\n")
    assert (mission.dry_run.seed, mission.dry_run.mocap_noise_m, mission.dry_run.mocap_dropout) == (7, 0.001, 0.01)
    assert mission.dry_run.mocap_noise_deg is None
    assert load(BASE).dry_run.seed == 0 and load(BASE).dry_run.mocap_noise_m is None


def test_dry_run_bad_values(fail):
    fail(BASE + "dry_run: {mocap_dropout: 1.5}\n", "m.yaml:5: dry_run.mocap_dropout: must be in [0, 1), got 1.5")
    fail(BASE + "dry_run: {seed: -1}\n", "m.yaml:5: dry_run.seed: must be at least 0, got -1")
    fail(BASE + "dry_run: {seed: 1.5}\n", "m.yaml:5: dry_run.seed: expected an integer")
    fail(BASE + "dry_run: {noise: 1}\n", "m.yaml:5: dry_run.noise: unknown key")


# ------------------------------------------------------------------------------------ safety.blind_drift_m_s2


def test_blind_drift_is_read_and_defaults_to_the_supervisors_assumption(load):
    assert load(BASE + "safety: {blind_drift_m_s2: 0.25}\n").safety.blind_drift_m_s2 == 0.25
    assert load(BASE).safety.blind_drift_m_s2 == BLIND_DRIFT_M_S2 == 0.45


def test_blind_drift_must_be_positive(fail):
    fail(BASE + "safety: {blind_drift_m_s2: 0}\n", "m.yaml:5: safety.blind_drift_m_s2: must be positive, got 0")
