"""The mocap relay's pieces (rpf_fly/runtime/frames.py, relayed_mocap.py, relay.py): the signed frame format, the
worker's source over real Zenoh sessions on 127.0.0.1, and ``runtime.mocap_relay`` (when a flight has a relay).
The relay process in a flight: tests/runtime/test_distributed_flight.py."""

from __future__ import annotations

import json
import threading
import time

import orjson
import pytest

from rpf_fly.mission import MissionError, parse_mission
from rpf_fly.mission.model import ZenohSettings
from rpf_fly.mocap.frame import MocapFrame, MocapSource, RigidBodyPose
from rpf_fly.runtime.auth import mac, new_secret
from rpf_fly.runtime.frames import FrameSigner, FrameVerifier
from rpf_fly.runtime.relay import uses_relay
from rpf_fly.runtime.relayed_mocap import RelayedMocap
from rpf_fly.runtime.session import free_loopback_endpoint, open_session

MISSION = (
    "name: relay\narena: {x: [-2, 2], y: [-2, 2]}\n"
    "drones:\n  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [0, 0], goal: [1, 0]}\n"
)


def frame(number: int, x: float = 0.5, valid: bool = True) -> MocapFrame:
    return MocapFrame(
        number,
        number / 100,
        time.monotonic(),
        0.004,
        {
            "cf1": RigidBodyPose("cf1", 1, (x, -0.25, 0.5), (0.0, 0.0, 0.3826834, 0.9238795), valid, 0.0002),
            "cf2": RigidBodyPose("cf2", 2, (1.0, 1.0, 0.0), (0.0, 0.0, 0.0, 1.0), False),
        },
    )


def test_a_signed_frame_round_trips_with_every_field_and_is_taken_once():
    secret = new_secret()
    signer, verifier = FrameSigner(secret, "f1"), FrameVerifier(secret, "f1")
    sent = frame(7)
    payload, signature = signer.sign(sent)
    body = orjson.loads(payload)
    assert body["seq"] == 1 and body["flight"] == "f1" and body["relay_publish_ns"] >= body["relay_receive_ns"] > 0
    verdict = verifier.verify(payload, signature, 123.0)
    got = verdict.frame
    assert got is not None and verdict.why == "" and verdict.relay_receive_ns == body["relay_receive_ns"]
    assert (got.frame_number, got.capture_time_s, got.latency_s, got.receive_time_s) == (7, 0.07, 0.004, 123.0)
    assert got.bodies == sent.bodies  # names, ids, poses, validity, marker error: exactly
    again = verifier.verify(payload, signature, 124.0)
    assert again.frame is None and "replayed" in again.why and not again.malformed


@pytest.mark.parametrize(
    "case",
    [
        "unsigned",
        "other secret",
        "other flight",
        "tampered",
        "older",
        "not json",
        "no bodies",
        "text position",
        "short quaternion",
        "bool id",
    ],
)
def test_frames_that_are_not_the_relays_are_refused(case):
    secret = new_secret()
    verifier = FrameVerifier(secret, "f1")
    signer = FrameSigner(secret if case != "other secret" else new_secret(), "f1" if case != "other flight" else "f2")
    signer.seq = 10
    payload, signature = signer.sign(frame(1))
    body = orjson.loads(payload)
    if case == "older":
        verifier.last_seq = 11
    edits = {
        "no bodies": lambda b: b.pop("bodies"),
        "text position": lambda b: b["bodies"][0].update(position=["a", 0, 0]),
        "short quaternion": lambda b: b["bodies"][0].update(quaternion=[0, 0, 1]),
        "bool id": lambda b: b["bodies"][0].update(id=True),
    }
    if case in edits:
        edits[case](body)
        payload = json.dumps(body).encode()
    if case == "not json":
        payload = b"\xff{"
    if case in edits or case == "not json":
        signature = mac(secret.encode(), payload)  # signed with the flight's secret, yet not a frame
    if case == "tampered":
        payload = payload.replace(b'"cf1"', b'"cf9"')
    if case == "unsigned":
        signature = None
    verdict = verifier.verify(payload, signature, 0.0)
    assert verdict.frame is None and verdict.why, case
    assert verdict.malformed == (case in edits or case == "not json"), (case, verdict.why)


def test_the_workers_source_hands_over_the_newest_verified_frame_and_counts_the_rest():
    """Over a router and two client sessions: frames signed with the flight's secret come out of ``receive`` (the
    newest; older ones superseded), stamped with this process's receipt time; forged ones are dropped, counted
    and reported once (rate-limited); ``close`` ends a waiting ``receive``."""
    endpoint = free_loopback_endpoint()
    router = open_session(ZenohSettings(), listen=[endpoint], mode="router")
    worker = open_session(ZenohSettings(), connect=[endpoint])
    relay = open_session(ZenohSettings(), connect=[endpoint])
    secret, key = new_secret(), "rpf_fly/f1/mocap_frames"
    warnings: list[str] = []
    source = RelayedMocap(worker, key, secret, "f1", warn=warnings.append)
    try:
        assert isinstance(source, MocapSource)
        signer = FrameSigner(secret, "f1")
        before = time.monotonic()
        for _ in range(50):  # until the subscription is routed: the first frame that arrives
            payload, signature = signer.sign(frame(1))
            relay.put(key, payload, attachment=signature)
            if source.wait_first(0.1):
                break
        first = source.receive(1.0)
        assert first is not None and first.frame_number == 1 and before <= first.receive_time_s <= time.monotonic()
        for number in (2, 3, 4):
            payload, signature = signer.sign(frame(number, x=0.5 + number))
            relay.put(key, payload, attachment=signature)
        forged, _ = FrameSigner(new_secret(), "f1").sign(frame(99, x=40.0))
        relay.put(key, forged)
        relay.put(key, forged, attachment=b"0" * 64)
        # one session's puts arrive in order: once both forged frames are counted, frames 2-4 are in
        assert _until(lambda: source.stats.dropped == 2)
        newest = source.receive(1.0)
        assert newest is not None and newest.frame_number == 4 and newest.bodies["cf1"].position[0] == 4.5
        stats = source.stats
        assert stats.superseded >= 2 and stats.dropped == 2 and stats.malformed == 0
        assert stats.packets == stats.frames + stats.dropped and stats.body_dropouts == 2  # cf2 untracked, twice
        assert len(warnings) == 1 and "unsigned mocap frame" in warnings[0], warnings
        assert source.transit and all(before <= at and 0 <= t < 1.0 for at, t in source.transit)
        assert source.receive(0.05) is None  # nothing new
        waiting = threading.Thread(target=lambda: source.receive(30.0))
        waiting.start()
        source.close()
        waiting.join(2.0)
        assert not waiting.is_alive()
    finally:
        source.close()
        for session in (relay, worker, router):
            session.close()


def _until(predicate, timeout_s: float = 5.0) -> bool:  # noqa: ANN001
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.01)
    return False


@pytest.mark.parametrize(
    "mocap, setting, relayed",
    [
        ("{kind: natnet, multicast: false}", None, True),
        ("{kind: natnet, multicast: true}", None, False),
        ("{kind: natnet}", None, False),  # multicast by default
        ("{kind: motioncapture, type: vicon, hostname: 10.0.0.2}", None, True),
        ("{kind: sim}", None, False),
        ("{kind: natnet, multicast: true}", "on", True),
        ("{kind: natnet, multicast: false}", "off", False),
        ("{kind: natnet, multicast: false}", "auto", True),
    ],
)
def test_runtime_mocap_relay_says_when_the_flight_has_a_relay(mocap, setting, relayed):
    runtime = f"runtime: {{mocap_relay: {setting}}}\n" if setting else ""
    mission = parse_mission(MISSION + f"mocap: {mocap}\n" + runtime)
    assert mission.runtime.mocap_relay == (setting or "auto")
    assert uses_relay(mission) is relayed


def test_a_bad_mocap_relay_value_is_one_line_naming_it():
    with pytest.raises(MissionError) as err:
        parse_mission(MISSION + "runtime:\n  mocap_relay: sometimes\n")
    assert str(err.value) == ("<string>:6: runtime.mocap_relay: expected one of 'auto', 'on', 'off', got 'sometimes'")
    quoted = parse_mission(MISSION + "runtime: {mocap_relay: 'on', zenoh: {mode: peer}}\n").runtime
    assert quoted.mocap_relay == "on" and quoted.zenoh.mode == "peer"


def test_the_relays_transit_figures_are_read_while_frames_arrive():
    """A worker's last report reads the relay's hop of every frame (`relay_transit`) while Zenoh's thread still
    appends arriving frames: the figures come out, never "deque mutated during iteration" (a worker on a loaded host
    died of it after its flight, without its report)."""
    from rpf_fly.runtime.worker import relay_transit

    endpoint = free_loopback_endpoint()
    router = open_session(ZenohSettings(), listen=[endpoint], mode="router")
    worker = open_session(ZenohSettings(), connect=[endpoint])
    relay = open_session(ZenohSettings(), connect=[endpoint])
    secret, key = new_secret(), "rpf_fly/f2/mocap_frames"
    source = RelayedMocap(worker, key, secret, "f2")
    signer = FrameSigner(secret, "f2")
    stop = threading.Event()

    def stream() -> None:
        number = 0
        while not stop.is_set():
            number += 1
            payload, signature = signer.sign(frame(number))
            relay.put(key, payload, attachment=signature)

    sender = threading.Thread(target=stream, daemon=True)
    try:
        sender.start()
        assert _until(lambda: source.stats.frames > 50)
        reads = 0
        deadline = time.monotonic() + 1.5
        while time.monotonic() < deadline:
            figures = relay_transit(source, 0.0)
            assert figures["relay_transit_p50_s"] <= figures["relay_transit_p99_s"]
            reads += 1
        assert reads > 10 and source.stats.frames > 200
    finally:
        stop.set()
        sender.join(2.0)
        source.close()
        for session in (relay, worker, router):
            session.close()
