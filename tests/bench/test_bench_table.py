"""``rpf-fly bench``'s table as a user reads it piped (a log file, CI): within 100 columns, nothing cut, no spread
where a figure comes from one run."""

from __future__ import annotations

from pathlib import Path

from typer.testing import CliRunner

from rpf_fly.bench.report import fmt_stat
from rpf_fly.cli import get_app

ROOT = Path(__file__).resolve().parents[2]


def bench(episodes: int, tmp_path: Path) -> str:
    result = CliRunner().invoke(
        get_app(),
        [
            "bench",
            "--episodes",
            str(episodes),
            "--planners",
            "apf,orca,ppo",
            "--scenes",
            "lab-3,arena-b-6",
            "--policies",
            str(ROOT / "policies"),
            "--missions",
            str(ROOT / "missions"),
        ],
    )
    assert result.exit_code == 0, result.output
    return result.stdout


def table_of(text: str) -> list[str]:
    lines = text.splitlines()
    end = next(i for i, line in enumerate(lines) if line.startswith("success: "))
    return lines[:end]


def test_a_one_seed_table_has_no_spreads_and_fits_100_columns(tmp_path):
    text = bench(1, tmp_path)
    table = table_of(text)
    assert "1 seed per scene" in table[0]
    assert all(len(line) <= 100 for line in text.splitlines()), max(text.splitlines(), key=len)
    assert "±" not in "\n".join(table) and "…" not in text
    rows = [line.split() for line in table if line.startswith(" lab-3")]
    assert [r[1] for r in rows] == ["APF", "ORCA", "PPO"]
    assert rows[0][2] == "1/1" and float(rows[0][5]) > 0  # travel, a bare number
    assert "mean±std" not in text


def test_a_multi_seed_table_has_spreads_and_fits_100_columns(tmp_path):
    text = bench(3, tmp_path)
    table = table_of(text)
    assert all(len(line) <= 100 for line in text.splitlines()), max(text.splitlines(), key=len)
    assert "…" not in text
    rows = [line.split() for line in table if line.startswith(" lab-3")]
    assert rows[0][1] == "APF" and "±" in rows[0][5] and rows[0][2] == "3/3"


def test_fmt_stat_shows_no_spread_over_one_run():
    assert fmt_stat({"mean": 4.5812, "std": 0.0, "n": 1}) == "4.58"
    assert fmt_stat({"mean": 4.5812, "std": 0.1, "n": 2}, n=True) == "4.58 ± 0.10 (2)"
    assert fmt_stat(None) == "-"
