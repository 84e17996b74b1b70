"""The radio budget: per dongle, the transactions a mission needs against what a Crazyradio carries under cflib
0.1.34, from the dongle's figures (address switches, retries, packed broadcasts, rate-limited polls); `check` prints
the table, `check` and `fly` refuse a mission over budget (one line naming the dongle, exit 2)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from cflib.crtp.radiodriver import RadioDriver
from typer.testing import CliRunner

from rpf_fly.cli import get_app
from rpf_fly.emulator.crazyradio_timing import (
    CRAZYRADIO_2,
    CRAZYRADIO_PA,
    DR_2M,
    RadioType,
    ard_s,
    ceiling_per_s,
    radio_s,
    transaction_s,
)
from rpf_fly.emulator.fake_world import BurstLoss
from rpf_fly.mission import MissionError, parse_mission
from rpf_fly.radio import budget
from rpf_fly.radio.budget import (
    CONNECT_TRANSACTIONS,
    EXPECTED_ATTEMPT_LOSS,
    KEEPALIVE_HZ,
    LINK_PING_HZ,
    connect_timeouts,
    link_rate_limits,
    link_uri,
    radio_loads,
    uri_rate_limit,
)
from rpf_fly.radio.dongle_model import (
    HOST_SWITCH_S,
    HOST_TRANSACTION_S,
    LinkTraffic,
    Run,
    Traffic,
    simulate,
    timing_of,
)


def mission_text(count: int, rate_hz: float, radio: str = "", dongles: int = 1) -> str:
    lines = [f"name: budget-{count}", "arena: {x: [-5, 5], y: [-4, 4]}", f"flight: {{rate_hz: {rate_hz}}}"]
    if radio:
        lines.append(f"radio: {{{radio}}}")
    lines.append("drones:")
    for i in range(count):
        lines.append(
            f"  - {{name: cf{i + 1}, uri: radio://{i % dongles}/80/2M/E7E7E7E7{i + 1:02X}, rigid_body: cf{i + 1}, "
            f"start: [{-3.5 + 0.5 * i:.1f}, -2.0], goal: [{-3.5 + 0.5 * i:.1f}, 2.0]}}"
        )
    return "\n".join(lines) + "\n"


def expected_s(radio: RadioType, up: int, switching: bool = True) -> float:
    """One transaction from crazyradio_timing's own functions: the address switch, bulk write, radio and read, and
    the expected retries at the budget's loss (each a ramp-up, the packet's time on air and the wait), and the
    host's own time (dongle_model's measured figures)."""
    p = EXPECTED_ATTEMPT_LOSS
    wait = radio.ack_timeout_s if radio.ack_timeout_s is not None else ard_s(0x80 | 32, DR_2M)
    retry = radio_s(radio, DR_2M, up, 0, 1, False, wait) - radio.upload_s_per_byte * up
    host = HOST_TRANSACTION_S + (HOST_SWITCH_S if switching else 0.0)  # cflib's and pyusb's own time on the host
    return (
        (radio.control_s if switching else 0.0) + transaction_s(radio, DR_2M, up, 1) + (p + p**2 + p**3) * retry + host
    )


def host_ceiling(radio: RadioType, switching: bool = True) -> float:
    """crazyradio_timing's ceiling (smallest transactions a second) with the host's own time on each."""
    return 1.0 / (1.0 / ceiling_per_s(radio, switching) + HOST_TRANSACTION_S + (HOST_SWITCH_S if switching else 0.0))


def downlink_s(drones: int) -> float:
    """The status telemetry and the pings' echoes on the acknowledgements: their bytes beyond the empty ack's one."""
    return drones * (10 * 27 + 10 * 9) * 8 / 2e6


def test_the_loss_the_budget_expects_is_the_dry_runs() -> None:
    assert EXPECTED_ATTEMPT_LOSS == pytest.approx(BurstLoss().retried_loss(3), abs=5e-4)


def test_each_dongle_needs_its_drones_traffic_and_carries_what_its_figures_allow() -> None:
    mission = parse_mission(mission_text(10, 10.0, dongles=2))
    loads = radio_loads(mission)
    assert [load.dongle for load in loads] == [0, 1]
    assert loads[0].drones == ("cf1", "cf3", "cf5", "cf7", "cf9")
    for load in loads:
        assert (load.setpoints, load.extpos, load.broadcasts) == (50.0, 150.0, 0.0)  # extpos_rate_hz's default 30
        assert (load.pings, load.keepalives) == (5 * LINK_PING_HZ, 5 * KEEPALIVE_HZ)
        assert load.needed == 5 * (10 + 30 + 10 + 5)
        # every transaction behind an address switch (five links take turns), at the budget's expected loss
        busy = 5 * (
            10 * expected_s(CRAZYRADIO_PA, 18)
            + 30 * expected_s(CRAZYRADIO_PA, 13)
            + 10 * expected_s(CRAZYRADIO_PA, 10)
            + 5 * expected_s(CRAZYRADIO_PA, 2)
        ) + downlink_s(5)
        assert load.busy_s == pytest.approx(busy, rel=1e-9)
        assert load.budget == pytest.approx(load.needed / busy)
        # about the ceiling of crazyradio_timing for links taking turns (572 smallest transactions a second) with the
        # host's own time on each (445)
        assert 0.9 * host_ceiling(CRAZYRADIO_PA) < load.budget < host_ceiling(CRAZYRADIO_PA)
        assert not load.over and load.rate_limits and set(load.rate_limits) == set(load.drones)
        assert load.setpoint_p99_s < 0.1 and load.extpos_p99_s < 1 / 30


def test_a_crazyradio_2_carries_less_its_setup_calls_take_two_and_a_half_times_as_long() -> None:
    (pa,) = radio_loads(parse_mission(mission_text(6, 10.0)))
    (two,) = radio_loads(parse_mission(mission_text(6, 10.0, radio="dongle_type: crazyradio_2")))
    assert two.radio_type == "crazyradio_2" and pa.radio_type == "crazyradio_pa"  # the documented default
    assert two.needed == pa.needed and two.budget < 0.65 * pa.budget
    assert two.budget == pytest.approx(
        two.needed
        / (
            6
            * (
                10 * expected_s(CRAZYRADIO_2, 18)
                + 30 * expected_s(CRAZYRADIO_2, 13)
                + 10 * expected_s(CRAZYRADIO_2, 10)
                + 5 * expected_s(CRAZYRADIO_2, 2)
            )
            + downlink_s(6)
        )
    )


def test_packed_extpos_costs_one_broadcast_per_four_drones_and_a_frame_instead_of_one_packet_a_drone() -> None:
    (unicast,) = radio_loads(parse_mission(mission_text(10, 10.0)))
    (packed,) = radio_loads(parse_mission(mission_text(10, 10.0, radio="extpos: packed")))
    assert (unicast.extpos, unicast.broadcasts) == (300.0, 0.0)
    assert (packed.extpos, packed.broadcasts) == (0.0, 3 * 30.0)  # groups of 4, 4 and 2 drones, 30 times a second
    assert packed.needed == unicast.needed - 300 + 90
    # a broadcast: an address switch and four unanswered attempts of the packed packet (1 + 7 per drone bytes)
    broadcast = {
        n: CRAZYRADIO_PA.control_s
        + CRAZYRADIO_PA.bulk_out_s
        + CRAZYRADIO_PA.bulk_in_s
        + radio_s(CRAZYRADIO_PA, DR_2M, 1 + 7 * n, 0, 4, False, ard_s(0x80 | 32, DR_2M))
        + HOST_TRANSACTION_S
        + HOST_SWITCH_S
        for n in (4, 2)
    }
    saved = 300 * expected_s(CRAZYRADIO_PA, 13) - 30 * (2 * broadcast[4] + broadcast[2])
    assert unicast.busy_s - packed.busy_s == pytest.approx(saved, rel=1e-9)
    assert broadcast[4] < 4 * expected_s(CRAZYRADIO_PA, 13)  # four drones' extpos: 4.6 ms against 7.2 ms
    assert unicast.use > 1.0 and unicast.over  # 10 drones with 30 Hz extpos each: over a PA
    assert packed.use < unicast.use - 0.2 and packed.over  # packed at 30 Hz: 105 %, still over
    (slower,) = radio_loads(parse_mission(mission_text(10, 10.0, radio="extpos: packed, extpos_rate_hz: 20")))
    assert slower.use <= budget.USE_LIMIT and not slower.over  # packed at 20 Hz: within


def test_a_labs_measured_figure_scales_every_time() -> None:
    (figures,) = radio_loads(parse_mission(mission_text(4, 10.0)))
    (lab,) = radio_loads(parse_mission(mission_text(4, 10.0, radio="budget_packets_s: 286")))
    ceiling = host_ceiling(CRAZYRADIO_PA)  # 445 with the host's time: the lab's dongle does about two thirds
    assert lab.measured and not figures.measured
    assert lab.budget == pytest.approx(figures.budget * 286 / ceiling)
    assert lab.busy_s == pytest.approx(figures.busy_s * ceiling / 286)


def test_the_model_of_cflibs_shared_radio_meets_the_ceilings_of_the_figures() -> None:
    """Idle links polling back to back without a rate limit: one link alone never switches, links taking turns
    switch before every transaction (crazyradio_timing.ceiling_per_s, the docs' table), each with the host's own
    time."""
    for radio in (CRAZYRADIO_PA, CRAZYRADIO_2):
        timing = timing_of(radio, "2M")
        for links, switching in ((1, False), (3, True)):
            traffic = Traffic(
                tuple(LinkTraffic((80, "2M", k), None, ping_hz=0, keepalive_hz=0, status_hz=0) for k in range(links)),
                0.0,
                100.0,
                0.0,
            )
            run = simulate(traffic, timing, seconds=1.0)
            assert run.transactions == pytest.approx(host_ceiling(radio, switching), abs=2)
            assert run.busy > 0.995  # (a second holds a whole number of them)


def test_without_rate_limits_idle_polls_starve_the_broadcasts_and_with_them_the_setpoints_keep_their_period() -> None:
    """Ten drones on a PA with packed extpos at 25 Hz: polling back to back, every link keeps a transaction in
    cflib's queue, so a broadcast waits a full round; rate-limited, the queue is short."""
    timing = timing_of(CRAZYRADIO_PA, "2M")

    def run(limit: int | None) -> Run:
        links = tuple(LinkTraffic((80, "2M", k), limit) for k in range(10))
        groups = tuple(((g + 0.5) / 3, 29, 80, "2M") for g in range(3))
        return simulate(Traffic(links, 10.0, 50.0, 25.0, groups, loss=EXPECTED_ATTEMPT_LOSS), timing)

    free, limited = run(None), run(32)
    assert free.busy > 0.99 and free.extpos_delivered < 0.8 and free.extpos_p(0.99) > 0.04
    assert limited.extpos_delivered == 1.0 and limited.extpos_p(0.99) < 0.04
    assert limited.setpoint_p(0.99) < 0.1 and limited.setpoints_superseded == 0


def test_each_radio_link_is_opened_with_its_rate_limit_and_cflib_reads_it() -> None:
    mission = parse_mission(
        mission_text(3, 10.0).replace("radio://0/80/2M/E7E7E7E703,", '"radio://0/80/2M/E7E7E7E703?rate_limit=77",')
    )
    limits = link_rate_limits(mission)
    assert limits["cf3"] == 77 and limits["cf1"] == limits["cf2"] > 55  # the URI's own is kept
    uri = link_uri(mission.drones[0].uri, limits["cf1"])
    assert uri == f"radio://0/80/2M/E7E7E7E701?rate_limit={limits['cf1']}"
    assert RadioDriver.parse_uri(uri)[4] == limits["cf1"]  # cflib 0.1.34's own parser
    assert link_uri(mission.drones[2].uri, 5) == mission.drones[2].uri and uri_rate_limit(mission.drones[2].uri) == 77
    assert link_uri("fake://0/80/2M/E7E7E7E701?x=1&y=2", 40) == "fake://0/80/2M/E7E7E7E701?x=1&y=2"
    assert link_uri("radio://0/80/2M/E7E7E7E701?foo=1", 40) == "radio://0/80/2M/E7E7E7E701?foo=1&rate_limit=40"


def test_a_drone_sharing_a_busy_dongle_is_given_time_for_every_drones_connection_on_it() -> None:
    """Drones connect in parallel and share their dongle's transactions: 8 on one emulated PA took 6.3-15.7 s (TOCs
    cached or not), so a flat 10 s timed every one of them out. Each is given twice its dongle's time for all of
    its drones' connections, and never less than a drone alone is given."""
    from rpf_fly.radio.cflib_backend import CflibBackend

    eight = parse_mission(mission_text(8, 10.0, "extpos: packed"))
    (load,) = radio_loads(eight)
    timeouts = connect_timeouts(eight, 10.0)
    assert set(timeouts) == {d.name for d in eight.drones}
    assert all(t == pytest.approx(2.0 * 8 * CONNECT_TRANSACTIONS / load.budget) for t in timeouts.values())
    assert min(timeouts.values()) > 30.0  # 8 000 transactions on a dongle that carries ~330 of this mix a second
    two_dongles = connect_timeouts(parse_mission(mission_text(8, 10.0, "extpos: packed", dongles=2)), 10.0)
    assert max(two_dongles.values()) < min(timeouts.values())  # four drones a dongle wait for four connections
    assert connect_timeouts(parse_mission(mission_text(1, 10.0)), 10.0) == {"cf1": 10.0}  # alone: the floor
    backend = CflibBackend.for_mission(eight, None)
    assert backend.connect_timeout_of("cf8") == timeouts["cf8"]
    assert CflibBackend().connect_timeout_of("cf8") == CflibBackend.CONNECT_TIMEOUT_S  # no mission: the floor


def test_bad_radio_keys_and_a_packed_mission_whose_ids_clash_are_mission_errors() -> None:
    with pytest.raises(MissionError, match="radio.budget_packets_s"):
        parse_mission(mission_text(2, 10.0, radio="budget_packets_s: -5"))
    with pytest.raises(MissionError, match="radio.dongle_type"):
        parse_mission(mission_text(2, 10.0, radio="dongle_type: crazyradio_9"))
    with pytest.raises(MissionError, match="rate_limit 'x'"):
        parse_mission(
            mission_text(2, 10.0).replace("radio://0/80/2M/E7E7E7E702,", '"radio://0/80/2M/E7E7E7E702?rate_limit=x",')
        )
    clash = mission_text(2, 10.0, radio="extpos: packed").replace("E7E7E7E702,", "A1A1A1A101,")
    with pytest.raises(MissionError, match="cf1 and cf2 both have id 0x01") as err:
        parse_mission(clash)
    assert err.value.line == 4  # the radio section's line
    parse_mission(clash.replace("radio://0/80/2M/A1", "radio://0/90/2M/A1"))  # on another channel: no clash


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "mission.yaml"
    path.write_text(text)
    return path


def test_check_refuses_ten_drones_at_100_hz_with_per_drone_extpos_on_one_dongle_and_names_it(tmp_path: Path) -> None:
    path = write(tmp_path, mission_text(10, 100.0))
    result = CliRunner().invoke(get_app(), ["check", str(path), "--no-preflight"])
    assert result.exit_code == 2
    assert "OVER BUDGET" in result.stdout and "crazyradio_pa" in result.stdout  # the table first
    error = result.stderr.strip().splitlines()
    assert len(error) == 1
    assert error[0].startswith(f"{path}:"), error[0]
    assert (
        error[0]
        .split(": ", 1)[1]
        .startswith("radio: radio dongle 0 (10 drones: cf1, ..., cf10) needs 1450 transactions/s")
    ), error[0]
    assert "a crazyradio_pa carries about" in error[0] and "radio.extpos: packed" in error[0]


def test_check_accepts_the_same_swarm_with_packed_extpos_and_rates_within_the_budget(tmp_path: Path) -> None:
    path = write(tmp_path, mission_text(10, 10.0, radio="extpos: packed, extpos_rate_hz: 20"))
    result = CliRunner().invoke(get_app(), ["check", str(path), "--no-preflight"])
    assert result.exit_code == 0, result.output
    row = next(line for line in result.stdout.splitlines() if line.strip().startswith("0  crazyradio_pa"))
    cells = row.split()
    assert cells[3:7] == ["100", "0", "60", "150"] and cells[7] == "310"  # setpoints, extpos, packed, pings+k-a
    assert "OVER" not in row


def test_fly_refuses_an_over_budget_mission_before_anything_connects(tmp_path: Path) -> None:
    path = write(tmp_path, mission_text(10, 100.0))
    result = CliRunner().invoke(get_app(), ["fly", str(path), "--dry-run", "--log", str(tmp_path / "f.mcap")])
    assert result.exit_code == 2 and "radio dongle 0" in result.stderr
    assert not (tmp_path / "f.mcap").exists()  # nothing flew, nothing was logged


def test_allow_over_budget_lets_check_pass_with_the_table(tmp_path: Path) -> None:
    path = write(tmp_path, mission_text(10, 100.0, radio="allow_over_budget: true"))
    result = CliRunner().invoke(get_app(), ["check", str(path), "--no-preflight"])
    assert result.exit_code == 0, result.output
    assert "OVER BUDGET" in result.stdout


def test_every_shipped_mission_is_within_budget() -> None:
    """Every mission under missions/, in sub-folders too (the campaign's and the radio's), but the one that says it
    flies over budget (`radio.allow_over_budget`, docs/radio.md "Over budget in the dry run")."""
    from rpf_fly.mission import load_mission

    paths = sorted(Path("missions").rglob("*.yaml"))
    assert len(paths) > 10
    for path in paths:
        mission = load_mission(path)
        if mission.radio.allow_over_budget:
            continue
        loads = radio_loads(mission)
        assert not any(load.over for load in loads), (path, [(load.use, load.setpoint_p99_s) for load in loads])
        assert all(math.isfinite(load.setpoint_p99_s) for load in loads)


def test_the_refusal_names_the_radio_sections_line(tmp_path: Path) -> None:
    """FILE:LINE as every mission error: the line of `radio:` (line 4 here), not 0 (the command line's)."""
    path = write(tmp_path, mission_text(15, 100.0, radio="kind: cflib"))
    result = CliRunner().invoke(get_app(), ["check", str(path), "--no-preflight"])
    assert result.exit_code == 2
    assert result.stderr.startswith(f"{path}:4: radio: radio dongle 0"), result.stderr
