"""The telemetry clock: firmware log timestamps mapped onto the host's clock (rpf_fly/radio/telemetry_clock.py)."""

from __future__ import annotations

import random

import pytest

from rpf_fly.radio.telemetry_clock import WRAP_S, TelemetryClock


def test_the_mapping_finds_when_packets_were_made_through_a_delaying_radio():
    """Packets made every 0.1 s (the firmware booted at host time 50 s) arrive 2-300 ms later: after a few that
    came quickly, each one's making time is known within the least delay."""
    rng = random.Random(1)
    clock, errors = TelemetryClock(), []
    for k in range(200):
        made = 100.0 + 0.1 * k
        delay = 0.002 + (rng.random() ** 4) * 0.3  # mostly quick, a tail of hundreds of ms
        errors.append(clock.measured_at(round((made - 50.0) * 1000), made + delay) - made)
    assert max(abs(e) for e in errors[20:]) < 0.006, max(errors[20:])
    assert max(errors[:20]) <= 0.3 + 1e-9  # from the first packet on, never later than its own arrival


def test_a_reboot_or_the_wrap_restarts_the_mapping():
    clock = TelemetryClock()
    assert clock.measured_at(50_000, 1000.01) == pytest.approx(1000.01)
    assert clock.measured_at(50_100, 1000.11) == pytest.approx(1000.11)
    # rebooted: its clock starts again near 0
    assert clock.measured_at(1_600, 1003.0) == pytest.approx(1003.0)
    assert clock.measured_at(1_700, 1003.1) == pytest.approx(1003.1)
    # the 24-bit wrap
    wrapped = TelemetryClock()
    wrapped.measured_at(int(WRAP_S * 1000) - 50, 500.0)
    assert wrapped.measured_at(50, 500.1) == pytest.approx(500.1)


def test_a_slow_firmware_clock_is_followed():
    """A firmware crystal 50 ppm slow: the smallest delay alone would pin the offset to the first minutes."""
    clock, errors = TelemetryClock(), []
    for k in range(36000):  # an hour at 10 Hz
        made = 10.0 + 0.1 * k
        firmware_ms = round((made * (1 - 50e-6)) * 1000)
        errors.append(clock.measured_at(firmware_ms, made + 0.003) - made)
    assert max(abs(e) for e in errors) < 0.01
