"""A dry run's log carries the simulated world's truth (``/truth/<drone>``), and the dry run's world knows the
mission's obstacles (a drone flown into one crashes there)."""

from __future__ import annotations

import json
import threading
import time

import numpy as np
import pytest
from cflib.crazyflie import Crazyflie
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie
from flight_harness import SHORT_MISSION, fly, fly_on_time
from test_dry_run_flight import validate_every_message
from typer.testing import CliRunner

from rpf_fly.cli import get_app
from rpf_fly.emulator.mocap_noise import POSITION_NOISE_M
from rpf_fly.flight.dry_run import DryRun
from rpf_fly.flight.phases import FlightOutcome
from rpf_fly.log.review import review
from rpf_fly.mission import parse_mission

NAMES = ("cf1", "cf2", "cf3")
MOCAP_LATENCY_MAX_S = 0.3
"""From a world step to the loop logging the mocap frame that carried it, at most (loaded 2-core machine)."""


def series(messages, key: str) -> tuple[np.ndarray, np.ndarray]:  # type: ignore[no-untyped-def]
    """Publish times (s) and ``(n, 3)`` positions of PoseInFrame (``key="pose"``) or TruthState messages."""
    t = np.array([m.publish_time for m in messages], dtype=np.int64) / 1e9
    if key == "pose":
        p = [m.data["pose"]["position"] for m in messages]
    else:
        p = [m.data[key] for m in messages]
    return t, np.array([[q["x"], q["y"], q["z"]] for q in p])


def test_dry_run_log_has_the_truth_of_every_drone(tmp_path, short_mission):
    flight = fly_on_time(short_mission, tmp_path)  # a flight the host held back drifts its estimators: not judged
    assert flight.report.success, flight.report.reasons
    validate_every_message(flight.log_path)  # every /truth message against rpf_fly.TruthState, with the rest
    stats = {t.topic: t for t in review(flight.log).topics}
    for name in NAMES:
        truth = flight.log.messages(f"/truth/{name}")
        mocap = flight.log.messages(f"/mocap/{name}")
        assert flight.log.schemas[f"/truth/{name}"] == "rpf_fly.TruthState"
        t_truth, p_truth = series(truth, "position")
        t_mocap, p_mocap = series(mocap, "pose")
        # At 50 Hz or more over the whole flight: from before the first mocap pose to after the last one.
        assert t_truth[0] < t_mocap[0] and t_truth[-1] > t_mocap[-1]
        assert (len(truth) - 1) / (t_truth[-1] - t_truth[0]) >= 50.0, name
        assert stats[f"/truth/{name}"].rate_hz >= 50.0  # as the review measures it (on log time)
        assert np.diff(t_truth).max() < 0.25  # no gap (the world catches up when late; a loaded machine stalls it)
        assert all(m.log_time == m.publish_time for m in truth)
        assert [m.sequence for m in truth] == list(range(len(truth)))  # nothing dropped
        # Truth (the world), not mocap: the tracked poses agree with it within a few cm at the mocap's times (a
        # pose is logged when the loop handles its frame, a few ms after the world was there) ...
        error = np.linalg.norm(
            p_mocap - np.column_stack([np.interp(t_mocap, t_truth, p_truth[:, k]) for k in range(3)]), axis=1
        )
        assert np.median(error) < 0.01 and np.percentile(error, 95) < 0.05, (name, np.percentile(error, 95))
        # ... and each is, to NatNet's float32 and the emulated room's jitter (0.5 mm per axis: 3.5 mm is seven of
        # it), the truth of one world step shortly before: the emulator serves the world's state, the latency is the
        # pipeline's (a busy machine delays frames by tens of ms).
        jitter = 7 * POSITION_NOISE_M
        for t, p in zip(t_mocap, p_mocap):
            lo, hi = np.searchsorted(t_truth, [t - MOCAP_LATENCY_MAX_S, t + 0.001])
            assert hi > lo and np.linalg.norm(p_truth[lo:hi] - p, axis=1).min() < 1e-3 + jitter, (name, t - t_mocap[0])
        # In the air with the motors on, every world step until the landing plan ends: the hand-over to the landing
        # sends the land before notify-setpoint-stop, so the firmware tick between the two packets holds the last
        # setpoint (docs/radio.md). The firmware stops the motors when its landing plan ends, wherever the drone is
        # (the cascade trails the plan: from 0.5 m in 1 s it is still 0.2 m up), and they stay off.
        flying = p_truth[:, 2] > 0.1
        motors = np.array([m.data["motors"] for m in truth])
        on = np.flatnonzero(motors)
        cut = on[-1] + 1
        assert flying.sum() > 150 and motors[on[0] : cut].all() and not motors[cut:].any()
        landing = min(
            m.publish_time / 1e9
            for m in flight.log.messages("/events")
            if m.data["name"] == name and m.data["message"].startswith("landing")
        )
        assert t_truth[cut] >= landing + short_mission.flight.land_s - 0.05, (name, t_truth[cut] - landing)
        assert not any(m.data["crashed"] for m in truth)
        _, estimate = series(truth, "estimate")  # the firmware's estimate, fed by the mocap, stays on the truth
        offset = np.linalg.norm(estimate[flying] - p_truth[flying], axis=1)  # (as late as the mocap: a lag)
        assert np.median(offset) < 0.02 and offset.max() < 0.1, (name, np.median(offset), offset.max())
        assert -np.pi <= min(m.data["yaw"] for m in truth) and max(m.data["yaw"] for m in truth) <= np.pi
    # `rpf-fly review` reads such a log: summary (with the truth topics), metrics, CSV and the figure.
    runner = CliRunner()
    result = runner.invoke(
        get_app(),
        ["review", str(flight.log_path), "--csv", str(tmp_path / "csv"), "--plot", str(tmp_path / "review.png")],
    )
    assert result.exit_code == 0, result.output
    assert "/truth/cf1" in result.stdout and (tmp_path / "csv" / "truth_cf3.csv").stat().st_size > 10_000
    result = runner.invoke(get_app(), ["review", str(flight.log_path), "--json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["success"] is True


@pytest.mark.parametrize("process", [True, False], ids=["world-process", "in-process"])
def test_the_dry_run_world_has_the_mission_obstacles(short_mission, process):
    """short-3's pole at (0, 0.9), r = 0.1: cf3 (start (-1, 0.6)) flown at it by a plain cflib script crashes on it;
    the others, on the floor, do not; the truth says so, keyed by drone name. The script feeds cf3's estimator
    with extpos from its true position at 50 Hz, as a mocap script does: without it the estimate drifts (the IMU's
    bias, 0.1-0.4 m in 3 s) and the drone may pass beside the pole."""
    with DryRun(short_mission, mocap="sim", process=process) as rig:
        rig.truth_samples()
        with SyncCrazyflie(rig.uris["cf3"], cf=Crazyflie(rw_cache=str(rig.cache_dir))) as scf:
            feeding = threading.Event()

            def feed_extpos() -> None:
                while not feeding.is_set():
                    scf.cf.extpos.send_extpos(*rig.snapshot("cf3").position)
                    feeding.wait(0.02)

            feeder = threading.Thread(target=feed_extpos, daemon=True)
            feeder.start()
            try:
                time.sleep(0.5)  # the estimate settles on the truth
                scf.cf.high_level_commander.takeoff(0.5, 1.0)
                time.sleep(1.2)
                scf.cf.high_level_commander.go_to(0.0, 0.9, 0.5, 0.0, 2.0)  # at the pole's axis
                deadline = time.monotonic() + 5.0
                while not rig.snapshot("cf3").crashed and time.monotonic() < deadline:
                    time.sleep(0.02)
                time.sleep(0.5)
            finally:
                feeding.set()
                feeder.join(1.0)
        snap = rig.snapshot("cf3")
        assert snap.crash_reason == "obstacle" and snap.locked and snap.position[2] == 0.0
        assert np.hypot(snap.position[0], snap.position[1] - 0.9) == pytest.approx(0.1 + 0.065, abs=0.012)
        assert not rig.snapshot("cf1").crashed and not rig.snapshot("cf2").crashed
        samples = rig.truth_samples()
        assert samples and all(set(states) == set(NAMES) for _, states in samples)
        position, _, motors, crashed, _ = samples[-1][1]["cf3"]
        assert crashed and not motors and position == snap.position


def test_a_crash_in_a_dry_run_is_in_the_truth(tmp_path):
    """cf2 pushed into short-3's pole mid-flight crashes there; the log's truth shows the crash, motors off, the
    fall and the wreck where it fell; the others fly on. The supervisor notices the crash (cf2 `emergency`), so the
    flight ends once cf1 and cf3 are at their goals (about 7 s on an idle machine). The timeout is the mission's 30 s:
    10 s, set here when a crashed drone ran into it, failed a clean-clone CI run on a loaded machine (cf1 and cf3
    still on their way at 10 s, no event holding them)."""
    mission = parse_mission(SHORT_MISSION)

    def push(loop, rig):  # type: ignore[no-untyped-def]
        deadline = time.monotonic() + 10.0
        while abs(rig.snapshot("cf2").position[0]) > 0.05 and time.monotonic() < deadline:
            time.sleep(0.005)
        rig.world.disturb(rig.addresses["cf2"], (0.0, 0.9, 0.0))  # from (0, 0) through the pole at (0, 0.9)

    flight = fly(mission, tmp_path, when_flying=push)
    snap = flight.snapshots["cf2"]
    assert snap.crashed and snap.crash_reason == "obstacle" and snap.locked and snap.position[2] == 0.0
    assert flight.report.outcomes["cf1"] == flight.report.outcomes["cf3"] == FlightOutcome.REACHED, (
        flight.report.reasons
    )
    truth = [m.data for m in flight.log.messages("/truth/cf2")]
    crashed = [d["crashed"] for d in truth]
    first = crashed.index(True)
    assert not any(crashed[:first]) and all(crashed[first:])  # once crashed, crashed for good
    assert truth[first - 1]["motors"] and not any(d["motors"] for d in truth[first:])
    fall = [d["position"]["z"] for d in truth[first:]]
    assert fall[0] > 0.4 and fall == sorted(fall, reverse=True) and fall[-1] == 0.0
    assert abs(np.hypot(truth[first]["position"]["x"], truth[first]["position"]["y"] - 0.9) - 0.165) < 0.012
    final = truth[-1]["position"]
    assert (final["x"], final["y"], final["z"]) == snap.position  # the wreck lies where it fell
    assert not any(m.data["crashed"] for n in ("cf1", "cf3") for m in flight.log.messages(f"/truth/{n}"))
    validate_every_message(flight.log_path)
