"""A piped link (rpf_fly/emulator/piped_port.py): each transaction with a drone of the child's world decided in this
process from the world's own figures and state, recorded in the child, the drone's answers pushed back; no round
trip per transaction."""

from __future__ import annotations

import os
import signal

import pytest
from polling import wait_for

from rpf_fly.emulator.burst_loss import BurstLoss
from rpf_fly.emulator.crtp import PORT_PARAM
from rpf_fly.emulator.fake_world import FakeDroneConfig, LinkFaults
from rpf_fly.emulator.piped_port import PipedPort
from rpf_fly.emulator.remote_world import RemoteWorld
from rpf_fly.emulator.world_process import WorldProcess

A1 = 0xE7E7E7E701
NULL = None
TOC_INFO = ((PORT_PARAM << 4) | 0x0C, bytes((3,)))
"""A parameter TOC info request (CMD_TOC_INFO_V2 on the TOC channel): the firmware answers it with one packet."""


@pytest.fixture
def world():  # type: ignore[no-untyped-def]
    process = WorldProcess({A1: FakeDroneConfig.at(0.0, 0.0)}, {A1: "cf1"}, natnet=None)
    yield process
    process.close()


def piped(process: WorldProcess) -> PipedPort:
    port = RemoteWorld(process.radio, process.addresses, piped=True).port(A1)
    assert isinstance(port, PipedPort)
    return port


def test_transactions_are_counted_in_the_child_and_answers_come_back_on_later_acknowledgements(world) -> None:
    port = piped(world)
    try:
        acked, _, down = port.transact(80, TOC_INFO)
        assert acked and down is None  # the answer is not ready when its own packet is acknowledged
        answers = []
        assert wait_for(lambda: answers.append(port.transact(80, NULL)[2]) or any(answers), 5.0)
        port_, channel, payload = next(a for a in answers if a is not None)
        assert (port_, channel, payload[:1]) == (PORT_PARAM, 0, bytes((3,)))
        sent = 1 + len(answers)
        assert wait_for(lambda: world.radio_counters(A1).transactions == sent, 5.0), world.radio_counters(A1)
    finally:
        port.detach(None)  # type: ignore[arg-type]


def test_a_runtime_loss_fault_and_a_dropped_link_reach_the_piped_link(world) -> None:
    port = piped(world)
    try:
        assert port.transact(80, NULL)[0]
        world.packet_loss(A1, 1.0, 1.0)
        assert wait_for(lambda: not port.transact(80, NULL)[0], 2.0)
        assert wait_for(lambda: port.transact(80, NULL)[0], 5.0)  # the fault expired
        world.drop_link(A1)
        assert wait_for(lambda: not port.transact(80, NULL)[0], 2.0)
        assert not port.transact(80, NULL)[0] and not port.transact(80, NULL)[0]
        world.restore_link(A1)
        assert wait_for(lambda: port.transact(80, NULL)[0], 2.0)
        counters = world.radio_counters(A1)
        assert counters.lost_transactions >= 3
    finally:
        port.detach(None)  # type: ignore[arg-type]


def test_the_piped_link_draws_the_same_bursts_as_the_world() -> None:
    burst = BurstLoss(mean_good_s=0.2, mean_bad_s=0.05)
    process = WorldProcess({A1: FakeDroneConfig.at(0.0, 0.0, faults=LinkFaults(burst=burst))}, {A1: "cf1"}, natnet=None)
    port = piped(process)
    try:
        assert port._burst is not None
        theirs = process.radio_bursts(A1, 0.0, 30.0)
        ours = port._burst.bad_intervals(0.0, 30.0)
        assert len(theirs) > 20 and ours == pytest.approx(theirs)
    finally:
        port.detach(None)  # type: ignore[arg-type]
        process.close()


def test_a_transaction_does_not_wait_for_the_child(world) -> None:
    """The child stopped (SIGSTOP): a round trip would time out; the piped link answers from what it knows, as a
    drone's radio answers whatever its flight firmware is doing, and the child records it when it runs again."""
    port = piped(world)
    try:
        before = world.radio_counters(A1).transactions
        os.kill(world.pid, signal.SIGSTOP)
        try:
            results = [port.transact(80, NULL) for _ in range(20)]
        finally:
            os.kill(world.pid, signal.SIGCONT)
        assert all(acked for acked, _, _ in results)
        assert wait_for(lambda: world.radio_counters(A1).transactions >= before + 20, 5.0)
    finally:
        port.detach(None)  # type: ignore[arg-type]


def test_a_killed_child_answers_nothing(world) -> None:
    port = piped(world)
    assert port.transact(80, NULL)[0]
    os.kill(world.pid, signal.SIGKILL)
    assert wait_for(lambda: not port.transact(80, NULL)[0], 3.0)
    port.detach(None)  # type: ignore[arg-type]
