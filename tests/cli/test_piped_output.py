"""Output that is not a terminal (a pipe, a log file, CI): plain lines, each with its newline, nothing cut."""

from __future__ import annotations

import io
import subprocess
import sys
from pathlib import Path

from typer.testing import CliRunner

from rpf_fly.cli import get_app
from rpf_fly.cli.output import ProgressLines

ROOT = Path(__file__).resolve().parents[2]
runner = CliRunner()


def test_sim_table_piped_keeps_every_header_and_cell():
    result = runner.invoke(get_app(), ["sim", str(ROOT / "missions" / "lab-3.yaml")])
    assert result.exit_code == 0, result.output
    out = result.stdout
    assert "travel [m]" in out and "time to goal [s]" in out  # not eaten as markup, not cut
    assert "…" not in out and out.endswith("\n")
    summary = [line for line in out.splitlines() if line.startswith("travel ")]
    assert len(summary) == 1 and "min obstacle clearance" in summary[0]  # one line, not wrapped at 80 columns


def test_review_piped_names_every_schema_in_full(tmp_path):
    log = tmp_path / "lab.mcap"
    assert runner.invoke(get_app(), ["sim", str(ROOT / "missions" / "lab-3.yaml"), "--log", str(log)]).exit_code == 0
    result = runner.invoke(get_app(), ["review", str(log)])
    assert result.exit_code == 0, result.output
    assert "rpf_fly.PlannerStep" in result.stdout and "foxglove.FrameTransforms" in result.stdout
    assert "longest gap [s]" in result.stdout and "…" not in result.stdout


def test_train_piped_prints_progress_lines_not_a_bar(tmp_path):
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "rpf_fly",
            "train",
            "--out",
            str(tmp_path / "t.onnx"),
            "--episodes",
            "1",
            "--arenas",
            "2",
            "--eval-seeds",
            "0",
            "--threads",
            "1",
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    progress = [line for line in lines if line.startswith("train: ")]
    assert progress and progress[-1].startswith("train: 1/1 episodes")
    assert "━" not in proc.stdout and "\r" not in proc.stdout and proc.stdout.endswith("\n")


def test_progress_lines_are_paced_and_end_with_the_last_step():
    now = [0.0]
    out = io.StringIO()
    lines = ProgressLines("bench", 100, "runs", stream=out, period_s=10.0, clock=lambda: now[0])
    for step in range(1, 101):
        now[0] = step * 0.5  # 50 s in all
        lines.update(step, f"run {step}")
    text = out.getvalue().splitlines()
    assert text[0].startswith("bench: 1/100 runs")
    assert text[-1].startswith("bench: 100/100 runs  0:50  run 100")
    assert 5 <= len(text) <= 7  # one line per 10 s, plus the first and the last
    lines.update(100, "again", final=True)
    assert len(out.getvalue().splitlines()) == len(text)  # the last line is printed once
