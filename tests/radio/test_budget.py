"""The radio budget: per dongle, the packets a second a mission needs against what a Crazyradio carries; `check`
prints the table, `check` and `fly` refuse a mission over budget (one line naming the dongle, exit 2)."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from rpf_fly.cli import get_app
from rpf_fly.mission import MissionError, parse_mission
from rpf_fly.radio.budget import DONGLE_BUDGETS, radio_loads


def mission_text(count: int, rate_hz: float, radio: str = "", dongles: int = 1) -> str:
    lines = [f"name: budget-{count}", "arena: {x: [-5, 5], y: [-4, 4]}", f"flight: {{rate_hz: {rate_hz}}}"]
    if radio:
        lines.append(f"radio: {{{radio}}}")
    lines.append("drones:")
    for i in range(count):
        lines.append(f"  - {{name: cf{i + 1}, uri: radio://{i % dongles}/80/2M/E7E7E7E7{i + 1:02X}, rigid_body: cf{i + 1}, "
                     f"start: [{-3.5 + 0.5 * i:.1f}, -2.0], goal: [{-3.5 + 0.5 * i:.1f}, 2.0]}}")
    return "\n".join(lines) + "\n"


def test_each_dongle_counts_its_own_drones_setpoints_and_extpos() -> None:
    mission = parse_mission(mission_text(10, 50.0, dongles=2))
    loads = radio_loads(mission)
    assert [load.dongle for load in loads] == [0, 1]
    assert [len(load.drones) for load in loads] == [5, 5]
    assert loads[0].drones == ("cf1", "cf3", "cf5", "cf7", "cf9")
    for load in loads:
        assert load.setpoints == 5 * 50.0 and load.extpos == 5 * 30.0  # extpos_rate_hz's default
        assert load.pings == 5 * 10.0  # cflib's latency ping on every link
        assert load.telemetry == 50.0 and load.telemetry_transactions == 0.0  # downlink rides on the acks
        assert load.needed == 450.0 and load.budget == DONGLE_BUDGETS["crazyradio_pa"] and not load.over


def test_fifteen_drones_at_100_hz_on_one_dongle_are_over_budget_and_a_lower_rate_is_not() -> None:
    (load,) = radio_loads(parse_mission(mission_text(15, 100.0)))
    assert load.over and load.needed == 15 * 140.0
    (load,) = radio_loads(parse_mission(mission_text(15, 20.0, radio="extpos_rate_hz: 20")))
    assert not load.over and load.needed == 15 * 50.0


def test_the_budget_can_be_set_to_a_labs_own_figure() -> None:
    (load,) = radio_loads(parse_mission(mission_text(4, 100.0, radio="budget_packets_s: 400")))
    assert load.budget == 400.0 and load.over


def test_a_bad_budget_key_is_a_mission_error() -> None:
    with pytest.raises(MissionError, match="radio.budget_packets_s"):
        parse_mission(mission_text(2, 10.0, radio="budget_packets_s: -5"))
    with pytest.raises(MissionError, match="radio.dongle_type"):
        parse_mission(mission_text(2, 10.0, radio="dongle_type: crazyradio_9"))


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "mission.yaml"
    path.write_text(text)
    return path


def test_check_refuses_fifteen_drones_at_100_hz_on_one_dongle_and_names_it(tmp_path: Path) -> None:
    path = write(tmp_path, mission_text(15, 100.0))
    result = CliRunner().invoke(get_app(), ["check", str(path), "--no-preflight"])
    assert result.exit_code == 2
    assert "OVER BUDGET" in result.stdout  # the table is printed before the refusal
    error = result.stderr.strip().splitlines()
    assert len(error) == 1
    assert "radio dongle 0" in error[0] and "needs 2100 packets/s" in error[0] and "about 1000" in error[0]


def test_fly_refuses_an_over_budget_mission_before_anything_connects(tmp_path: Path) -> None:
    path = write(tmp_path, mission_text(15, 100.0))
    result = CliRunner().invoke(get_app(), ["fly", str(path), "--dry-run", "--log", str(tmp_path / "f.mcap")])
    assert result.exit_code == 2 and "radio dongle 0" in result.stderr
    assert not (tmp_path / "f.mcap").exists()  # nothing flew, nothing was logged


def test_allow_over_budget_lets_check_pass_with_the_table(tmp_path: Path) -> None:
    path = write(tmp_path, mission_text(15, 100.0, radio="allow_over_budget: true"))
    result = CliRunner().invoke(get_app(), ["check", str(path), "--no-preflight"])
    assert result.exit_code == 0, result.output
    assert "OVER BUDGET" in result.stdout and "210%" in result.stdout


def test_every_shipped_mission_is_within_budget() -> None:
    for path in sorted(Path("missions").glob("*.yaml")):
        from rpf_fly.mission import load_mission

        assert not any(load.over for load in radio_loads(load_mission(path))), path


def test_the_refusal_names_the_radio_sections_line(tmp_path: Path) -> None:
    """FILE:LINE as every mission error: the line of `radio:` (line 4 here), not 0 (the command line's)."""
    path = write(tmp_path, mission_text(15, 100.0, radio="kind: cflib"))
    result = CliRunner().invoke(get_app(), ["check", str(path), "--no-preflight"])
    assert result.exit_code == 2
    assert result.stderr.startswith(f"{path}:4: radio: radio dongle 0"), result.stderr
