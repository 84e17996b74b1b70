"""``runtime.zenoh.config``: a Zenoh configuration file under every session of a flight (TLS, access control),
checked at mission load, and read by real Zenoh sessions over TLS on loopback (tests/runtime/tls: a test CA and a
``localhost`` certificate made with openssl for these tests, valid for 100 years)."""

from __future__ import annotations

import json
import socket
import threading
from pathlib import Path

import pytest

from rpf_fly.mission import MissionError, parse_mission
from rpf_fly.mission.model import ZenohSettings
from rpf_fly.runtime.session import ZenohUnavailable, open_session

TLS = Path(__file__).resolve().parent / "tls"
MISSION = (
    "name: tls\narena: {x: [-2, 2], y: [-2, 2]}\n"
    "drones:\n  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [0, 0], goal: [1, 0]}\n"
)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def write(path: Path, config: dict) -> Path:
    path.write_text(json.dumps(config))
    return path


def test_the_config_file_is_resolved_beside_the_mission_and_checked_at_load(tmp_path: Path) -> None:
    write(tmp_path / "zenoh.json5", {"transport": {"link": {"tls": {"root_ca_certificate": str(TLS / "ca.pem")}}}})
    mission_file = tmp_path / "m.yaml"
    mission_file.write_text(MISSION + "runtime: {zenoh: {config: zenoh.json5}}\n")
    from rpf_fly.mission import load_mission

    assert load_mission(mission_file).runtime.zenoh.config == (tmp_path / "zenoh.json5").resolve()
    with pytest.raises(MissionError, match=r"runtime.zenoh.config: Zenoh config file 'absent.json5' not found"):
        parse_mission(MISSION + "runtime: {zenoh: {config: absent.json5}}\n")
    (tmp_path / "bad.json5").write_text("{transport: [")
    mission_file.write_text(MISSION + "runtime:\n  zenoh:\n    config: bad.json5\n")
    with pytest.raises(MissionError) as err:
        load_mission(mission_file)
    assert "m.yaml:7: runtime.zenoh.config: Zenoh cannot read" in str(err.value) and "\n" not in str(err.value)


def test_sessions_reach_each_other_over_tls_only_with_the_certificates_of_their_config_files(tmp_path: Path) -> None:
    router_file = write(
        tmp_path / "router.json5",
        {
            "transport": {
                "link": {
                    "tls": {
                        "listen_certificate": str(TLS / "server.pem"),
                        "listen_private_key": str(TLS / "server.key"),
                    }
                }
            }
        },
    )
    client_file = write(
        tmp_path / "client.json5", {"transport": {"link": {"tls": {"root_ca_certificate": str(TLS / "ca.pem")}}}}
    )
    endpoint = f"tls/localhost:{free_port()}"
    router = open_session(ZenohSettings(config=router_file), listen=[endpoint], mode="router")
    got = threading.Event()
    try:
        router.declare_subscriber("rpf_fly/tls/test", lambda sample: got.set())
        client = open_session(ZenohSettings(config=client_file), connect=[endpoint])
        try:
            for _ in range(20):
                client.put("rpf_fly/tls/test", b"over tls")
                if got.wait(0.1):
                    break
            assert got.is_set()
        finally:
            client.close()
        with pytest.raises(ZenohUnavailable, match="cannot open a session"):  # no CA: the handshake fails
            open_session(ZenohSettings(), connect=[endpoint]).close()
    finally:
        router.close()
