"""The dry run's mocap is as imperfect as a real room's: jitter on position and orientation, and a body now and
then untracked for a frame (rpf_fly/emulator/mocap_noise.py), with the figures it documents."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest

from rpf_fly.emulator.fake_world import FakeDroneConfig, FakeWorld
from rpf_fly.emulator.mocap_noise import MocapNoise
from rpf_fly.emulator.simulated_bodies import SimulatedBodies


def test_the_jitter_and_the_dropouts_have_the_documented_figures():
    noise = MocapNoise(position_m=0.0005, orientation_deg=0.5, dropout=0.001)
    rng = random.Random(1)
    true_q = (0.0, 0.0, math.sin(0.3), math.cos(0.3))
    samples = [noise.apply(rng, (1.0, -2.0, 0.5), true_q) for _ in range(100_000)]
    positions = np.array([p for p, _, _ in samples])
    assert positions.mean(axis=0) == pytest.approx((1.0, -2.0, 0.5), abs=2e-5)
    assert positions.std(axis=0) == pytest.approx([0.0005] * 3, rel=0.03)
    angles = np.array(
        [math.degrees(2 * math.acos(min(1.0, abs(sum(a * b for a, b in zip(q, true_q)))))) for _, q, _ in samples]
    )
    # the angle of a rotation with 0.5 degrees per axis: a chi distribution of 3 degrees of freedom
    assert np.sqrt(np.mean(angles**2)) == pytest.approx(0.5 * math.sqrt(3), rel=0.03)
    assert angles.max() < 5.0
    dropped = sum(not tracked for _, _, tracked in samples)
    assert 60 <= dropped <= 140  # 0.1 % of 100 000


def test_no_noise_serves_the_truth_exactly():
    noise = MocapNoise(0.0, 0.0, 0.0)
    assert noise.off and noise.apply(random.Random(0), (1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0)) == (
        (1.0, 2.0, 3.0),
        (0.0, 0.0, 0.0, 1.0),
        True,
    )


def test_the_served_poses_carry_it_with_each_dry_runs_seed():
    world = FakeWorld({0xE7E7E7E701: FakeDroneConfig.at(0.5, 0.0)})
    noisy = SimulatedBodies(world, {0xE7E7E7E701: "cf1"}, MocapNoise(0.001, 1.0, 0.0), seed=3)
    again = SimulatedBodies(world, {0xE7E7E7E701: "cf1"}, MocapNoise(0.001, 1.0, 0.0), seed=3)
    other = SimulatedBodies(world, {0xE7E7E7E701: "cf1"}, MocapNoise(0.001, 1.0, 0.0), seed=4)
    a, b, c = noisy.poses()["cf1"], again.poses()["cf1"], other.poses()["cf1"]
    assert a == b and a != c  # seeded
    assert a[0] != (0.5, 0.0, 0.0) and math.dist(a[0], (0.5, 0.0, 0.0)) < 0.01 and a[2]
