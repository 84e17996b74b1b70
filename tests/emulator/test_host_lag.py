"""rpf_fly/emulator/host_lag.py: the time the host held the simulated world or the flight's radio links back, as
the flight's ``host`` warning and the campaigns' retries read it."""

from __future__ import annotations

from rpf_fly.emulator.host_lag import HostLag, JobLag, SpanMeter


def test_spans_of_many_links_held_by_one_stall_count_once() -> None:
    meter = SpanMeter(bound_s=0.05)
    meter.record(0.01, 10.0)  # under the bound: scheduling noise, not behind
    meter.record(0.2, 11.0)  # held 10.8 .. 11.0
    meter.record(0.15, 11.0)  # another link, the same stall: inside the first span
    meter.record(0.3, 11.1)  # a third reaching further back and on: 10.8 .. 11.1 in all
    meter.record(0.06, 12.0)  # a later, separate one: 11.94 .. 12.0
    lag = meter.snapshot()
    assert lag.runs == 5 and lag.late_runs == 4
    assert abs(lag.max_late_s - 0.3) < 1e-9
    assert abs(lag.behind_s - (0.3 + 0.06)) < 1e-9


def test_time_behind_since_a_reading_is_each_jobs_own_growth() -> None:
    def job(behind_s: float) -> JobLag:
        return JobLag(runs=10, late_runs=1, max_late_s=0.1, behind_s=behind_s)

    # the process's links were held 2 s by an earlier flight; this one's world 0.3 s, its links 0.4 s more
    before = HostLag(0.05, world=job(0.0), natnet=None, links=job(2.0))
    after = HostLag(0.05, world=job(0.3), natnet=None, links=job(2.4))
    assert abs(after.behind_since(before) - 0.4) < 1e-9
    assert "radio transactions" in after.sentence(before)
    assert HostLag(0.05, world=job(0.3), natnet=None, links=job(2.0)).behind_since(before) == 0.3
    assert after.behind_since(after) == 0.0 and after.sentence(after) == ""
    assert HostLag(0.05, world=job(0.5), natnet=None).behind_since(None) == 0.5  # the world's figures alone


def test_a_window_counts_only_the_part_of_each_span_inside_it() -> None:
    """A flight's window (take-off to the end of its landing): a link held across take-off counts from take-off
    on, one held before it or after the landing not at all."""
    meter = SpanMeter(bound_s=0.05)
    meter.window = (10.0, 20.0)
    meter.record(0.3, 9.9)  # before take-off
    meter.record(0.08, 10.03)  # held 9.95 .. 10.03: 0.03 of it in the air, under the bound
    meter.record(0.2, 10.1)  # 9.9 .. 10.1: 0.1 in the air
    meter.record(0.3, 20.5)  # 20.2 .. 20.5: after the landing
    meter.record(0.2, 20.05)  # 19.85 .. 20.05: 0.15 in the air
    lag = meter.snapshot()
    assert lag.runs == 3 and lag.late_runs == 2
    assert abs(lag.behind_s - (0.1 + 0.15)) < 1e-9
