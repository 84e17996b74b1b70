"""Sample NatNet content with every section populated, shared by the protocol and fuzz tests."""

from __future__ import annotations

from rpf_fly.mocap.natnet_protocol import (
    AnalogData,
    AssetData,
    FrameOfData,
    LabeledMarker,
    MarkerSetData,
    MarkerSetDescription,
    ModelDefinitions,
    OtherDescription,
    RigidBodyData,
    RigidBodyDescription,
    RigidBodyMarker,
    ServerInfo,
    SkeletonData,
    SkeletonDescription,
    Version,
)

VERSIONS: tuple[Version, ...] = ((3, 0), (4, 0), (4, 1), (4, 2))

# float32-exact values so that encode -> decode compares with ==
_Q = (0.5, -0.5, 0.5, 0.5)


def rigid_body(body_id: int, valid: bool = True) -> RigidBodyData:
    return RigidBodyData(body_id, 0.25 * body_id, 1.5, -0.75, *_Q, 0.000244140625, int(valid))


def labeled(model: int, marker: int) -> LabeledMarker:
    return LabeledMarker((model << 16) | marker, 0.125, 1.0, -2.5, 0.015625, 0x0A, 0.0009765625)


def rich_frame(version: Version, frame_number: int = 1000) -> FrameOfData:
    """A frame using every section the version has (assets and precision stamps only from 4.1)."""
    new = version >= (4, 1)
    return FrameOfData(
        frame_number=frame_number,
        marker_sets=[
            MarkerSetData("cf1", [(0.5, 0.25, 1.0), (0.75, 0.25, 1.0)]),
            MarkerSetData("all", [(1.0, 2.0, 3.0)]),
        ],
        other_markers=[(0.5, 0.5, 0.5), (-1.0, 0.0, 2.0)],
        rigid_bodies=[rigid_body(1), rigid_body(2, valid=False), rigid_body(7)],
        skeletons=[SkeletonData(3, [rigid_body(31), rigid_body(32)]), SkeletonData(4, [])],
        assets=[AssetData(9, [rigid_body(91)], [labeled(9, 1), labeled(9, 2)])] if new else [],
        labeled_markers=[labeled(1, 1), labeled(1, 2), labeled(0, 50007)],
        force_plates=[AnalogData(1, [[1.0, 2.0], [3.0]]), AnalogData(2, [])],
        devices=[AnalogData(5, [[0.5, 0.25, 0.125]])],
        timecode=(1 << 24) | (2 << 16) | (3 << 8) | 4,
        timecode_subframe=5,
        timestamp=1356.125,
        camera_mid_exposure=1416497730518,
        camera_data_received=1416497745808,
        transmit=1416497748722,
        precision_seconds=1700000000 if new else 0,
        precision_fraction=123456789 if new else 0,
        params=0x03,
    )


def rb_description(name: str, body_id: int, version: Version, n_markers: int = 3) -> RigidBodyDescription:
    return RigidBodyDescription(
        name,
        body_id,
        -1,
        (0.0, 0.125, 0.0),
        (0.0, 0.0, 0.5, 0.5) if version >= (4, 2) else (0.0, 0.0, 0.0, 1.0),
        tuple(
            RigidBodyMarker((0.03125 * k, -0.0625, 0.0), k, f"Marker{k + 1}" if version >= (4, 0) else "")
            for k in range(n_markers)
        ),
    )


def rich_model(version: Version) -> ModelDefinitions:
    """Marker sets, rigid bodies, a skeleton and (4.1+, skippable by size) a camera and an asset."""
    others = (
        (OtherDescription(5, b"Cam1\0" + bytes(28)), OtherDescription(6, b"opaque asset bytes"))
        if version >= (4, 1)
        else ()
    )
    return ModelDefinitions(
        marker_sets=(MarkerSetDescription("cf1", ("Marker1", "Marker2", "Marker3")), MarkerSetDescription("all", ())),
        rigid_bodies=(rb_description("cf1", 1, version), rb_description("cf2", 2, version, 0)),
        skeletons=(SkeletonDescription("walker", 3, (rb_description("hip", 31, version, 1),)),),
        others=others,
    )


def server_info(version: Version, data_port: int = 1511) -> ServerInfo:
    natnet = (version[0], version[1], 0, 0)
    return ServerInfo("Motive", (3, 1, 0, 0), natnet, 10_000_000, data_port, True, "239.255.42.99")
