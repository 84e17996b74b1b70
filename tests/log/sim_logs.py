"""Helpers of the log tests: simulated missions written with ``rpf-fly sim --log``. A module of its own, not
``conftest``: ``from conftest import`` finds whichever conftest another test directory put on ``sys.path`` first."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from rpf_fly.cli import get_app

ROOT = Path(__file__).resolve().parents[2]
MISSIONS = ROOT / "missions"


def run_cli(*args):  # type: ignore[no-untyped-def]
    return CliRunner().invoke(get_app(), [str(a) for a in args])


def sim_log(directory: Path, mission: str, seed: int = 0) -> tuple[Path, dict]:
    """Simulate ``missions/<mission>.yaml`` with ``--log``; returns the log and the ``sim --json`` metrics."""
    log = directory / f"{mission}-{seed}.mcap"
    result = run_cli("sim", MISSIONS / f"{mission}.yaml", "--seed", seed, "--json", "--log", log)
    assert result.exit_code == 0, result.output
    return log, json.loads(result.stdout)
