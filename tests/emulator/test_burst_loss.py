"""Bursty radio loss (`BurstLoss`, a Gilbert-Elliott channel per link): the attempts it loses come in bursts, unlike
independent loss of the same mean; its long-run rate is the configured one; cflib's link quality dips in the bursts;
it is seeded per world seed and drone; the runtime ``packet_loss`` fault hook overrides it while it lasts; a dry run
has it by default. Figures: docs/radio.md, "Bursty loss"."""

from __future__ import annotations

import bisect
import statistics
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from cflib.crazyflie import Crazyflie
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie

from rpf_fly.emulator.burst_loss import BurstLoss
from rpf_fly.emulator.dongle_air import RadioTiming
from rpf_fly.emulator.fake_world import FakeDroneConfig, FakeWorld, LinkFaults
from rpf_fly.flight.dry_run import RADIO_LOSS, DryRun
from rpf_fly.mission import parse_mission

A = 0xE7E7E7E701
MakeWorld = Callable[..., FakeWorld]

SYNTHETIC_S = 400.0
"""Synthetic seconds of radio traffic the statistics tests draw (about 400 bursts with the defaults)."""
PERIOD_S = 0.002
"""One transaction every 2 ms: about what a streaming dry-run link carries (setpoints, extpos, log, polls)."""


class SyntheticClock:
    """A world's clock set by the test, so hundreds of seconds of transactions take a second to draw."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def synthetic_world(faults: LinkFaults, seed: int = 0) -> tuple[FakeWorld, SyntheticClock]:
    """A world (never started: no dynamics thread) whose drone's radio is driven at synthetic times."""
    world = FakeWorld({A: FakeDroneConfig.at(0.0, 0.0, faults=faults)}, seed=seed)
    clock = SyntheticClock()
    world.time_s = clock  # type: ignore[method-assign]
    return world, clock


def attempts(
    world: FakeWorld, clock: SyntheticClock, seconds: float, start_s: float = 0.0
) -> list[tuple[float, bool, bool]]:
    """(world time, lost, first) of every radio attempt of empty polls every `PERIOD_S` through the drone's real
    `DronePort.transact`: an acknowledged transaction that used ``r`` retries lost ``r`` attempts first, a lost one
    all of its 4; ``first``: the transaction's first attempt (made at an arbitrary moment, unlike its retries,
    which crowd into the bursts)."""
    port = world.port(A)
    assert port is not None
    out: list[tuple[float, bool, bool]] = []
    for i in range(round(seconds / PERIOD_S)):
        t = clock.now = start_s + i * PERIOD_S
        ok, retry, _ = port.transact(80, None)
        lost = retry + (0 if ok else 1)
        out += [(t, n < lost, n == 0) for n in range(retry + 1)]
    return out


def first_attempt_loss(drawn: list[tuple[float, bool, bool]]) -> float:
    """The share of first attempts lost: the probability that an attempt at a random moment is lost."""
    firsts = [lost for _, lost, first in drawn if first]
    return sum(firsts) / len(firsts)


def run_lengths(lost: list[bool]) -> list[int]:
    runs, run = [], 0
    for x in lost:
        if x:
            run += 1
        elif run:
            runs.append(run)
            run = 0
    return runs


def lag1_autocorrelation(lost: list[bool]) -> float:
    mean = sum(lost) / len(lost)
    values = [float(x) - mean for x in lost]
    variance = sum(v * v for v in values) / len(values)
    return sum(a * b for a, b in zip(values, values[1:])) / (len(values) - 1) / variance


def test_bursty_loss_comes_in_bursts_at_the_configured_long_run_rate() -> None:
    model = BurstLoss()
    world, clock = synthetic_world(LinkFaults(burst=model))
    drawn = attempts(world, clock, SYNTHETIC_S)
    lost = [x for _, x, _ in drawn]
    rate = sum(lost) / len(lost)  # retries included: they crowd into the bursts, so more of them are lost
    assert model.mean_loss == pytest.approx(0.0272, abs=1e-4)  # the documented figures
    assert model.retried_loss(3) == pytest.approx(0.0458, abs=1e-4)
    assert first_attempt_loss(drawn) == pytest.approx(model.mean_loss, rel=0.15)
    assert rate == pytest.approx(model.retried_loss(3), rel=0.15)
    runs = run_lengths(lost)
    independent_run = 1.0 / (1.0 - rate)  # mean run of lost attempts if each were lost on its own (geometric)
    assert statistics.mean(runs) > 1.5 * independent_run  # measured 1.8 times (8 seeds)
    assert (
        sum(r >= 4 for r in runs) / len(runs) > 100 * rate**3
    )  # independent loss: p^3 of the runs; 1200-1800 times that
    assert lag1_autocorrelation(lost) > 0.3  # 0.44-0.46
    # the losses are where the channel is bad: 60 % of attempts inside the bursts, 1 % outside
    bursts = world.radio_bursts(A, 0.0, SYNTHETIC_S)
    assert len(bursts) == pytest.approx(SYNTHETIC_S / (model.mean_good_s + model.mean_bad_s), rel=0.15)
    assert statistics.mean(b - a for a, b in bursts) == pytest.approx(model.mean_bad_s, rel=0.15)
    inside = [x for t, x, _ in drawn if any(a <= t < b for a, b in bursts_near(bursts, t))]
    outside_rate = (sum(lost) - sum(inside)) / (len(lost) - len(inside))
    assert sum(inside) / len(inside) == pytest.approx(model.bad_loss, abs=0.05)
    assert outside_rate == pytest.approx(model.good_loss, abs=0.005)
    counters = world.radio_counters(A)
    assert counters.lost_attempts == sum(lost)  # the counters cflib's side never sees agree with the draws


def bursts_near(bursts: list[tuple[float, float]], t: float) -> list[tuple[float, float]]:
    """The burst that could contain ``t`` (the list is sorted by start)."""
    i = bisect.bisect_right([a for a, _ in bursts], t)
    return bursts[max(0, i - 1) : i]


def test_independent_loss_of_the_same_mean_is_not_bursty() -> None:
    """The control of the test above: its burst measures tell the two models apart."""
    world, clock = synthetic_world(LinkFaults(packet_loss=BurstLoss().mean_loss))
    drawn = attempts(world, clock, SYNTHETIC_S / 2)
    lost = [x for _, x, _ in drawn]
    rate = sum(lost) / len(lost)
    assert first_attempt_loss(drawn) == pytest.approx(BurstLoss().mean_loss, rel=0.1)
    assert statistics.mean(run_lengths(lost)) == pytest.approx(1.0 / (1.0 - rate), rel=0.05)
    assert abs(lag1_autocorrelation(lost)) < 0.02
    assert world.radio_bursts(A, 0.0, 100.0) == []


def test_the_bursts_are_seeded_by_the_world_seed_and_drone() -> None:
    faults = LinkFaults(burst=BurstLoss())
    one = FakeWorld({A: FakeDroneConfig(faults=faults), A + 1: FakeDroneConfig(faults=faults)}, seed=7)
    again = FakeWorld({A: FakeDroneConfig(faults=faults)}, seed=7)
    other = FakeWorld({A: FakeDroneConfig(faults=faults)}, seed=8)
    bursts = one.radio_bursts(A, 0.0, 60.0)
    assert len(bursts) > 20
    assert again.radio_bursts(A, 0.0, 60.0) == bursts
    assert again.radio_bursts(A, 10.0, 20.0) == one.radio_bursts(A, 10.0, 20.0)  # any window, any order
    assert other.radio_bursts(A, 0.0, 60.0) != bursts
    assert one.radio_bursts(A + 1, 0.0, 60.0) != bursts  # each link its own channel


def test_the_packet_loss_hook_overrides_the_bursts_while_it_lasts() -> None:
    world, clock = synthetic_world(LinkFaults(burst=BurstLoss()))
    clock.now = 10.0
    world.packet_loss(A, 0.3, 100.0)  # independent 30 % for 100 s, bursts or not
    during = attempts(world, clock, 100.0, start_s=10.0)
    lost = [x for _, x, _ in during]
    assert sum(lost) / len(lost) == pytest.approx(0.3, abs=0.01)
    assert abs(lag1_autocorrelation(lost)) < 0.02  # no bursts while the fault lasts
    after = attempts(world, clock, 200.0, start_s=110.0)  # expired: the bursts are back
    assert first_attempt_loss(after) == pytest.approx(BurstLoss().mean_loss, rel=0.3)
    assert lag1_autocorrelation([x for _, x, _ in after]) > 0.2


def test_link_quality_dips_in_the_bursts(make_world: MakeWorld, toc_cache: Path) -> None:
    """Real cflib over the fake radio, a drone with the default bursts and an extpos stream at 100 Hz: cflib's link
    quality (its `RadioLinkStatistics`, 10 points a retry over the last 100 acks) falls in the bursts, far more
    often than between them, and dips below 100 % without nearing the supervisor's 96 % warning."""
    model = BurstLoss()
    world = make_world(
        {A: FakeDroneConfig.at(0.0, 0.0, faults=LinkFaults(burst=model))},
        seed=3,
        timing=RadioTiming(transaction_s=0.001),
    )
    quality: list[tuple[float, float]] = []
    with SyncCrazyflie(world.uri(A), cf=Crazyflie(rw_cache=str(toc_cache))) as scf:
        scf.cf.link_statistics.link_quality_updated.add_callback(lambda q: quality.append((world.time_s(), q)))
        stop = threading.Event()

        def stream() -> None:
            while not stop.wait(0.01):
                scf.cf.extpos.send_extpos(0.0, 0.0, 0.0)

        streamer = threading.Thread(target=stream, daemon=True)
        streamer.start()
        time.sleep(1.0)  # cflib averages over the last 100 acks: fewer right after connecting make bigger steps
        start, before = world.time_s(), world.radio_counters(A)
        time.sleep(7.0)
        end, after = world.time_s(), world.radio_counters(A)
        stop.set()
        streamer.join(2.0)
    bursts = world.radio_bursts(A, start, end)
    assert len(bursts) >= 2
    window = [(t, q) for t, q in quality if start <= t <= end]
    falls = [t for (_, q0), (t, q1) in zip(window, window[1:]) if q1 < q0 - 1e-9]
    in_burst = [t for t in falls if any(a <= t <= b + 0.005 for a, b in bursts)]
    burst_s = sum(b - a + 0.005 for a, b in bursts)
    rate_in, rate_out = len(in_burst) / burst_s, (len(falls) - len(in_burst)) / (end - start - burst_s)
    assert in_burst and rate_in > 10 * rate_out, (rate_in, rate_out)
    values = [q for _, q in window]
    assert min(values) < 100.0 and min(values) > 97.0  # a dip, not a warning
    lost = after.lost_attempts - before.lost_attempts
    sent = after.transactions - before.transactions + lost
    assert 0.01 < lost / sent < 0.12  # 5.6-7.5 % measured: lost transactions are sent again, in the burst


MISSION = """\
name: burst-1
arena: {x: [-2.0, 2.0], y: [-2.0, 2.0], z: [0.0, 1.5]}
flight: {height: 0.5, speed: 0.5, rate_hz: 10, goal_tolerance: 0.1, takeoff_s: 1.0, land_s: 1.0, timeout_s: 30}
planner: {kind: apf, margin: 0}
mocap: {kind: sim, rate_hz: 100}
drones:
  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [0.5, -0.5], goal: [1.0, -0.5]}
"""


def test_a_dry_run_has_the_bursts_by_default_in_its_child_process(toc_cache: Path) -> None:
    """The default reaches the simulated drones' process with their settings, with the same bursts as a world in
    this process of the same seed; ``radio_loss=None`` turns it off."""
    mission = parse_mission(MISSION)
    with DryRun(mission, mocap="sim", cache_dir=toc_cache, seed=5) as rig:
        bursts = rig.world.radio_bursts(A, 0.0, 30.0)
        assert rig.drone_configs[A].faults.burst == RADIO_LOSS == BurstLoss()
    local = FakeWorld({A: FakeDroneConfig.at(0.5, -0.5, faults=LinkFaults(burst=RADIO_LOSS))}, seed=5)
    assert len(bursts) > 10 and bursts == local.radio_bursts(A, 0.0, 30.0)
    with DryRun(mission, mocap="sim", cache_dir=toc_cache, radio_loss=None) as rig:
        assert rig.world.radio_bursts(A, 0.0, 30.0) == [] and rig.drone_configs[A].faults.burst is None
