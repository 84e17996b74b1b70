"""The planning-tick schedule: ticks fire on mocap frames, at the mission rate, and keep streaming without mocap.

Driven on a virtual time line the way the flight loop drives it: wait for the next frame until the window's end,
then ask whether the tick is due."""

from __future__ import annotations

import random

import pytest

from rpf_fly.flight.ticks import TickSchedule

DT = 0.01


def run(schedule: TickSchedule, frames: list[float], until: float) -> list[tuple[float, bool]]:
    """(time, on a frame) of every tick fired before ``until``."""
    ticks: list[tuple[float, bool]] = []
    now, i = schedule.due_s, 0
    while now < until:
        wait_until = schedule.window_end_s
        if i < len(frames) and frames[i] <= max(wait_until, now):
            now, have_frame = max(now, frames[i]), True
            i += 1
        else:
            now, have_frame = max(now, wait_until), False
        if schedule.is_due(now, have_frame):
            schedule.fired(now, have_frame)
            ticks.append((now, have_frame))
    return ticks


def frames_at(rate_hz: float, offset_s: float, until: float, jitter_s: float = 0.0, seed: int = 0) -> list[float]:
    rng = random.Random(seed)
    n = int(until * rate_hz) + 2
    return sorted(offset_s + k / rate_hz + rng.uniform(-jitter_s, jitter_s) for k in range(n))


@pytest.mark.parametrize("offset_periods", [0.0, 0.3, 0.49, 0.51, 0.7, 0.99])
def test_matched_rates_tick_on_every_frame_the_moment_it_arrives(offset_periods):
    frames = frames_at(100.0, offset_periods * DT, 10.0)
    ticks = run(TickSchedule(DT, 0.0), frames, 10.0)
    assert abs(len(ticks) - 1000) <= 2
    settled = ticks[5:]
    assert all(on_frame for _, on_frame in settled)
    arrivals = set(frames)
    assert all(t in arrivals for t, _ in settled)


def test_jitter_at_the_window_edge_locks_onto_the_frames():
    # Frames arrive around the first window's end: without the phase lock the ticks would alternate between
    # frames and deadlines (planning on a pose up to a period old).
    frames = frames_at(100.0, 0.5 * DT, 10.0, jitter_s=0.0005)
    schedule = TickSchedule(DT, 0.0)
    ticks = run(schedule, frames, 10.0)
    assert abs(len(ticks) - 1000) <= 2
    assert sum(not on_frame for _, on_frame in ticks[50:]) == 0
    assert schedule.frameless <= 3


def test_faster_mocap_keeps_the_mission_rate():
    frames = frames_at(120.0, 0.003, 10.0)
    ticks = run(TickSchedule(DT, 0.0), frames, 10.0)
    assert abs(len(ticks) - 1000) <= 2
    assert all(on_frame for _, on_frame in ticks)
    intervals = [b[0] - a[0] for a, b in zip(ticks, ticks[1:])]
    assert min(intervals) > 0.004 and max(intervals) < 0.017


def test_slower_mocap_fills_the_gaps_with_frameless_ticks():
    frames = frames_at(50.0, 0.002, 10.0)
    schedule = TickSchedule(DT, 0.0)
    ticks = run(schedule, frames, 10.0)
    assert abs(len(ticks) - 1000) <= 2
    assert 450 <= schedule.frameless <= 550


def test_mocap_lost_ticks_keep_streaming_at_the_period():
    frames = [f for f in frames_at(100.0, 0.004, 3.0) if f < 1.0]
    schedule = TickSchedule(DT, 0.0)
    ticks = run(schedule, frames, 3.0)
    after = [t for t, on_frame in ticks if t > 1.02]
    assert not any(on_frame for t, on_frame in ticks if t > 1.02)
    intervals = [b - a for a, b in zip(after, after[1:])]
    assert intervals and max(intervals) == pytest.approx(DT) and min(intervals) == pytest.approx(DT)
    assert abs(len(ticks) - 300) <= 2


def test_a_tick_more_than_a_period_late_is_an_overrun_and_restarts_the_grid():
    schedule = TickSchedule(DT, 0.0)
    schedule.fired(0.0, True)
    assert schedule.due_s == pytest.approx(DT)
    schedule.fired(0.05, False)  # four periods late
    assert schedule.overruns == 1 and schedule.frameless == 1
    assert schedule.due_s == pytest.approx(0.06) and schedule.phase_s == 0.0
    assert not schedule.is_due(0.052, True)  # a frame before the next window does not fire it
    assert schedule.is_due(0.056, True)
    assert schedule.is_due(0.065, False)
