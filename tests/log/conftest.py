"""Shared flight logs for the log tests: simulated missions written with ``rpf-fly sim --log`` (once per worker)."""

from __future__ import annotations

from pathlib import Path

import pytest
from sim_logs import sim_log


@pytest.fixture(scope="session")
def lab_log(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    """lab-3 (3 drones, 7 poles), seed 0: the log and its ``sim --json`` metrics."""
    return sim_log(tmp_path_factory.mktemp("lab"), "lab-3")
