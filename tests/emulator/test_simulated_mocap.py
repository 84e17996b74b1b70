"""SimulatedMocap: rate, latency, noise, dropouts and seeding, on an injected clock (deterministic)."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from rpf_fly.emulator.simulated_mocap import SimulatedMocap
from rpf_fly.mocap.frame import MocapSource


class FakeClock:
    """A monotonic clock that only moves when slept on."""

    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        self.t += max(seconds, 1e-6)


def moving(clock: FakeClock):
    """cf1 moves along x at 1 m/s from x = 0 at t = 100; cf2 is never tracked."""

    def poses():
        return {
            "cf1": ((clock() - 100.0, 0.0, 1.0), (0.0, 0.0, 0.0, 1.0), True),
            "cf2": ((5.0, 5.0, 5.0), (0.0, 0.0, 0.0, 1.0), False),
        }

    return poses


def make(clock: FakeClock, **kwargs) -> SimulatedMocap:
    return SimulatedMocap(moving(clock), clock=clock, sleep=clock.sleep, **kwargs)


def test_is_a_mocap_source_and_paces_frames_at_the_rate():
    clock = FakeClock()
    with make(clock, rate_hz=50.0) as mocap:
        assert isinstance(mocap, MocapSource)
        numbers = [mocap.receive(1.0).frame_number for _ in range(10)]
        assert numbers == list(range(10))
        assert clock.t == pytest.approx(100.0 + 9 / 50.0)
        pose = mocap.receive(1.0).bodies["cf1"]
        assert pose.position == pytest.approx((10 / 50.0, 0.0, 1.0))
        assert pose.valid and pose.id == 1
    assert mocap.receive(1.0) is None  # closed


def test_latency_delays_delivery():
    clock = FakeClock()
    mocap = make(clock, rate_hz=100.0, latency_s=0.05)
    frame = mocap.receive(1.0)
    assert clock.t == pytest.approx(100.05)
    assert frame.frame_number == 0 and frame.bodies["cf1"].position[0] == pytest.approx(0.0)
    assert frame.latency_s == pytest.approx(0.05)
    assert frame.receive_time_s - frame.capture_time_s == pytest.approx(100.05)  # capture time is relative to t0
    assert mocap.receive(0.001) is None  # slot 1 was sampled at 100.01: not 50 ms old yet
    frame = mocap.receive(1.0)
    assert frame.frame_number == 1 and clock.t == pytest.approx(100.06)
    assert frame.bodies["cf1"].position[0] == pytest.approx(0.01)  # the pose of 50 ms ago


def test_newest_ready_frame_wins_and_the_rest_are_superseded():
    clock = FakeClock()
    mocap = make(clock, rate_hz=100.0, latency_s=0.05)
    assert mocap.receive(1.0).frame_number == 0  # slots 1..5 were sampled while waiting
    clock.t += 0.1  # the caller was busy: slots 1..5 are all ready now
    frame = mocap.receive(0.0)
    assert frame.frame_number == 5
    stats = mocap.stats
    assert (stats.delivered, stats.superseded) == (2, 4)
    assert mocap.receive(0.0) is None  # slot 15, sampled now, is not ready for 50 ms


def test_timeout_returns_none():
    clock = FakeClock()
    mocap = make(clock, rate_hz=10.0, latency_s=0.5)
    assert mocap.receive(0.2) is None
    assert clock.t == pytest.approx(100.2)


def test_noise_is_gaussian_with_the_requested_sigma_and_seeded():
    def run(seed):
        clock = FakeClock()
        frozen = {"cf1": ((1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0), True)}
        mocap = SimulatedMocap(
            lambda: frozen, rate_hz=1000.0, noise_m=0.01, noise_rad=0.02, seed=seed, clock=clock, sleep=clock.sleep
        )
        frames = [mocap.receive(1.0).bodies["cf1"] for _ in range(3000)]
        return np.array([f.position for f in frames]), np.array([f.quaternion for f in frames])

    positions, quaternions = run(3)
    assert positions.mean(axis=0) == pytest.approx([1.0, 2.0, 3.0], abs=0.001)
    assert positions.std(axis=0) == pytest.approx([0.01, 0.01, 0.01], rel=0.06)
    assert np.allclose(np.linalg.norm(quaternions, axis=1), 1.0)
    angles = 2.0 * np.arccos(np.clip(np.abs(quaternions[:, 3]), -1, 1))
    assert np.sqrt(np.mean(angles**2)) == pytest.approx(0.02 * math.sqrt(3), rel=0.08)
    again, _ = run(3)
    other, _ = run(4)
    assert np.array_equal(positions, again) and not np.array_equal(positions, other)


def test_dropouts_are_per_body_per_frame_and_hold_the_last_pose():
    clock = FakeClock()
    mocap = make(clock, rate_hz=100.0, dropout=0.3, seed=11)
    invalid = 0
    last_valid_x = None
    n = 2000
    for _ in range(n):
        frame = mocap.receive(1.0)
        pose = frame.bodies["cf1"]
        assert not frame.bodies["cf2"].valid  # untracked in the truth stays untracked
        if pose.valid:
            last_valid_x = pose.position[0]
        else:
            invalid += 1
            assert pose.position[0] == (last_valid_x if last_valid_x is not None else 0.0)
    assert invalid / n == pytest.approx(0.3, abs=0.03)
    assert mocap.stats.body_dropouts == invalid + n  # cf2 every frame
    assert frame.bodies["cf2"].position == (0.0, 0.0, 0.0)  # never seen valid: origin, identity


def test_real_clock_does_not_spin():
    mocap = SimulatedMocap(lambda: {}, rate_hz=20.0, latency_s=0.0)
    mocap.receive(1.0)
    start_cpu, start = time.process_time(), time.monotonic()
    frame = mocap.receive(1.0)
    assert frame is not None and frame.bodies == {}
    assert 0.02 < time.monotonic() - start < 0.2  # waited for the next 20 Hz slot ...
    assert time.process_time() - start_cpu < 0.02  # ... asleep, not spinning


@pytest.mark.parametrize("kwargs", [{"rate_hz": 0}, {"noise_m": -1}, {"dropout": 1.5}, {"latency_s": -0.1}])
def test_rejects_bad_parameters(kwargs):
    with pytest.raises(ValueError):
        SimulatedMocap(lambda: {}, **kwargs)
