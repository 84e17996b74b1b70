"""tests/conftest.py's rule for a test whose own dry run the host held back: it runs again once the host is calm,
as the fault campaign flies such a run again (docs/flight.md, "When the host cannot keep up")."""

from __future__ import annotations

from pathlib import Path

import pytest

from rpf_fly.flight.host_watch import WATCHED


@pytest.fixture
def runs(tmp_path_factory: pytest.TempPathFactory, request: pytest.FixtureRequest) -> Path:
    """A count of this test's runs that outlives each run (its own folder under the session's base temp)."""
    return tmp_path_factory.getbasetemp() / f"{request.node.name}.runs"


def test_a_failure_whose_dry_run_the_host_held_back_runs_again(runs: Path) -> None:
    """The first run fails with its dry run 0.5 s behind (as a flight's host watch would leave it); the second,
    on a calm host, passes: the test passes only if it was run again."""
    count = int(runs.read_text()) + 1 if runs.exists() else 1
    runs.write_text(str(count))
    if count == 1:
        WATCHED.append(0.5)
        raise AssertionError("a drone cut by the estimate check on a starved host")
    assert count == 2


WATCH_IN_A_CHILD = """
from rpf_fly.emulator.host_lag import HostLag, JobLag
from rpf_fly.flight.events import EventBus
from rpf_fly.flight.host_watch import HostWatch

readings = iter([HostLag(0.05, JobLag(1, 0, 0.0, 0.0), None), HostLag(0.05, JobLag(9, 4, 0.3, 0.4), None)])
watch = HostWatch(lambda: next(readings), EventBus(lambda: 0.0))  # its first reading is the baseline
watch.stop()  # the last reading: 0.4 s behind since
"""


def test_a_failure_whose_dry_run_in_another_process_fell_behind_runs_again(runs: Path) -> None:
    """The same for a dry run in a process of its own (a CLI flight): its host watch, finished 0.4 s behind, says
    so in the file the environment names (`host_watch.HOST_LOG_ENV`)."""
    import os
    import subprocess
    import sys

    count = int(runs.read_text()) + 1 if runs.exists() else 1
    runs.write_text(str(count))
    if count == 1:
        subprocess.run([sys.executable, "-c", WATCH_IN_A_CHILD], check=True, env=dict(os.environ))
        raise AssertionError("a drone of the CLI's dry run cut by the estimate check on a starved host")
    assert count == 2
