"""Waiting for a calm host before a held-back run is flown again (rpf_fly/campaign/calm_host.py)."""

from __future__ import annotations

from rpf_fly.campaign import calm_host
from rpf_fly.campaign.calm_host import wait_for_a_calm_host


def test_it_waits_its_least_then_returns_on_a_calm_host_and_gives_up_at_its_most(monkeypatch) -> None:
    assert wait_for_a_calm_host(wait_s=0.0) < 1.0  # nothing to wait for: not one second's sample
    assert wait_for_a_calm_host(wait_s=10.0, at_least_s=0.3) >= 0.3
    # a host that never idles: /proc/stat read as busy; the wait ends at its most
    ticks = iter(range(10**6))
    monkeypatch.setattr(calm_host, "_cpu_times", lambda: (0.0, float(next(ticks) * 100)))
    waited = wait_for_a_calm_host(wait_s=2.0, idle=0.35)
    assert 2.0 <= waited < 2.0 + 5.0
    # a host that idles: back after the first second
    idle = iter(range(10**6))
    monkeypatch.setattr(calm_host, "_cpu_times", lambda: (float(next(idle) * 100), float(next(idle) * 100)))
    assert wait_for_a_calm_host(wait_s=30.0, idle=0.35) < 30.0


def test_without_proc_stat_it_waits_a_fixed_time_within_its_bounds(monkeypatch) -> None:
    monkeypatch.setattr(calm_host, "_cpu_times", lambda: None)
    monkeypatch.setattr(calm_host, "FIXED_WAIT_S", 0.2)
    assert 0.2 <= wait_for_a_calm_host(wait_s=10.0) < 10.0
    assert 0.4 <= wait_for_a_calm_host(wait_s=10.0, at_least_s=0.4) < 10.0
