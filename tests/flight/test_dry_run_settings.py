"""The mission's ``dry_run`` section reaches the simulated room: its mocap jitter is what the NatNet client
receives over UDP from the emulator, and its seed draws the simulated world."""

from __future__ import annotations

import time

import numpy as np
from flight_harness import SHORT_MISSION

from rpf_fly.flight.dry_run import DryRun
from rpf_fly.mission import parse_mission


def served_positions(text: str, frames: int = 60) -> tuple[DryRun, np.ndarray]:
    mission = parse_mission(text)
    with DryRun(mission) as rig:
        seen: list[tuple[float, float, float]] = []
        deadline = time.monotonic() + 10.0
        while len(seen) < frames and time.monotonic() < deadline:
            frame = rig.mocap.receive(0.1)
            if frame is not None and "cf1" in frame.bodies and frame.bodies["cf1"].valid:
                seen.append(frame.bodies["cf1"].position)
    return rig, np.array(seen)


def test_the_missions_mocap_jitter_is_served_by_the_natnet_emulator():
    rig, loud = served_positions(SHORT_MISSION + "dry_run: {seed: 5, mocap_noise_m: 0.01}\n")
    assert rig.seed == 5 and len(loud) >= 60
    _, quiet = served_positions(SHORT_MISSION)  # the emulator's 0.5 mm
    assert 0.006 < float(loud[:, 0].std()) < 0.015  # a standing drone: the spread is the jitter
    assert float(quiet[:, 0].std()) < 0.0015
