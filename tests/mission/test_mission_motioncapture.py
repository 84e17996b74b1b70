"""`mocap: {kind: motioncapture, ...}`: the library's type, host and options are checked against libmotioncapture
1.1's own table (the library itself ignores unknown keys and misreads values), one line `FILE:LINE: FIELD: problem`."""

from __future__ import annotations

import pytest

from rpf_fly.mocap.motioncapture_options import TYPES, WHEEL_TYPES, parse_rigid_bodies

BASE = """\
arena: {x: [-2, 2], y: [-2, 2], z: [0, 1.5]}
drones:
  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [-1.5, 0], goal: [1.5, 0]}
"""


def test_a_mock_with_options_loads_as_the_library_text(load):
    mission = load(
        BASE + "mocap:\n  kind: motioncapture\n  type: mock\n  up_axis: y\n"
        "  options: {rigid_bodies: 'cf1(0,0,0,1,0,0,0)', frequency: 50}\n"
    )
    m = mission.mocap
    assert (m.kind, m.system, m.hostname, m.up_axis) == ("motioncapture", "mock", None, "y")
    assert m.options == (("rigid_bodies", "cf1(0,0,0,1,0,0,0)"), ("frequency", "50"))


def test_vicon_and_optitrack_options_become_the_strings_connect_reads(load):
    vicon = load(
        BASE + "mocap: {kind: motioncapture, type: vicon, hostname: 'vicon.lab:801', "
        "options: {enable_objects: true, enable_pointclout: false}}\n"
    ).mocap
    assert vicon.hostname == "vicon.lab:801"
    assert vicon.options == (("enable_objects", "true"), ("enable_pointclout", "false"))
    opti = load(
        BASE + "mocap: {kind: motioncapture, type: optitrack, hostname: 10.0.0.10, "
        "options: {interface_ip: 10.0.0.2, port_command: 1510}}\n"
    ).mocap
    assert opti.options == (("interface_ip", "10.0.0.2"), ("port_command", "1510"))


@pytest.mark.parametrize(
    "mocap, message",
    [
        (
            "{kind: motioncapture}",
            "m.yaml:4: mocap.type: missing required key: kind 'motioncapture' needs the system's type, one of mock,",
        ),
        (
            "{kind: motioncapture, type: optitrack_closed}",
            "m.yaml:4: mocap.type: unknown motioncapture type 'optitrack_closed' "
            "(did you mean 'optitrack_closed_source'?)",
        ),
        (
            "{kind: motioncapture, type: mock, hostname: lab}",
            "m.yaml:4: mocap.hostname: type 'mock' has no host (it needs no hardware); remove hostname",
        ),
        (
            "{kind: motioncapture, type: vicon, hostname: 'vicon:99999'}",
            "m.yaml:4: mocap.hostname: expected host or host:port (port 1-65535), got 'vicon:99999'",
        ),
        (
            "{kind: motioncapture, type: optitrack, hostname: 192.168.1.1000}",
            "m.yaml:4: mocap.hostname: expected a host name or IP address, got '192.168.1.1000'",
        ),
        (
            "{kind: motioncapture, type: vicon, options: {enable_pointcloud: true}}",
            "m.yaml:4: mocap.options.enable_pointcloud: unknown option 'enable_pointcloud' "
            "of type 'vicon' (did you mean "
            "'enable_pointclout'?); vicon takes enable_objects, enable_pointclout",
        ),
        (
            "{kind: motioncapture, type: vicon, options: {enable_objects: 'on'}}",
            "m.yaml:4: mocap.options.enable_objects: expected true or false, got 'on'",
        ),
        (
            "{kind: motioncapture, type: optitrack, options: {port_command: 15x}}",
            "m.yaml:4: mocap.options.port_command: expected an integer, got '15x'",
        ),
        (
            "{kind: motioncapture, type: optitrack, options: {interface_ip: eth0}}",
            "m.yaml:4: mocap.options.interface_ip: expected an IPv4 address, got 'eth0'",
        ),
        (
            "{kind: motioncapture, type: optitrack, options: {hostname: 10.0.0.1}}",
            "m.yaml:4: mocap.options.hostname: give the host as mocap.hostname (or --host), not as an option",
        ),
        (
            "{kind: motioncapture, type: vrpn, options: {port: 3883}}",
            "m.yaml:4: mocap.options.port: unknown option 'port' of type 'vrpn'; vrpn takes no options",
        ),
        (
            "{kind: motioncapture, type: mock, options: {frequency: 0}}",
            "m.yaml:4: mocap.options.frequency: must be 1-1000, got 0",
        ),
        (
            "{kind: motioncapture, type: mock, options: [frequency]}",
            "m.yaml:4: mocap.options: expected a mapping of mock options, got a list of 1 item",
        ),
        (
            "{kind: natnet, type: vicon}",
            "m.yaml:4: mocap.type: only for kind 'motioncapture' (this mocap is kind 'natnet')",
        ),
    ],
)
def test_what_the_library_would_misread_is_refused_in_one_line(fail, mocap, message):
    fail(BASE + f"mocap: {mocap}\n", message)


@pytest.mark.parametrize(
    "text, problem",
    [
        ("cf1(0,0,0,1,0,0,0);cf2(0,0,0)", "expected bodies name(x,y,z,qw,qx,qy,qz) joined by ';', got 'cf2(0,0,0)'"),
        ("cf1(0,0,0,1,0,0,0); cf2(0,0,0,1,0,0,0)", "body name ' cf2' has surrounding spaces (the library keeps them)"),
        ("x" * 100 + "(0,0,0,1,0,0,0)", "body name of 100 characters: the library takes at most 99"),
        ("cf1(0,0,0,1,0,0,0);cf1(1,0,0,1,0,0,0)", "duplicate body 'cf1'"),
        ("cf1(0,0,0,0.5,0,0,0)", "body 'cf1': quaternion (qw,qx,qy,qz) has norm 0.5, expected a unit one"),
        ("cf1(nan,0,0,1,0,0,0)", "expected bodies name(x,y,z,qw,qx,qy,qz) joined by ';', got 'cf1(nan,0,0,1,0,0,0)'"),
    ],
)
def test_mock_bodies_the_library_would_drop_or_overflow_on_are_refused(text, problem):
    """The library's sscanf loop stops at the first bad entry and keeps the others; a name of 100+ characters
    overflows its stack buffer."""
    with pytest.raises(ValueError) as info:
        parse_rigid_bodies(text)
    assert str(info.value) == problem


def test_mock_bodies_reorder_the_quaternion_to_xyzw():
    (body,) = parse_rigid_bodies("cf1(1, 2, 0.5, 0.7071068, 0, 0, 0.7071068);")
    assert body.name == "cf1" and body.position == (1.0, 2.0, 0.5)
    assert body.quaternion == (0.0, 0.0, 0.7071068, 0.7071068)


def test_the_wheel_types_are_a_subset_of_the_table():
    assert set(WHEEL_TYPES) == {"mock", "optitrack", "qualisys", "vicon", "vrpn"} < set(TYPES)
