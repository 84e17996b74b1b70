"""Distributed dry runs on Zenoh (docs/distributed.md): real sessions on 127.0.0.1, worker and logger processes,
cflib over the fake radio to the coordinator's simulated drones, the MCAP log read back.

Flights of four drones on two dongles, each a few seconds. The mission's NatNet is unicast, so its workers take
their mocap from the flight's relay (``runtime.mocap_relay: auto``): one flight with a remote worker started by
itself (``--connect`` to the coordinator's ``--listen``), a tap on ``rpf_fly/**`` and a foreign session
commanding land and emergency stop and forging mocap frames; one whose relay is killed mid-flight. The flight
whose worker is killed mid-flight takes the direct path (``mocap_relay: off``: each worker its own NatNet
client); one whose relay cannot open its mocap never starts a worker; one whose coordinator listens on another
address than 127.0.0.1 (its simulated drones serve there) with a drone failing its preflight on one dongle and the
drones beside it kept down on the other.
"""

from __future__ import annotations

import cmath
import json
import math
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections import defaultdict
from pathlib import Path
from types import SimpleNamespace

import pytest

from rpf_fly.emulator.radio_wire import CLOSE, REQUEST
from rpf_fly.flight.dry_run import StartFault
from rpf_fly.log.reader import read_log
from rpf_fly.log.review import review
from rpf_fly.mission import load_mission
from rpf_fly.mocap.frame import MocapFrame, RigidBodyPose
from rpf_fly.runtime.auth import SECRET_ENV, mac, new_secret, sign
from rpf_fly.runtime.coordinator import Coordinator
from rpf_fly.runtime.frames import FrameSigner
from rpf_fly.runtime.relay import RelayError
from rpf_fly.runtime.session import free_loopback_endpoint, open_session

HERE = Path(__file__).resolve().parent
MISSION = HERE / "two-dongles.yaml"
GROUNDED = HERE / "grounded.yaml"
ROOT = HERE.parents[1]


def _env() -> dict[str, str]:
    return dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))


def _wait(predicate, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.05)
    return False


def _variant(tmp_path: Path, extra: str, replace: tuple[str, str] = ("", "")) -> Path:
    """The test mission with ``extra`` appended (and one text replaced), beside its copy of the policy path."""
    text = MISSION.read_text().replace("../../policies/", f"{ROOT}/policies/").replace(*replace)
    path = tmp_path / "mission.yaml"
    path.write_text(text + extra)
    return path


def _forged_frames(flight: str, secret: str, genuine: tuple[bytes, bytes]) -> list[tuple[bytes, bytes | None]]:
    """What a foreign session can put on the relay key: cf1 far outside the arena, numbered far ahead (flown on, it
    would land cf1 and, taken as the newest, shut out the relay's own frames), unsigned and signed with another
    secret; a genuine frame replayed; a frame signed with the flight's secret that does not decode."""
    far = MocapFrame(
        10**9,
        0.0,
        time.monotonic(),
        None,
        {"cf1": RigidBodyPose("cf1", 1, (50.0, 50.0, 0.5), (0.0, 0.0, 0.0, 1.0), True)},
    )
    signer = FrameSigner(new_secret(), flight)
    signer.seq = 10**9
    payload, wrong = signer.sign(far)
    garbage = json.dumps({"flight": flight, "seq": 10**9}).encode()
    return [(payload, None), (payload, wrong), genuine, (garbage, mac(secret.encode(), garbage))]


def _told(lines: list[str], folder: Path) -> str:
    """What a failed flight said: the coordinator's lines and the end of each worker's log beside its flight log."""
    tails = [
        f"{path.name}: " + " | ".join(path.read_text(errors="replace").splitlines()[-12:])
        for path in sorted(folder.glob("*.log"))
    ]
    return "\n".join(lines + tails)


def _start(coordinator: Coordinator) -> tuple[threading.Thread, dict]:
    result: dict = {}

    def run() -> None:
        result["code"] = coordinator.run()

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread, result


def test_remote_worker_tap_and_foreign_commands(tmp_path):
    """A worker started by itself with --connect flies dongle 1 in the coordinator's flight, both workers on the
    relay's frames; a subscriber on rpf_fly/** sees every drone's setpoints, status and events and the relay's
    frames; a foreign session's land and emergency stop on the command key, and its forged, replayed and malformed
    mocap frames on the relay key, change nothing: counted by each worker and one warning each in the log. The log
    reviews as a clean flight and names the relay."""
    mission = load_mission(MISSION)
    endpoint = free_loopback_endpoint()
    lines: list[str] = []
    log_path = tmp_path / "remote.mcap"
    coordinator = Coordinator(
        mission,
        MISSION,
        log_path,
        dry_run=True,
        remote_dongles=(1,),
        listen=(endpoint,),
        say=lines.append,
        remote_wait_s=60.0,
    )
    thread, result = _start(coordinator)
    assert _wait(lambda: any("waiting for dongle 1" in line for line in lines), 60), lines
    remote = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "rpf_fly",
            "worker",
            str(MISSION),
            "--dongle",
            "1",
            "--connect",
            endpoint,
            "--dry-run",
        ],  # no --flight: the one flight its --connect reaches
        env=dict(_env(), **{SECRET_ENV: coordinator.secret, "RPF_FLY_WORKER_LOG": str(tmp_path / "remote.log")}),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
    )
    seen: dict[str, set[str]] = defaultdict(set)
    genuine: list[tuple[bytes, bytes]] = []
    tap = open_session(mission.runtime.zenoh, connect=(endpoint,))
    foreign = open_session(mission.runtime.zenoh, connect=(endpoint,))
    try:

        def sample(s) -> None:  # noqa: ANN001
            parts = str(s.key_expr).split("/")
            if parts[2] == "mocap_frames":
                genuine.append((s.payload.to_bytes(), s.attachment.to_bytes()))
            elif parts[2] == "events":
                name = json.loads(s.payload.to_bytes()).get("name")
                seen["events"].add(name)
            elif len(parts) == 4:
                seen[parts[2]].add(parts[3])

        tap.declare_subscriber(f"rpf_fly/{coordinator.flight}/**", sample)
        assert _wait(lambda: coordinator.phase == "flying", 90), lines
        key = f"rpf_fly/{coordinator.flight}/command"
        forged, _ = sign("not the flight's secret" * 3, coordinator.flight, "emergency_stop", 99)
        foreign.put(key, json.dumps({"command": "land", "seq": 1, "flight": coordinator.flight}).encode())
        foreign.put(key, forged, attachment=b"00" * 32)
        prefix = f"rpf_fly/{coordinator.flight}"  # junk on the message keys: dropped and counted, never logged
        foreign.put(f"{prefix}/setpoint/cf1", b"not json", attachment=b"\0" * 16)
        foreign.put(f"{prefix}/status/cf1", b"{bad")
        assert genuine, "the tap saw no relayed frame"
        for payload, attachment in _forged_frames(coordinator.flight, coordinator.secret, genuine[-1]):
            foreign.put(f"{prefix}/mocap_frames", payload, attachment=attachment)
        thread.join(120)
        assert not thread.is_alive()
        out = remote.communicate(timeout=30)[0].decode()
    finally:
        tap.close()
        foreign.close()
        if remote.poll() is None:
            remote.kill()
    assert result["code"] == 0, (lines, out)
    assert remote.returncode == 0, out
    names = {d.name for d in mission.drones}
    for kind in ("setpoint", "status", "planner", "mocap"):
        assert seen[kind] == names, (kind, seen[kind])
    assert names <= seen["events"], seen["events"]
    log = read_log(log_path)
    assert not log.truncated and log.undecodable == 0
    for name in names:
        status = [m.data for m in log.messages(f"/{name}/status")]
        assert status[-1]["state"] == "landed" and status[-1]["outcome"] == "reached", name
        assert all(not m.data["crashed"] for m in log.messages(f"/truth/{name}")), name
    for dongle in (0, 1):  # each worker logs its own dongle's measured load, the coordinator's log holds both
        loads = [m.data for m in log.messages(f"/radio/{dongle}")]
        assert loads and max(load["packets_per_s"] for load in loads) > 0, dongle
    warnings = [
        m.data["message"]
        for m in log.messages("/events")
        if m.data["level"] == 3 and "ignored a command" in m.data["message"]
    ]
    assert len(warnings) >= 4, warnings  # two refused commands, at each of the two workers
    runtime = log.metadata["runtime"]
    assert runtime["flight_id"] == coordinator.flight
    workers = json.loads(runtime["workers"])
    assert sorted(w["dongle"] for w in workers) == [0, 1] and all(w["pid"] for w in workers)
    assert any(w["pid"] == remote.pid for w in workers)
    for worker in coordinator.workers.values():  # each worker says what its logging cost it, in its three parts
        cost = worker.info["logging_cpu"]
        assert cost["messages"] > 100 and cost["writer_pct"] > 0 and cost["zenoh_pct"] is not None, cost
        assert cost["total_pct"] >= cost["loop_pct"] + cost["writer_pct"] - 0.01, cost
    # The two workers tick half a planning period apart (worker k of n at k/n: rpf_fly/runtime/worker.py
    # tick_offset), so they never plan on the same mocap frame: the circular mean of each worker's tick times
    # within the period, from the planner steps' log times.
    period_ns = round(mission.flight.dt * 1e9)

    def tick_phase(drones: tuple[str, ...]) -> complex:
        ticks = {m.log_time for n in drones for m in log.messages(f"/{n}/planner") if m.data["eta"] is not None}
        return sum(cmath.exp(2j * math.pi * (t % period_ns) / period_ns) for t in ticks) / len(ticks)

    apart = abs(cmath.phase(tick_phase(("cf1", "cf2")) / tick_phase(("cf3", "cf4")))) / (2 * math.pi)
    assert 0.3 <= apart <= 0.5, apart  # half a period, give or take the phase lock's pull towards the frames
    relay = json.loads(runtime["relay"])
    assert relay["pid"] == coordinator.relay_process.pid and relay["key"].endswith("/mocap_frames")
    assert relay["relayed"] is True
    assert coordinator.relay_info["state"] == "done" and coordinator.relay_info["frames"] > 100
    assert any(m.data["name"] == "relay" and m.data["message"].startswith("relaying") for m in log.messages("/events"))
    for worker in coordinator.workers.values():  # 4 refused by each (1 malformed), none taken
        mocap = worker.info["mocap"]
        assert mocap["dropped"] == 4 and mocap["malformed"] == 1 and mocap["frames"] > 100, (worker.name, mocap)
        assert worker.info["relay_transit_p50_s"] < 0.1, worker.info["relay_transit_p50_s"]
    refused = [m.data for m in log.messages("/events") if m.data["file"] == "mocap_relay" and m.data["level"] == 3]
    assert len(refused) == 2 and all("ignored a mocap frame" in e["message"] for e in refused), refused  # rate-limited
    assert not any(m.data["file"] == "geofence" for m in log.messages("/events"))  # cf1 was never 50 m away
    summary = review(log)
    assert summary.clean_end and not summary.interrupted
    assert summary.outcomes == {name: "reached" for name in names}


def test_a_killed_worker_is_noticed_and_the_others_fly_on(tmp_path):
    """SIGKILL of dongle 1's worker mid-flight: an event names it and its drones within 1 s of the kill; dongle
    0's drones reach their goals and land; the log closes. Direct mocap (``mocap_relay: off``): no relay runs, each
    worker has its own NatNet client. The console's rows (``Coordinator.snapshot``, through its status hook) follow
    the drones' status and tf messages: each drone's worker, its phase, where it is and how far from its goal, its
    battery and link as the log has them; the lost worker's drones are marked."""
    path = _variant(tmp_path, "runtime: {mocap_relay: off}\n")
    mission = load_mission(path)
    lines: list[str] = []
    log_path = tmp_path / "killed.mcap"
    shown: list[list[dict]] = []
    coordinator = Coordinator(
        mission, path, log_path, dry_run=True, say=lines.append, status_hook=lambda c: shown.append(c.snapshot())
    )
    thread, result = _start(coordinator)
    assert _wait(lambda: coordinator.drones["cf3"].state == "planning", 90), lines
    time.sleep(0.5)
    flying = {row["name"]: row for row in coordinator.snapshot()}
    assert list(flying) == ["cf1", "cf2", "cf3", "cf4"]
    assert [flying[n]["worker"] for n in flying] == ["dongle-0", "dongle-0", "dongle-1", "dongle-1"]
    goals = {d.name: complex(*d.goal) for d in mission.drones}
    for name, row in flying.items():
        assert row["phase"] in ("planning", "arrived") and not row["lost"] and row["outcome"] is None, row
        x, y, z = row["position"]
        assert abs(z - mission.flight.height) < 0.15, row  # from the worker's tf: in the air
        assert row["goal_distance"] == abs(goals[name] - complex(x, y))
        assert 3.0 < row["battery_v"] < 4.3 and 0 <= row["link_pct"] <= 100, row
    victim = coordinator.workers["dongle-1"].process
    assert victim is not None
    killed_at = time.monotonic()
    killed_ns = time.time_ns()
    os.kill(victim.pid, signal.SIGKILL)
    thread.join(120)
    assert not thread.is_alive()
    lost = [e for e in coordinator.events.history if e.kind == "worker_lost"]
    assert len(lost) == 1 and "dongle-1" in lost[0].message and "cf3, cf4" in lost[0].message
    assert f"its process was killed by signal {signal.SIGKILL.value}; see killed.dongle-1.log" in lost[0].message
    assert lost[0].time_s - killed_at < 1.0
    assert result["code"] == 1  # a worker was lost
    assert coordinator.drones["cf1"].outcome == "reached" and coordinator.drones["cf2"].outcome == "reached"
    log = read_log(log_path)
    assert not log.truncated
    assert any("worker dongle-1" in m.data["message"] for m in log.messages("/events"))
    for name in ("cf1", "cf2"):
        assert log.messages(f"/{name}/status")[-1].data["state"] == "landed"
        assert all(not m.data["crashed"] for m in log.messages(f"/truth/{name}")), name
    end = {row["name"]: row for row in coordinator.snapshot()}
    for name in ("cf1", "cf2"):
        last = log.messages(f"/{name}/status")[-1].data  # the same message reached the logger and the coordinator
        row = end[name]
        assert (row["phase"], row["outcome"], row["battery_v"], row["link_pct"]) == (
            last["state"],
            last["outcome"],
            last["battery_v"],
            100 * last["link_quality"],
        ), (row, last)
        pose = log.messages(f"/mocap/{name}")[-1].data["pose"]["position"]
        assert max(abs(a - b) for a, b in zip(row["position"], (pose["x"], pose["y"], pose["z"]))) < 0.02, row
        assert not row["lost"] and row["reason"] == "every drone of the swarm is at its goal", row  # its worker's
    for name in ("cf3", "cf4"):
        assert end[name]["lost"] and end[name]["worker"] == "dongle-1", end[name]
        assert end[name]["reason"].startswith("worker dongle-1 lost"), end[name]
    cf1 = [rows[0] for rows in shown]  # the hook's rows over the flight: cf1 took off, flew to its goal
    phases = [row["phase"] for row in cf1]
    # (the last status and the worker's end race in Zenoh's threads: the hook may miss "landed", the final rows not)
    assert "planning" in phases and phases[-1] in ("arrived", "landing", "landed"), sorted(set(phases))
    flown = [row["goal_distance"] for row in cf1 if row["phase"] == "planning"]
    assert flown[0] - flown[-1] > 0.5, flown
    # The relay still runs, for the log's mocap only: the workers read their own NatNet; the dead worker's drones
    # stay in the log's /mocap (the relay publishes every drone's pose, no worker does) as they fall to the floor.
    relay = json.loads(log.metadata["runtime"]["relay"])
    assert relay["relayed"] is False and relay["pid"] == coordinator.relay_process.pid
    for name in ("cf3", "cf4"):
        after = [m.data["pose"]["position"]["z"] for m in log.messages(f"/mocap/{name}") if m.log_time > killed_ns]
        assert len(after) > 50 and max(after) > 0.3 and after[-1] < 0.05, (name, len(after), after[-5:])
    assert coordinator.workers["dongle-0"].info["mocap"]["messages"] > 0  # NatNet's own handshake: its own client


def test_a_killed_relay_is_noticed_and_every_drone_lands(tmp_path):
    """SIGKILL of the mocap relay mid-flight: an event names it within 1 s and the coordinator lands every drone at
    once (not 1.5 s later, when each worker's supervisor would find its poses lost); every drone is down in the log,
    none crashed."""
    mission = load_mission(MISSION)
    lines: list[str] = []
    log_path = tmp_path / "relay-killed.mcap"
    coordinator = Coordinator(mission, MISSION, log_path, dry_run=True, say=lines.append)
    thread, result = _start(coordinator)
    assert _wait(lambda: all(coordinator.drones[n].state == "planning" for n in ("cf1", "cf3")), 90), lines
    relay = coordinator.relay_process
    assert relay is not None
    killed_at = time.monotonic()
    killed_ns = time.time_ns()
    os.kill(relay.pid, signal.SIGKILL)
    thread.join(120)
    assert not thread.is_alive()
    lost = [e for e in coordinator.events.history if e.kind == "relay_lost"]
    assert len(lost) == 1 and f"pid {relay.pid}" in lost[0].message, lost
    assert lost[0].time_s - killed_at < 1.0
    assert result["code"] == 1
    log = read_log(log_path)
    assert not log.truncated
    events = [m.data for m in log.messages("/events")]
    assert any(e["file"] == "relay_lost" for e in events)
    for name in ("cf1", "cf2", "cf3", "cf4"):
        statuses = log.messages(f"/{name}/status")
        final = statuses[-1].data
        # landed, or (blind, 4 drones in a line: the blind drift of safety.blind_drift_m_s2 could reach a neighbour
        # before a landing ends) landing at once and dropped near the floor (docs/flight.md, "Blind")
        assert (final["state"], final["outcome"]) in (("landed", "landed_early"), ("emergency", "emergency")), (
            name,
            final,
        )
        assert log.messages(f"/truth/{name}")[-1].data["position"]["z"] < 0.02, name
        landing = next(m.log_time for m in statuses if m.log_time > killed_ns and m.data["state"] == "landing")
        assert (landing - killed_ns) / 1e9 < 1.0, (name, (landing - killed_ns) / 1e9)  # a supervisor: 1.5 s
        assert all(not m.data["crashed"] for m in log.messages(f"/truth/{name}")), name


def test_a_relay_that_cannot_open_its_mocap_stops_the_flight_before_any_worker(tmp_path):
    """A real flight whose unicast NatNet server does not answer: the relay says why and exits; the coordinator
    raises one line naming it (the command line's exit 2), no worker was started, nothing is left running."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        silent = s.getsockname()[1]  # nobody answers there once closed
    path = _variant(tmp_path, "", ("up_axis: z, rate_hz: 50", f"up_axis: z, rate_hz: 50, command_port: {silent}"))
    mission = load_mission(path)
    coordinator = Coordinator(mission, path, tmp_path / "no-mocap.mcap", dry_run=False, say=lambda line: None)
    with pytest.raises(RelayError) as err:
        coordinator.run()
    message = str(err.value)
    assert "\n" not in message and "relay exited at start (code 2)" in message and "NatNet" in message, message
    assert all(w.process is None for w in coordinator.workers.values())
    assert coordinator.relay_process.poll() == 2 and coordinator.logger_process.poll() is not None
    assert not coordinator.events.history  # that one line only (the logger it ended is not "gone")


def _local_address() -> str:
    """A non-loopback IPv4 address of this machine, else 127.0.0.2: another address than the default 127.0.0.1
    either way, so a rig found there follows the coordinator's listen address."""
    import fcntl
    import struct

    for _, name in socket.if_nameindex():
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            try:  # SIOCGIFADDR: the card's IPv4 address
                packed = fcntl.ioctl(s.fileno(), 0x8915, struct.pack("256s", name.encode()[:15]))
            except OSError:
                continue
        address = socket.inet_ntoa(packed[20:24])
        if not address.startswith("127."):
            return address
    return "127.0.0.2"


def _answers(host: str, port: int) -> bool:
    """Whether the fake-radio server answers at (host, port): a CLOSE of no link, which changes nothing."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.settimeout(2.0)
        s.connect((host, port))
        s.send(REQUEST.pack(CLOSE, 1, 0, 0, 0))
        try:
            return len(s.recv(64)) > 0
        except OSError:  # refused: nothing listens there
            return False


def test_grounded_drones_across_workers_and_the_rig_on_the_listen_address(tmp_path):
    """``safety.on_preflight_failure: ground`` across workers, the coordinator listening on a non-loopback address
    (127.0.0.2 on a machine with none), dongle 1's worker started by itself with --connect to it.

    The simulated drones serve on that address, not on 127.0.0.1, and both workers reach them there. cf1 (dongle 0)
    stands 0.5 m off its start: its preflight fails. cf3's goal (dongle 1) is where cf1 stands: the coordinator's
    signed go names cf1 and dongle 1's worker keeps cf3 down; cf2's goal (dongle 0) is 0.1 m from cf3's start: it
    stays down too (the rule in turn, across workers). cf4 flies and reaches its goal. Before, cf2 and cf3 took off
    and flew to land on a drone standing on the floor."""
    mission = load_mission(GROUNDED)
    address = _local_address()
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((address, 0))
        endpoint = f"tcp/{address}:{s.getsockname()[1]}"
    lines: list[str] = []
    log_path = tmp_path / "grounded.mcap"
    coordinator = Coordinator(
        mission,
        GROUNDED,
        log_path,
        dry_run=True,
        remote_dongles=(1,),
        listen=(endpoint,),
        say=lines.append,
        remote_wait_s=60.0,
        start_faults={"cf1": StartFault(offset_m=(0.0, 0.5))},
    )
    thread, result = _start(coordinator)
    remote = None
    try:
        assert _wait(lambda: any("waiting for dongle 1" in line for line in lines), 60), lines
        radio, natnet = coordinator.rig.world.radio, coordinator.rig.world.natnet_command_port
        assert radio[0] == address and _answers(address, radio[1])
        assert not _answers("127.0.0.1", radio[1])  # bound to the listen address, not to loopback
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.settimeout(2.0)
            s.connect(("127.0.0.1", natnet))
            s.send(b"\0" * 4)
            with pytest.raises(ConnectionRefusedError):  # the NatNet emulator is not on loopback either
                s.recv(64)
        tap = open_session(mission.runtime.zenoh, connect=(endpoint,))
        try:
            rig = [
                json.loads(r.ok.payload.to_bytes())
                for r in tap.get(f"rpf_fly/{coordinator.flight}/rig", timeout=5.0)
                if r.ok is not None
            ]
        finally:
            tap.close()
        assert rig and rig[0]["radio"] == [address, radio[1]] and rig[0]["natnet_command_port"] == natnet
        remote = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "rpf_fly",
                "worker",
                str(GROUNDED),
                "--dongle",
                "1",
                "--connect",
                endpoint,
                "--dry-run",
            ],
            env=dict(_env(), **{SECRET_ENV: coordinator.secret, "RPF_FLY_WORKER_LOG": str(tmp_path / "remote.log")}),
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
        )
        thread.join(120)
        assert not thread.is_alive()
        out = remote.communicate(timeout=30)[0].decode()
    finally:
        if thread.is_alive():  # a failed check above: land (nothing has taken off) and end every process
            coordinator.interrupt()
            thread.join(60)
        if remote is not None and remote.poll() is None:
            remote.kill()
    assert result["code"] == 1, lines  # not every drone reached its goal
    assert remote.returncode == 1 and "cf3: not_flown" in out and "cf4: reached" in out, out
    outcomes = {name: view.outcome for name, view in coordinator.drones.items()}
    assert outcomes == {"cf1": "not_flown", "cf2": "not_flown", "cf3": "not_flown", "cf4": "reached"}, outcomes
    go = [e.message for e in coordinator.events.history if e.kind == "command" and e.message.startswith("go")]
    assert len(go) == 1 and "cf1, cf2 stay on the ground" in go[0], go  # cf2: dongle 0 applied the rule in turn
    log = read_log(log_path)
    assert not log.truncated
    said = {(m.data["name"], m.data["message"]) for m in log.messages("/events")}
    assert any(name == "cf1" and "from its start" in text for name, text in said), said
    assert any(
        name == "cf3" and "preflight: its goal is 0.00 m from cf1, which stays on the ground" in text
        for name, text in said
    ), said
    assert any(
        name == "cf2" and "preflight: its goal is 0.10 m from cf3, which stays on the ground" in text
        for name, text in said
    ), said
    assert any(
        name == "flight" and text.startswith("cf3 stay on the ground beside the swarm's grounded drones")
        for name, text in said
    ), said
    for name in ("cf1", "cf2", "cf3"):
        assert log.messages(f"/{name}/status")[-1].data["state"] == "failed", name
        truth = log.messages(f"/truth/{name}")
        assert truth and not any(m.data["motors"] for m in truth), name
        assert max(m.data["position"]["z"] for m in truth) < 0.01, name
    assert log.messages("/cf4/status")[-1].data["state"] == "landed"
    assert max(m.data["position"]["z"] for m in log.messages("/truth/cf4")) > 0.4


def test_zenoh_unreachable_at_start_is_one_line_and_exit_2(tmp_path):
    endpoint = free_loopback_endpoint()  # nobody listens there
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "rpf_fly",
            "worker",
            str(MISSION),
            "--dongle",
            "0",
            "--flight",
            "nobody",
            "--connect",
            endpoint,
            "--dry-run",
        ],
        env=dict(_env(), **{SECRET_ENV: "0" * 64, "RPF_FLY_WORKER_LOG": str(tmp_path / "w.log")}),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and "zenoh: cannot open a session" in done.stderr, done.stderr
    assert done.stdout == ""


def test_a_distributed_dry_run_takes_only_power_on_faults(tmp_path):
    """--faults with --distributed: the power-on faults live in the simulated drones (the coordinator's); a timed
    one needs the flight loop of a worker: refused in one line naming its line and kind, nothing started."""
    from typer.testing import CliRunner

    from rpf_fly.cli import get_app

    faults = tmp_path / "faults.yaml"
    faults.write_text(
        "faults:\n  - {kind: start_offset, drone: cf1, offset_m: [0.0, 0.5]}\n"
        "  - {kind: planner_error, drone: cf2, at_s: 1.0}\n"
    )
    result = CliRunner().invoke(
        get_app(),
        ["fly", str(MISSION), "--dry-run", "--distributed", "--faults", str(faults), "--log", str(tmp_path / "f.mcap")],
    )
    assert result.exit_code == 2
    assert (
        result.output.strip() == f"{faults}:3: planner_error: --distributed takes the power-on faults only "
        "(yaw_offset, start_offset, upside_down, motor_fault; docs/distributed.md)"
    )
    assert not (tmp_path / "f.mcap").exists()


def test_a_drone_refused_at_arming_keeps_another_workers_drones_beside_it_down(tmp_path):
    """cf1 (dongle 0) passes its preflight but a motor fails the arming's spin-up: it stays on the ground. cf3's goal
    (dongle 1) is where cf1 stands, and cf2's goal (dongle 0) is beside cf3's start. The workers report their arming,
    the coordinator's signed ``takeoff`` names cf1, and dongle 1's worker keeps cf3 down (disarmed), and so dongle 0
    keeps cf2 down: the same as one process. Before, the workers took off without a second round: cf3 flew to land
    on cf1. cf4 flies and reaches its goal."""
    text = (
        GROUNDED.read_text()
        .replace("../../policies/", f"{ROOT}/policies/")
        .replace("goal: [-0.8, -0.3]}", "goal: [-0.8, -0.8]}")
    )
    path = tmp_path / "arming.yaml"
    path.write_text(text)
    mission = load_mission(path)
    lines: list[str] = []
    log_path = tmp_path / "arming.mcap"
    coordinator = Coordinator(
        mission, path, log_path, dry_run=True, say=lines.append, start_faults={"cf1": StartFault(motor_fault=True)}
    )
    thread, result = _start(coordinator)
    thread.join(120)
    assert not thread.is_alive()
    assert result["code"] == 1, lines
    outcomes = {name: view.outcome for name, view in coordinator.drones.items()}
    assert outcomes == {"cf1": "not_flown", "cf2": "not_flown", "cf3": "not_flown", "cf4": "reached"}, outcomes
    takeoff = [e.message for e in coordinator.events.history if e.kind == "command" and e.message.startswith("takeoff")]
    assert len(takeoff) == 1 and "cf1, cf2 stay on the ground" in takeoff[0], takeoff  # cf2: dongle 0, in turn
    log = read_log(log_path)
    said = {(m.data["name"], m.data["message"]) for m in log.messages("/events")}
    # (why, in the supervisor's words, depends on when its telemetry came: "spin-up check" or "not armed")
    assert any(name == "cf1" and "its supervisor was not ready to fly" in text for name, text in said), said
    assert any(
        name == "cf3" and "its goal is 0.00 m from cf1, which stays on the ground" in text for name, text in said
    ), said
    assert any(
        name == "cf2" and "its goal is 0.10 m from cf3, which stays on the ground" in text for name, text in said
    ), said
    for name in ("cf1", "cf2", "cf3"):
        truth = log.messages(f"/truth/{name}")
        assert truth and max(m.data["position"]["z"] for m in truth) < 0.01, name
        assert not any(m.data["crashed"] for m in truth), name
        assert not truth[-1].data["motors"], name
    assert max(m.data["position"]["z"] for m in log.messages("/truth/cf4")) > 0.4


def test_a_motioncapture_mission_flies_distributed_through_the_relay(tmp_path):
    """A ``motioncapture`` mission (OptiTrack through the motioncapture package) flown distributed in a dry run: the
    relay reads the emulator as the single-process dry run does (the package's decoder on its multicast) and the
    workers fly on its frames. Before, the relay's unicast client got no frame from the multicasting emulator and
    no worker started."""
    path = _variant(
        tmp_path,
        "",
        (
            "mocap: {kind: natnet, server: 127.0.0.1, multicast: false, up_axis: z, rate_hz: 50}",
            "mocap: {kind: motioncapture, type: optitrack, hostname: 127.0.0.1}",
        ),
    )
    mission = load_mission(path)
    assert mission.mocap.kind == "motioncapture"
    lines: list[str] = []
    coordinator = Coordinator(mission, path, tmp_path / "mc.mcap", dry_run=True, say=lines.append)
    thread, result = _start(coordinator)
    thread.join(120)
    assert not thread.is_alive()
    assert result["code"] == 0, _told(lines, tmp_path)
    assert coordinator.relayed and coordinator.relay_info["frames"] > 100, coordinator.relay_info
    assert "motioncapture" in coordinator.relay_info["source"]
    assert coordinator.workers["dongle-0"].info["radio"] == {"radio": "fake"}  # the mission's default dry-run radio
    log = read_log(tmp_path / "mc.mcap")
    for name in ("cf1", "cf2", "cf3", "cf4"):
        assert log.messages(f"/{name}/status")[-1].data["outcome"] == "reached", name
        assert len(log.messages(f"/mocap/{name}")) > 100, name


def test_a_crazyradio_dry_run_flies_distributed_through_cflibs_radio_driver(tmp_path):
    """``dry_run.radio: crazyradio`` in a distributed dry run: each worker plugs its own dongle (an emulated
    Crazyradio PA) into its process, and cflib's ``radio://`` driver carries its drones' packets to the
    coordinator's simulated drones; every drone reaches its goal. Before, the workers flew ``fake://`` whatever the
    mission said."""
    path = _variant(tmp_path, "dry_run: {radio: crazyradio, crazyradio: crazyradio_pa}\n")
    lines: list[str] = []
    coordinator = Coordinator(load_mission(path), path, tmp_path / "cr.mcap", dry_run=True, say=lines.append)
    thread, result = _start(coordinator)
    thread.join(120)
    assert not thread.is_alive()
    assert result["code"] == 0, _told(lines, tmp_path)
    log = read_log(tmp_path / "cr.mcap")
    for worker in ("dongle-0", "dongle-1"):
        radio = coordinator.workers[worker].info["radio"]
        assert radio["radio"] == "crazyradio" and radio["type"] == "crazyradio_pa", radio
        drones = coordinator.workers[worker].drones
        assert set(radio["packets"]) == set(drones), radio
        for name in drones:  # at least the 10 Hz setpoints of the seconds it flew its mission went through the dongle
            status = log.messages(f"/{name}/status")
            assert status[-1].data["outcome"] == "reached", name
            planning = [m.log_time for m in status if m.data["state"] in ("planning", "arrived")]
            assert radio["packets"][name] >= 10 * (planning[-1] - planning[0]) / 1e9, (name, radio)


def test_a_workers_report_that_comes_after_its_token_ended_is_not_a_lost_worker(tmp_path):
    """A worker's last report (``done``) and the end of its liveliness token travel apart: on a loaded host the
    token's end can come first. That worker finished: it is not lost. A worker whose report never comes is lost one
    grace after its token ended, in one event naming it and its drones."""
    import zenoh

    from rpf_fly.runtime.swarm_views import REPORT_GRACE_S

    coordinator = Coordinator(load_mission(MISSION), MISSION, tmp_path / "late.mcap", dry_run=True, say=lambda _: None)
    names = list(coordinator.workers)
    assert len(names) == 2
    for name in names:
        coordinator._alive(name, True)
    coordinator._alive(names[0], False)
    coordinator._alive(names[1], False)
    assert [w.name for w in coordinator._live()] == names  # both may still report
    report = {
        "name": names[0],
        "state": "done",
        "outcomes": dict.fromkeys(coordinator.workers[names[0]].drones, "reached"),
    }
    coordinator._worker_info(SimpleNamespace(payload=zenoh.ZBytes(json.dumps(report).encode())))
    assert [w.name for w in coordinator._live()] == [names[1]]
    coordinator.workers[names[1]].gone_at -= REPORT_GRACE_S  # type: ignore[operator]
    assert coordinator._live() == []
    assert not coordinator.workers[names[0]].lost and coordinator.workers[names[1]].lost
    lost = [e.message for e in coordinator.events.history if e.kind == "worker_lost"]
    assert len(lost) == 1 and names[1] in lost[0] and ", ".join(coordinator.workers[names[1]].drones) in lost[0], lost
    assert all(coordinator.drones[n].outcome == "reached" for n in coordinator.workers[names[0]].drones)
