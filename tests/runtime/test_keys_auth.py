"""The flight's keys, the coordinator's signed commands and where a dry run's simulated drones serve
(rpf_fly/runtime/keys.py, auth.py, session.py)."""

from __future__ import annotations

import hashlib
import hmac
import json

import pytest

from rpf_fly.runtime.auth import CommandVerifier, new_secret, sign
from rpf_fly.runtime.keys import FlightKeys, check_flight_id, suffix_topic, topic_suffix
from rpf_fly.runtime.session import rig_address, rig_host


@pytest.mark.parametrize(
    "topic, suffix",
    [
        ("/mocap/cf1", "mocap/cf1"),
        ("/cf1/setpoint", "setpoint/cf1"),
        ("/cf1/planner", "planner/cf1"),
        ("/cf1/status", "status/cf1"),
        ("/events", "events"),
        ("/truth/cf1", "truth/cf1"),
        ("/radio/2", "radio/2"),
    ],
)
def test_log_topics_and_keys_map_both_ways(topic, suffix):
    assert topic_suffix(topic, "dongle-0") == suffix
    assert suffix_topic(suffix) == topic


def test_tf_is_per_publisher_and_the_scene_is_not_published():
    assert topic_suffix("/tf", "dongle-2") == "tf/dongle-2" and suffix_topic("tf/dongle-2") == "/tf"
    assert topic_suffix("/scene", "dongle-0") is None
    for suffix in ("command", "alive/dongle-0", "workers/dongle-0", "rig", "setpoint/a/b", "nonsense/cf1"):
        assert suffix_topic(suffix) is None, suffix


def test_flight_keys():
    keys = FlightKeys("lab-3-20261201-101010")
    assert keys.key("setpoint/cf1") == "rpf_fly/lab-3-20261201-101010/setpoint/cf1"
    assert keys.suffix_of("rpf_fly/lab-3-20261201-101010/status/cf2") == "status/cf2"
    assert keys.suffix_of("rpf_fly/other/status/cf2") is None
    with pytest.raises(ValueError):
        check_flight_id("a/b")


def test_a_signed_command_is_taken_once():
    secret = new_secret()
    verifier = CommandVerifier(secret, "f1")
    payload, signature = sign(secret, "f1", "land", 1, "operator")
    command, why = verifier.verify(payload, signature)
    assert command is not None and command.command == "land" and command.reason == "operator" and why == ""
    again, why = verifier.verify(payload, signature)
    assert again is None and "replayed" in why


@pytest.mark.parametrize("case", ["unsigned", "other secret", "other flight", "tampered", "unknown"])
def test_commands_that_are_not_the_coordinators_are_refused(case):
    secret = new_secret()
    verifier = CommandVerifier(secret, "f1")
    payload, signature = sign(
        secret if case != "other secret" else new_secret(),
        "f1" if case != "other flight" else "f2",
        "emergency_stop" if case != "unknown" else "self_destruct",
        1,
    )
    if case == "unsigned":
        signature = None
    if case == "tampered":
        payload = payload.replace(b"emergency_stop", b"go")
    command, why = verifier.verify(payload, signature)
    assert command is None and why


def test_a_go_carries_the_grounded_drones_under_its_signature():
    """The drones that stay on the ground ride in the signed go: a foreign session can neither add nor remove one,
    nor ground drones with another command."""
    secret = new_secret()
    payload, signature = sign(secret, "f1", "go", 1, "", ("cf3", "cf1"))
    command, why = CommandVerifier(secret, "f1").verify(payload, signature)
    assert command is not None and command.grounded == ("cf1", "cf3") and why == ""
    plain, _ = CommandVerifier(secret, "f1").verify(*sign(secret, "f1", "go", 1))
    assert plain is not None and plain.grounded == ()
    tampered = payload.replace(b'"cf3"', b'"cf2"')
    assert CommandVerifier(secret, "f1").verify(tampered, signature)[0] is None
    ungrounded = payload.replace(b',"grounded":["cf1","cf3"]', b"")
    assert ungrounded != payload and CommandVerifier(secret, "f1").verify(ungrounded, signature)[0] is None
    land, why = CommandVerifier(secret, "f1").verify(*sign(secret, "f1", "land", 1, "", ("cf1",)))
    assert land is None and "refused" in why
    malformed = json.dumps(
        {"command": "go", "seq": 1, "reason": "", "t_ns": 0, "flight": "f1", "grounded": "cf1"}
    ).encode()
    assert CommandVerifier(secret, "f1").verify(
        malformed, hmac.new(secret.encode(), malformed, hashlib.sha256).hexdigest().encode()
    ) == (None, "malformed command")


@pytest.mark.parametrize(
    "listen, host",
    [
        ((), "127.0.0.1"),
        (("tcp/127.0.0.1:7447",), "127.0.0.1"),
        (("tcp/127.0.0.2:7447",), "127.0.0.2"),
        (("tcp/10.0.0.5:7447",), "10.0.0.5"),
        (("tls/10.0.0.5:7447?iface=eth0",), "10.0.0.5"),
        (("tcp/0.0.0.0:7447",), "0.0.0.0"),
        (("tcp/[::]:7447",), "0.0.0.0"),
        (("tcp/[::1]:7447",), "127.0.0.1"),
        (("tcp/localhost:7447",), "127.0.0.1"),
        (("tcp/10.0.0.5:7447", "tcp/127.0.0.1:7447"), "10.0.0.5"),
    ],
)
def test_the_rig_binds_the_first_listen_address(listen, host):
    assert rig_host(listen) == host


def test_the_rig_refuses_an_ipv6_listen_address_in_one_line():
    with pytest.raises(ValueError, match=r"tcp/\[fd00::2\]:7447.*IPv4"):
        rig_host(("tcp/[fd00::2]:7447",))


@pytest.mark.parametrize(
    "advertised, connect, host",
    [
        ("10.0.0.5", ("tcp/10.0.0.9:7447",), "10.0.0.5"),
        ("0.0.0.0", ("tcp/10.0.0.5:7447",), "10.0.0.5"),
        ("0.0.0.0", (), "127.0.0.1"),
        ("0.0.0.0", ("tcp/127.0.0.1:7447",), "127.0.0.1"),
    ],
)
def test_a_worker_reaches_a_rig_on_every_interface_where_it_reached_the_coordinator(advertised, connect, host):
    assert rig_address(advertised, connect) == host
