"""``rpf-fly replay`` and ``rpf-fly mocap emulate --replay`` on real dry-run logs (real cflib over the fake radio,
NatNet over loopback, real onnxruntime): the flight's own planner gives every logged decision back, another one
is reported where it differs, broken logs get one line, and a log's mocap goes over NatNet again."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from flight_harness import SHORT_MISSION, fly_to_every_goal
from mcap.records import Channel, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer
from typer.testing import CliRunner

from rpf_fly.cli import get_app
from rpf_fly.emulator.log_playback import PosePlayback
from rpf_fly.flight.replay import replay_log, replay_setup
from rpf_fly.flight.replay_inputs import PLANNING_MODES
from rpf_fly.log.mocap_frames import mocap_frames
from rpf_fly.log.reader import LogMessage, read_log
from rpf_fly.mission import parse_mission
from rpf_fly.mocap.natnet_client import NatNetClient

# Its module and session fixtures fly once: the tests sharing them run on one xdist worker (pyproject: --dist
# loadgroup).
pytestmark = pytest.mark.xdist_group("replay_logs")

ROOT = Path(__file__).resolve().parents[2]
RPF_POLICY = ROOT / "policies" / "rpf.onnx"
runner = CliRunner()


@pytest.fixture(scope="module")
def apf_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A dry run of the short 3-drone mission (one obstacle) with the fixed-gain APF."""
    flight = fly_to_every_goal(parse_mission(SHORT_MISSION), tmp_path_factory.mktemp("apf"))
    assert set(flight.report.outcomes.values()) == {"reached"}
    return flight.log_path


@pytest.fixture(scope="module")
def rpf_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The same mission flown with the shipped RPF-1 policy (onnxruntime, batched in the loop)."""
    text = SHORT_MISSION.replace("planner: {kind: apf, margin: 0}", f"planner: {{kind: rpf, policy: {RPF_POLICY}}}")
    flight = fly_to_every_goal(parse_mission(text), tmp_path_factory.mktemp("rpf"))
    assert set(flight.report.outcomes.values()) == {"reached"}
    return flight.log_path


def replay(*args: object):  # noqa: ANN201 - click's Result
    return runner.invoke(get_app(), ["replay", *map(str, args)])


def planning_rows(path: Path) -> dict[str, int]:
    data = read_log(path)
    return {
        d: sum(m.data["mode"] in PLANNING_MODES for m in data.topics[f"/{d}/planner"]) for d in ("cf1", "cf2", "cf3")
    }


# ---------------------------------------------------------------------------------------------- reproduction


def test_replaying_an_apf_flight_with_its_own_planner_gives_every_decision_back(apf_log: Path) -> None:
    result = replay(apf_log, "--json")
    assert result.exit_code == 0, result.output
    assert result.stderr == ""
    out = json.loads(result.stdout)
    assert out["planner"] == out["flown_planner"] == "apf" and out["same_as_flown"] is True
    assert out["exact_times"] is True and out["tolerance"] == 1e-6
    rows = planning_rows(apf_log)
    for name, drone in out["drones"].items():
        assert drone["ticks"] == rows[name] > 20, name  # every tick the flight planned, compared
        assert drone["first_divergence_tick"] is None, (name, drone)
        assert drone["max_direction_diff"] <= 1e-6, (name, drone)
        assert drone["mode_changes"] == 0 and drone["pose_mismatches"] == 0 and drone["skipped_ticks"] == 0
        assert drone["restarts"] == 1  # take-off; no holds in this flight


def test_replaying_an_rpf_flight_with_its_own_policy_agrees_to_the_onnx_parity_tolerance(rpf_log: Path) -> None:
    data = read_log(rpf_log)
    setup = replay_setup(data)
    assert setup.same_as_flown and setup.tolerance == 1e-5  # the export's parity tolerance (docs/learning.md)
    result = replay_log(data, setup.mission, setup.factory, tolerance=setup.tolerance)
    rows = planning_rows(rpf_log)
    for name, drone in result.drones.items():
        assert len(drone.ticks) == rows[name] > 20
        assert drone.first_divergence_tick is None and drone.max_direction_diff <= 1e-5, (name, drone.to_json())
        assert drone.mode_changes == 0


def _tampered_replay(log: Path, nth: int):  # type: ignore[no-untyped-def]
    """Replay ``log`` with cf2's ``nth`` planning tick's logged direction turned by 1e-4 rad: (result, that row)."""
    data = read_log(log)
    rows = data.topics["/cf2/planner"]
    k = [i for i, m in enumerate(rows) if m.data["mode"] in PLANNING_MODES][nth]
    d = rows[k].data["direction"]
    turned = complex(d["x"], d["y"]) * np.exp(1e-4j)
    tampered = dict(rows[k].data, direction={"x": turned.real, "y": turned.imag})
    rows[k] = LogMessage(rows[k].log_time, rows[k].publish_time, rows[k].sequence, tampered)
    setup = replay_setup(data)
    return replay_log(data, setup.mission, setup.factory, tolerance=setup.tolerance), tampered


def test_a_replay_reports_the_first_tick_where_the_log_says_otherwise(apf_log: Path) -> None:
    """The comparison is not blind: one logged direction turned by 1e-4 rad is found at its tick, and only there."""
    result, tampered = _tampered_replay(apf_log, 10)
    cf2 = result.drones["cf2"]
    assert cf2.first_divergence_tick == tampered["tick"]
    assert cf2.divergent_ticks == 1 and cf2.max_direction_diff == pytest.approx(1e-4, rel=1e-3)
    assert result.drones["cf1"].first_divergence_tick is None


@pytest.mark.parametrize("nth", [0, 4, 8, 12])
def test_a_tampered_direction_is_one_divergent_tick_not_a_restart_wherever_the_drone_turns(
    rpf_log: Path, nth: int
) -> None:
    """A logged direction a hair off moves the logged reference 5 um from where the replay's step puts it: that is
    not a restart (which would turn the replayed heading to the goal, and a drone avoiding others would then diverge
    for tens of ticks: 2-29 on an RPF flight before `replay.RESTART_OFF_M`)."""
    result, tampered = _tampered_replay(rpf_log, nth)
    cf2 = result.drones["cf2"]
    assert cf2.first_divergence_tick == tampered["tick"] and cf2.divergent_ticks == 1, cf2.to_json()


# ------------------------------------------------------------------------------------------ other planners


def test_orca_on_an_apf_flight_shows_where_it_would_have_decided_otherwise(apf_log: Path, tmp_path: Path) -> None:
    png = tmp_path / "orca.png"
    result = replay(apf_log, "--planner", "orca", "--json", "--plot", png)
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    assert out["planner"] == "orca" and out["flown_planner"] == "apf" and out["same_as_flown"] is False
    diverged = {n: d for n, d in out["drones"].items() if d["first_divergence_tick"] is not None}
    assert diverged and max(d["max_direction_diff"] for d in diverged.values()) > 0.1
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(
    "args", [("--planner", "apf"), ("--policy", ROOT / "policies" / "rpf-mean.onnx")], ids=["apf", "rpf-mean-policy"]
)
def test_another_planner_or_policy_on_an_rpf_flight_diverges(rpf_log: Path, args: tuple) -> None:
    result = replay(rpf_log, *args, "--json")
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    assert out["same_as_flown"] is False and out["flown_planner"] == "rpf"
    assert any(d["first_divergence_tick"] is not None for d in out["drones"].values()), out
    for drone in out["drones"].values():  # the JSON contract
        assert {"ticks", "first_divergence_tick", "max_direction_diff", "mode_changes"} <= set(drone)


def test_the_text_report_and_the_plot(apf_log: Path, tmp_path: Path) -> None:
    png = tmp_path / "replay.png"
    result = replay(apf_log, "--plot", png)
    assert result.exit_code == 0, result.output
    assert "every decision reproduced" in result.stdout and "apf" in result.stdout
    import matplotlib.image

    assert matplotlib.image.imread(png).shape[0] > 300


def test_the_text_report_piped_is_plain_lines_not_wrapped_at_80_columns(apf_log: Path) -> None:
    """Not a terminal (CliRunner, a pipe, CI): the header and the table's title are one line each, as `review`'s."""
    result = replay(apf_log, "--planner", "orca")
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert lines[0].startswith(f"{apf_log.name}: replayed orca, open loop against the flown apf; ")
    assert lines[0].endswith(" ms a tick"), lines[:2]
    assert lines[1].strip().startswith("decisions: ") and lines[1].strip().endswith("ticks whose mode differs")
    assert result.stdout.endswith("\n") and "…" not in result.stdout
    assert not any(line.endswith(" ") for line in lines), lines


def test_the_plot_has_one_time_axis_for_every_drone(apf_log: Path) -> None:
    """Drones that arrive at different times still share the time axis (as the review figure's panels do)."""
    import matplotlib.pyplot as plt

    from rpf_fly.flight.replay_plot import replay_figure

    data = read_log(apf_log)
    setup = replay_setup(data, "orca")
    result = replay_log(data, setup.mission, setup.factory, tolerance=setup.tolerance, planner="orca")
    ends = {name: d.ticks[-1].t_ns for name, d in result.drones.items()}
    assert len(set(ends.values())) > 1, ends  # the drones stop planning at different ticks
    fig = replay_figure(result)
    try:
        limits = {tuple(ax.get_xlim()) for ax in fig.axes}
        assert len(limits) == 1, limits
        assert all("mode differs on " in ax.get_title() for ax in fig.axes[1::2])
    finally:
        plt.close(fig)


# -------------------------------------------------------------------------------------------- broken logs


def copy_log(src: Path, dst: Path, drop: set[str] = frozenset(), metadata: dict | None = None) -> Path:
    """A finished copy of ``src`` without the topics in ``drop`` (and with ``metadata`` records replaced)."""
    with open(src, "rb") as f, open(dst, "wb") as out:
        writer = Writer(out, compression=CompressionType.ZSTD)
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for record in StreamReader(f, skip_magic=False).records:
            if isinstance(record, Header):
                writer.start(profile=record.profile, library=record.library)
            elif isinstance(record, Schema) and record.id not in schemas:
                schemas[record.id] = writer.register_schema(record.name, record.encoding, record.data)
            elif isinstance(record, Channel) and record.id not in channels and record.topic not in drop:
                channels[record.id] = writer.register_channel(
                    record.topic, record.message_encoding, schemas[record.schema_id], dict(record.metadata)
                )
            elif isinstance(record, Metadata) and record.name not in (metadata or {}):
                writer.add_metadata(record.name, dict(record.metadata))
            elif isinstance(record, Message) and record.channel_id in channels:
                writer.add_message(
                    channels[record.channel_id], record.log_time, record.data, record.publish_time, record.sequence
                )
            elif isinstance(record, Footer):
                break
        for name, values in (metadata or {}).items():
            writer.add_metadata(name, values)
        writer.finish()
    return dst


def one_line(result) -> str:  # noqa: ANN001
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert "Traceback" not in result.output
    return lines[0]


def test_a_drone_without_planner_rows_is_named_in_one_line_and_the_others_replay(apf_log: Path, tmp_path: Path) -> None:
    log = copy_log(apf_log, tmp_path / "no-cf2.mcap", drop={"/cf2/planner"})
    result = replay(log, "--json")
    assert result.exit_code == 0, result.output
    assert one_line(result) == (
        f"{log}: no planner rows (/cf2/planner) in the log: not replayed (its poses still "
        "count as a neighbour, by height)"
    )
    out = json.loads(result.stdout)
    assert out["drones"]["cf2"]["ticks"] == 0 and out["drones"]["cf2"]["first_divergence_tick"] is None
    assert out["drones"]["cf1"]["ticks"] > 20 and out["drones"]["cf1"]["first_divergence_tick"] is None


def test_a_log_without_any_planner_rows_is_one_line_and_exit_2(apf_log: Path, tmp_path: Path) -> None:
    log = copy_log(apf_log, tmp_path / "none.mcap", drop={f"/cf{i}/planner" for i in (1, 2, 3)})
    result = replay(log)
    assert result.exit_code == 2
    assert one_line(result).startswith(f"{log}: no planner rows (/<drone>/planner) for any drone")


def test_a_truncated_log_replays_what_it_holds_with_one_warning(apf_log: Path, tmp_path: Path) -> None:
    """A killed flight: the file ends mid-chunk, without summary and footer; the reader salvages its complete
    chunks and the replay reproduces every tick they hold."""
    cut = tmp_path / "cut.mcap"
    raw = apf_log.read_bytes()
    cut.write_bytes(raw[: int(len(raw) * 0.6)])
    assert read_log(cut).truncated
    result = replay(cut, "--json")
    assert result.exit_code == 0, result.output
    warnings = result.stderr.strip().splitlines()
    assert warnings and all(w.startswith(f"{cut}: warning: ") for w in warnings), result.stderr
    assert "ends before its footer" in warnings[0] and "Traceback" not in result.output
    out = json.loads(result.stdout)
    full = planning_rows(apf_log)
    compared = {n: d["ticks"] for n, d in out["drones"].items()}
    assert 0 < sum(compared.values()) < sum(full.values())
    assert all(d["first_divergence_tick"] is None for d in out["drones"].values()), out


@pytest.mark.parametrize("case", ["not-mcap", "missing", "no-mission", "sim-log", "missing-policy"])
def test_unreplayable_logs_are_one_line_and_exit_2(case: str, apf_log: Path, rpf_log: Path, tmp_path: Path) -> None:
    args: list[object] = []
    if case == "not-mcap":
        log = tmp_path / "x.mcap"
        log.write_text("not a log")
    elif case == "missing":
        log = tmp_path / "nowhere.mcap"
    elif case == "no-mission":
        log = copy_log(apf_log, tmp_path / "nomission.mcap", metadata={"mission": {"name": "short-3"}})
    elif case == "sim-log":
        mission = dict(read_log(apf_log).metadata["mission"], source="sim")
        log = copy_log(apf_log, tmp_path / "sim.mcap", metadata={"mission": mission})
    else:  # the mission names a policy that is nowhere to be found, and its SHA-256 matches no file around
        mission = dict(read_log(rpf_log).metadata["mission"], policy_sha256="0" * 64)
        mission["yaml"] = mission["yaml"].replace(str(RPF_POLICY), "gone/rpf.onnx")
        log = copy_log(rpf_log, tmp_path / "nopolicy.mcap", metadata={"mission": mission})
    result = replay(log, *args)
    assert result.exit_code == 2, result.output
    line = one_line(result)
    assert line.startswith(f"{log}: "), line
    expected = {
        "not-mcap": "",
        "missing": "",
        "no-mission": "mission.yaml",
        "sim-log": "mission.source",
        "missing-policy": "planner.policy",
    }[case]
    assert expected in line, line
    if case == "missing-policy":  # and with a planner of its own it replays all the same
        assert "--policy" in line
        ok = replay(log, "--planner", "apf", "--json")
        assert ok.exit_code == 0, ok.output
        assert json.loads(ok.stdout)["planner"] == "apf"


def test_the_flown_policy_is_found_by_its_hash_when_its_relative_path_does_not_resolve(
    rpf_log: Path, tmp_path: Path
) -> None:
    """missions/*.yaml name ``../policies/rpf.onnx`` relative to the mission's folder, which the log does not
    record: the replay finds the file with the logged SHA-256 instead (here: this checkout's policies/)."""
    mission = dict(read_log(rpf_log).metadata["mission"])
    mission["yaml"] = mission["yaml"].replace(str(RPF_POLICY), "../policies/rpf.onnx")
    log = copy_log(rpf_log, tmp_path / "relative.mcap", metadata={"mission": mission})
    setup = replay_setup(read_log(log))
    assert setup.mission.planner.policy == RPF_POLICY.resolve() and setup.same_as_flown


# ------------------------------------------------------------------------------------- mocap emulate --replay


@pytest.mark.parametrize("up_axis", ["z", "y"])
def test_emulate_replay_serves_the_logged_poses_over_natnet_at_their_logged_times(apf_log: Path, up_axis: str) -> None:
    """`rpf-fly mocap emulate --replay LOG` on 127.0.0.1 (its own process, unicast), read back with our NatNet
    client: every frame received is the logged frame of that number, to the float32 of the wire (a dry run's
    poses came in as float32, so exactly), and the frames keep their logged spacing (at 4x speed)."""
    frames = mocap_frames(read_log(apf_log))
    speed = 4.0
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "rpf_fly",
            "mocap",
            "emulate",
            "--replay",
            str(apf_log),
            "--unicast",
            "--command-port",
            "0",
            "--data-port",
            "0",
            "--replay-speed",
            str(speed),
            "--up-axis",
            up_axis,
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    received: list[tuple[int, float, dict]] = []
    try:
        first = proc.stdout.readline()
        assert "command port" in first, first + proc.stderr.read()
        port = int(first.split("command port ")[1].split(",")[0])
        with NatNetClient("127.0.0.1", multicast=False, command_port=port, up_axis=up_axis, keepalive_s=0.2) as client:
            assert client.wait_for_server(10.0)
            deadline = time.monotonic() + 60
            while proc.poll() is None and time.monotonic() < deadline:
                frame = client.receive(0.2)
                if frame is not None:
                    received.append((frame.frame_number, frame.capture_time_s, frame.bodies))
        out, _ = proc.communicate(timeout=10)
    finally:
        proc.kill()
    assert proc.returncode == 0
    assert f"replay done: {len(frames)} of {len(frames)} frames sent" in out
    # the client hands over the newest frame since the last call (as the flight wants), so a busy host skips some of
    # the 400 a second: a quarter of them, each checked exactly, and the span below, are the evidence (beside a
    # loaded suite 358 of 836 came through)
    assert len(received) >= max(100, 0.25 * len(frames)), (len(received), len(frames))
    worst = 0.0
    for number, _, bodies in received:
        logged = frames[number - 1].poses  # the emulator numbers the frames it sends from 1
        for name, body in bodies.items():
            assert body.valid == (name in logged), (number, name)
            if body.valid:
                expected = np.float32(logged[name][0]).astype(float)
                worst = max(worst, float(np.max(np.abs(np.array(body.position) - expected))))
    assert worst <= 1e-6, worst
    (n0, r0, _), (n1, r1, _) = received[0], received[-1]
    logged_span = (frames[n1 - 1].t_ns - frames[n0 - 1].t_ns) / 1e9 / speed
    # the frames keep their spacing, give or take how late the emulator says it sent them (a host that held it
    # back: beside a loaded suite its frames spanned 3.26 s for 2.48 s logged): the span of the frames' own
    # timestamps (the emulator's clock when it sent each), not of their receipt here, which a host that held this
    # process back stretches (0.39 s in a fresh clone's suite) whatever the emulator did
    late_s = float(re.search(r"latest ([0-9.]+) ms behind its time", out).group(1)) / 1e3
    assert logged_span > 1.0 and abs((r1 - r0) - logged_span) < 0.1 * logged_span + 0.05 + late_s, (
        r1 - r0,
        logged_span,
        late_s,
    )


def test_mocap_watch_reads_an_emulated_replay_back_to_1e_6(apf_log: Path) -> None:
    """The acceptance's round trip with the commands a user types: `mocap emulate --replay LOG` in its own process,
    `mocap watch --json` reading it; every frame watch prints is the logged frame of its number, to 1e-6."""
    frames = mocap_frames(read_log(apf_log))
    speed = 4.0
    span_s = (frames[-1].t_ns - frames[0].t_ns) / 1e9 / speed
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "rpf_fly",
            "mocap",
            "emulate",
            "--replay",
            str(apf_log),
            "--unicast",
            "--command-port",
            "0",
            "--data-port",
            "0",
            "--replay-speed",
            str(speed),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        first = proc.stdout.readline()
        assert "command port" in first, first + proc.stderr.read()
        port = first.split("command port ")[1].split(",")[0]
        watch = runner.invoke(
            get_app(),
            ["mocap", "watch", "--unicast", "--command-port", port, "--json", "--duration", f"{span_s + 2.0:.1f}"],
        )
        proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert watch.exit_code == 0, watch.output
    printed = [json.loads(line) for line in watch.stdout.splitlines()]
    assert len(printed) >= max(100, 0.25 * len(frames)), (len(printed), len(frames))  # newest-frame reads: as above
    worst = 0.0
    for obj in printed:
        logged = frames[obj["frame"] - 1].poses
        assert {n for n, b in obj["bodies"].items() if b["valid"]} == set(logged), obj["frame"]
        for name, (position, quaternion) in logged.items():
            body = obj["bodies"][name]
            worst = max(
                worst,
                float(np.max(np.abs(np.array(body["position"]) - np.asarray(position)))),
                float(np.max(np.abs(np.array(body["quaternion"]) - np.asarray(quaternion)))),
            )
    assert worst <= 1e-6, worst


def test_emulate_replay_of_a_log_without_mocap_is_one_line(apf_log: Path, tmp_path: Path) -> None:
    log = copy_log(apf_log, tmp_path / "nomocap.mcap", drop={f"/mocap/cf{i}" for i in (1, 2, 3)})
    result = runner.invoke(
        get_app(), ["mocap", "emulate", "--replay", str(log), "--unicast", "--command-port", "0", "--data-port", "0"]
    )
    assert result.exit_code == 2
    assert one_line(result) == f"{log}: no mocap poses (/mocap/<drone>) to serve"


def test_the_replay_rebuilds_the_flight_trackers_velocities_exactly(apf_log: Path) -> None:
    """What makes the reproduction exact, checked directly: the log's pose times are the tracker's own (on its
    1 us grid, through the logged integer clock offset), and every planning row says where it planned from."""
    data = read_log(apf_log)
    offset = int(data.metadata["mission"]["monotonic_offset_ns"])
    assert all((m.publish_time - offset) % 1000 == 0 for m in data.topics["/mocap/cf1"])
    planned = [m.data for m in data.topics["/cf1/planner"] if m.data["mode"] in PLANNING_MODES]
    assert planned and all("reference" in row for row in planned)
    assert not any("reference" in m.data for m in data.topics["/cf1/planner"] if m.data["mode"] not in PLANNING_MODES)


def test_a_log_from_before_the_replay_is_replayed_with_two_warnings(apf_log: Path) -> None:
    """Without the clock offset and the references (logs written before rpf-fly replay) the replay says so, and
    still starts each drone where the flight did at take-off: from its pose one frame before its first tick."""
    data = read_log(apf_log)
    del data.metadata["mission"]["monotonic_offset_ns"]
    for name in ("cf1", "cf2", "cf3"):
        topic = data.topics[f"/{name}/planner"]
        topic[:] = [m._replace(data={k: v for k, v in m.data.items() if k != "reference"}) for m in topic]
    setup = replay_setup(data)
    result = replay_log(data, setup.mission, setup.factory, tolerance=setup.tolerance)
    assert not result.exact_times
    assert any("monotonic_offset_ns" in w for w in result.warnings)
    assert any("without `reference`" in w for w in result.warnings)
    # this log's pose times are still the tracker's, only rebuilt from float seconds (1e-12 s off): a velocity from
    # two of them can differ in the last digits, so the directions agree to the replay's own tolerance, not bit-exact
    for name, drone in result.drones.items():
        # exact up to the drone's first hold: a hold (a loaded host can cause one) restarts it from where the
        # flight's reference was, which a log without references can only guess ("a guess after a hold")
        rows = data.topics[f"/{name}/planner"]
        first = next(m.log_time for m in rows if m.data.get("mode") in PLANNING_MODES)
        held = next((m.log_time for m in rows if m.log_time > first and m.data.get("mode") not in PLANNING_MODES), None)
        before = [t for t in drone.ticks if held is None or t.t_ns < held]
        assert len(before) > 10, (name, held, len(drone.ticks))
        exact = all(t.direction_diff < setup.tolerance and t.replayed_mode == t.logged_mode for t in before)
        assert exact, (name, drone.to_json())
        if drone.restarts == 1:  # no hold: the whole flight
            assert drone.first_divergence_tick is None and drone.max_direction_diff < setup.tolerance, (
                name,
                drone.to_json(),
            )


def test_pose_playback_sends_each_frame_at_its_time_and_stops_when_asked() -> None:
    """The pacing alone, on a fake clock: frame k goes out at start + (t_k - t_0) / speed, never skipped when late,
    with the frame's poses (all tracked; absent bodies are the server's to stream untracked)."""
    now = [100.0]
    sent: list[tuple[float, dict]] = []
    frames = [
        (5.0, {"cf1": ((0.0, 0.0, 0.5), (0, 0, 0, 1))}),
        (5.5, {"cf1": ((0.1, 0.0, 0.5), (0, 0, 0, 1))}),
        (6.5, {"cf2": ((1.0, 1.0, 0.5), (0, 0, 0, 1))}),
    ]
    playback = PosePlayback(frames, speed=2.0)

    class Server:
        def send_frame(self) -> int:
            sent.append((now[0], playback.poses()))
            return len(sent) + 40

    def sleep(s: float) -> None:
        now[0] += s

    assert playback.play(Server(), clock=lambda: now[0], sleep=sleep) == 3
    assert [round(t - 100.0, 9) for t, _ in sent] == [0.0, 0.25, 0.75]
    assert sent[2][1] == {"cf2": ((1.0, 1.0, 0.5), (0, 0, 0, 1), True)}
    assert playback.sent == [41, 42, 43] and playback.bodies == ["cf1", "cf2"] and playback.duration_s == 0.75
    stop = threading.Event()
    stop.set()
    assert PosePlayback(frames).play(Server(), stop, clock=lambda: now[0], sleep=sleep) == 0
    with pytest.raises(ValueError):
        PosePlayback(frames, speed=0)
