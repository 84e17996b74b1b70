"""``pytest --lf`` reruns the failures alone after a ``-n 2`` run, with or without ``-n`` (tests/xdist_ids.py)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from xdist_ids import PlainIds, plain_nodeid

TESTS = Path(__file__).resolve().parent
ADDOPTS = re.search(r'^addopts = "(.*)"$', (TESTS.parent / "pyproject.toml").read_text(), re.M).group(1)

SAMPLE = """\
import pytest

def test_passes(): pass
def test_fails(): assert {fails}

@pytest.mark.xdist_group("cli_flights")
def test_grouped_fails(): assert False

@pytest.mark.xdist_group("cli_flights")
def test_grouped_passes(): pass

@pytest.mark.parametrize("x", ["a@b"])
def test_at_in_a_parameter(x): pass
"""


def pytest_in(folder: Path, *args: str) -> str:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTEST_", "PYTHONPATH"))}
    env["PYTHONPATH"] = str(TESTS)
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:randomly", *args],
        cwd=folder,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    return done.stdout + done.stderr


@pytest.mark.parametrize("ungrouped_fails", [True, False], ids=["both", "grouped-only"])
def test_last_failed_reruns_only_the_failures_after_a_run_on_two_workers(tmp_path, ungrouped_fails):
    """Recorded under the xdist ids, grouped failures alone make a serial `--lf` run the whole suite, and beside
    an ungrouped failure they are left out of it."""
    (tmp_path / "pyproject.toml").write_text(
        f'[tool.pytest.ini_options]\ntestpaths = ["tests"]\naddopts = "{ADDOPTS}"\n'
    )
    (tmp_path / "tests").mkdir()
    shutil.copy(TESTS / "conftest.py", tmp_path / "tests" / "conftest.py")  # the suite's own conftest
    (tmp_path / "tests" / "test_sample.py").write_text(SAMPLE.format(fails=not ungrouped_fails))
    failed = 2 if ungrouped_fails else 1
    (tmp_path / "tests" / "test_other.py").write_text("def test_other(): pass\n")

    first = pytest_in(tmp_path, "-n", "2")
    assert f"{failed} failed, {6 - failed} passed" in first, first

    serial = pytest_in(tmp_path, "--lf")
    assert re.search(rf"\b{failed} failed\b", serial) and " passed" not in serial, serial
    assert "FAILED tests/test_sample.py::test_grouped_fails" in serial, serial

    workers = pytest_in(tmp_path, "--lf", "-n", "2")
    assert re.search(rf"\b{failed} failed\b", workers) and " passed" not in workers, workers


def test_plain_ids_drop_only_the_group_suffix():
    assert plain_nodeid("tests/a.py::test_x@cli_flights") == "tests/a.py::test_x"
    assert plain_nodeid("tests/a.py::test_x[a@b]") == "tests/a.py::test_x[a@b]"
    assert plain_nodeid("tests/a.py::test_x[a@b]@lab") == "tests/a.py::test_x[a@b]"
    ids = PlainIds({"tests/a.py::test_x@lab": True})
    assert dict(ids) == {"tests/a.py::test_x": True}
    assert "tests/a.py::test_x" in ids and "tests/a.py::test_x@lab" in ids
    ids.pop("tests/a.py::test_x")
    assert not ids
