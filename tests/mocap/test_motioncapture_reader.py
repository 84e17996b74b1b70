"""An independent reader of our NatNet emulator: libmotioncapture 1.1's own OptiTrack decoder (C++, written apart
from ours) against our NatNet client, on the same multicast frames over 127.0.0.1, value for value.

Each frame the emulator sends is read by both; their rigid bodies must agree exactly (float32 values, compared
after both applied the same up-axis conversion), names included (the library maps ids to names by its own MODELDEF
parse). The library's Python API reports no ids, frame numbers or timestamps: ids are checked through the names
(every body has its own pose, so a wrong id->name map shows as a mismatch), frame numbers through the one-to-one
match (the emulator's frame k is our client's frame k and the library's k-th frame, none lost, none doubled).

Bitstream 4.2: the library does not read the rotation-offset quaternion 4.2 added to rigid-body descriptions, so
its MODELDEF parse runs off the data: with two or more rigid bodies it segfaults while connecting. That runs in the
source's child process, so this test process survives to assert it (docs/mocap.md, "An independent reader").
"""

from __future__ import annotations

import random
import struct
import time

import pytest

from rpf_fly.emulator.natnet_server import NatNetServer
from rpf_fly.mocap.motioncapture_source import MotioncaptureSource, MotioncaptureUnavailable
from rpf_fly.mocap.natnet_client import NatNetClient

NAMES = ("cf1", "cf2", "rb_three", "Drone 4")
AGREEING = ("3.0", "4.0", "4.1")


def f32(value: float) -> float:
    return struct.unpack("<f", struct.pack("<f", value))[0]


def random_poses(rng: random.Random, names) -> dict:
    """Each body its own pose (no two alike), some untracked; quaternions unit but arbitrary."""
    poses = {}
    for name in names:
        q = [rng.uniform(-1.0, 1.0) for _ in range(4)]
        norm = sum(v * v for v in q) ** 0.5
        position = tuple(rng.uniform(-3.0, 3.0) for _ in range(3))
        poses[name] = (position, tuple(v / norm for v in q), rng.random() > 0.2)
    return poses


def read_both(version: str, up_axis: str, names=NAMES, frames: int = 25, seed: int = 1):
    """Send ``frames`` frames; yield (number, our client's frame, the library's frame, what was streamed)."""
    rng = random.Random(seed)
    current = {"poses": random_poses(rng, names)}
    with NatNetServer(
        lambda: current["poses"],
        version=version,
        multicast=True,
        local_ip="127.0.0.1",
        rate_hz=0,
        up_axis=up_axis,
        bodies=list(names),
    ) as server:
        with (
            NatNetClient(
                "127.0.0.1",
                multicast=True,
                local_ip="127.0.0.1",
                command_port=server.command_port,
                data_port=None,
                up_axis=up_axis,
            ) as ours,
            MotioncaptureSource(
                "optitrack", "127.0.0.1", {"port_command": server.command_port}, up_axis=up_axis, bodies=list(names)
            ) as library,
        ):
            assert ours.wait_for_server(5.0)
            ids = server.body_ids
            assert ours.rigid_body_names == {i: n for n, i in ids.items()}
            for k in range(1, frames + 1):
                current["poses"] = random_poses(rng, names)
                number = server.send_frame()
                ours_frame = ours.receive(3.0)
                library_frame = library.receive(3.0)
                assert ours_frame is not None and library_frame is not None, f"frame {k} not read by both"
                yield k, number, ids, ours_frame, library_frame, current["poses"]
            assert library.receive(0.2) is None and ours.receive(0.2) is None  # nothing extra, nothing doubled


def assert_agree(version: str, up_axis: str, names=NAMES) -> None:
    compared = 0
    for k, number, ids, ours, library, streamed in read_both(version, up_axis, names):
        assert number == k and ours.frame_number == k and library.frame_number == k
        assert sorted(ours.bodies) == sorted(library.bodies) == sorted(names)
        for name in names:
            a, b = ours.bodies[name], library.bodies[name]
            assert a.id == ids[name] and b.id == -1  # the library reports no ids
            assert a.valid == b.valid == streamed[name][2], (k, name)
            if a.valid:
                # value for value: both read the same float32 bits and converted them the same way
                assert a.position == b.position, (k, name, a.position, b.position)
                assert a.quaternion == b.quaternion, (k, name, a.quaternion, b.quaternion)
                assert all(v == f32(v) for v in (*b.position, *b.quaternion))
                compared += 1
    assert compared > 0.5 * 25 * len(names)  # about 80 % of the bodies were tracked, so most were compared


@pytest.mark.parametrize("version", AGREEING)
def test_the_library_reads_what_our_client_reads(version):
    assert_agree(version, "y")


def test_the_library_reads_what_our_client_reads_z_up():
    assert_agree("4.1", "z")


def test_bitstream_4_2_with_one_rigid_body_reads_alike():
    """With one rigid body the library's misread of the 4.2 description ends with the MODELDEF: no harm."""
    assert_agree("4.2", "y", names=("cf1",))


def test_bitstream_4_2_with_two_rigid_bodies_crashes_the_library_in_its_child_not_here():
    poses = {name: ((0.1, 0.2, 0.3), (0.0, 0.0, 0.0, 1.0), True) for name in ("cf1", "cf2")}
    with NatNetServer(lambda: poses, version="4.2", multicast=True, rate_hz=50) as server:
        with NatNetClient(
            "127.0.0.1", multicast=True, local_ip="127.0.0.1", command_port=server.command_port, data_port=None
        ) as ours:
            assert ours.wait_for_server(5.0)  # our client reads the stream
            frame = ours.receive(2.0)
            assert frame is not None and sorted(frame.bodies) == ["cf1", "cf2"]
        with pytest.raises(MotioncaptureUnavailable) as info:
            MotioncaptureSource("optitrack", "127.0.0.1", {"port_command": server.command_port})
    assert "the library's process died while connecting (killed by SIGSEGV)" in str(info.value)


def test_a_body_added_after_connect_is_named_by_our_client_only():
    """Where the readers differ by design: the library reads MODELDEF once, at connect, and ignores the
    models-changed bit; a body added later reaches it without a name, and the source leaves it out (no drone can
    fly on it). Our client asks for the definitions again and names it."""
    poses = {name: ((0.1 * i, 0.2, 0.3), (0.0, 0.0, 0.0, 1.0), True) for i, name in enumerate(("cf1", "cf2"))}
    with NatNetServer(lambda: poses, version="4.1", multicast=True, rate_hz=0, bodies=["cf1"]) as server:
        with (
            NatNetClient(
                "127.0.0.1", multicast=True, local_ip="127.0.0.1", command_port=server.command_port, data_port=None
            ) as ours,
            MotioncaptureSource("optitrack", "127.0.0.1", {"port_command": server.command_port}) as library,
        ):
            assert ours.wait_for_server(5.0)
            server.set_bodies(["cf1", "cf2"])
            for _ in range(5):
                server.send_frame()
                ours_frame, library_frame = ours.receive(2.0), library.receive(2.0)
                time.sleep(0.05)  # our client's MODELDEF request is answered meanwhile
            assert ours_frame is not None and library_frame is not None
            assert sorted(ours_frame.bodies) == ["cf1", "cf2"]
            assert sorted(library_frame.bodies) == ["cf1"] and library.unnamed_bodies == 5
