"""The command line itself: ``--version``, the help of flags, and help texts derived from the registries."""

import os
import re
import subprocess
import sys

import pytest
import typer
from typer.testing import CliRunner

from rpf_fly.cli import get_app, package_version
from rpf_fly.mission.model import PLANNER_KINDS

runner = CliRunner()
WIDE = {"COLUMNS": "200", "TERMINAL_WIDTH": "200"}


def all_command_paths() -> list[list[str]]:
    """Every command and sub-command of the app, as argument lists (``[]`` is the root)."""
    root = typer.main.get_command(get_app())
    paths: list[list[str]] = [[]]

    def walk(group, prefix: list[str]) -> None:  # type: ignore[no-untyped-def]
        for name, command in group.commands.items():
            paths.append(prefix + [name])
            if hasattr(command, "commands"):
                walk(command, prefix + [name])

    walk(root, [])
    return paths


def test_version_in_a_real_process():
    proc = subprocess.run([sys.executable, "-m", "rpf_fly", "--version"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == f"rpf-fly {package_version()}\n"
    assert re.fullmatch(r"\d+\.\d+\.\d+\S*", package_version())


def test_mocap_help_names_every_system_watch_reads():
    """`mocap --help` (and the group's line in `--help`) says `watch` reads NatNet and the motioncapture package's
    systems (`--system`), not OptiTrack alone."""

    def run(*args: str) -> str:
        proc = subprocess.run(
            [sys.executable, "-m", "rpf_fly", *args],
            capture_output=True,
            text=True,
            timeout=60,
            env={**os.environ, **WIDE},
        )
        assert proc.returncode == 0, proc.stderr
        return " ".join(proc.stdout.replace("│", " ").split())

    group = run("mocap", "--help")
    about = group[group.index("COMMAND [ARGS]...") + len("COMMAND [ARGS]...") : group.index("Options")]
    assert "motioncapture" in about and "Vicon" in about and "NatNet" in about, about
    assert "motioncapture" in run("--help").split(" mocap ", 1)[1]


def test_version_falls_back_to_the_package_when_not_installed(monkeypatch):
    import importlib.metadata

    import rpf_fly

    def not_installed(name):
        raise importlib.metadata.PackageNotFoundError(name)

    monkeypatch.setattr(importlib.metadata, "version", not_installed)
    assert package_version() == rpf_fly.__version__


@pytest.mark.parametrize("path", all_command_paths(), ids=lambda p: " ".join(p) or "rpf-fly")
def test_help_shows_no_type_after_a_flag(path):
    result = runner.invoke(get_app(), [*path, "--help"], env=WIDE)
    assert result.exit_code == 0, result.output
    assert "<bool>" not in result.output
    assert "--help" in result.output


def test_options_that_take_a_value_still_show_its_type():
    result = runner.invoke(get_app(), ["fly", "--help"], env=WIDE)
    line = next(row for row in result.output.splitlines() if "--log" in row)
    assert "<path>" in line
    dry = next(row for row in result.output.splitlines() if "--dry-run" in row)
    assert "<" not in dry


def test_sim_planner_help_lists_every_planner_kind():
    result = runner.invoke(get_app(), ["sim", "--help"], env=WIDE)
    text = " ".join(result.output.split())
    listed = re.search(r"Override the mission's planner: ([a-z0-9, -]+)\.", text)
    assert listed, text
    assert tuple(k.strip() for k in listed.group(1).split(",")) == PLANNER_KINDS
    assert "orca" in PLANNER_KINDS


def test_replay_planner_help_lists_every_planner_kind():
    result = runner.invoke(get_app(), ["replay", "--help"], env=WIDE)
    text = " ".join(result.output.split())
    listed = re.search(r"Replay with this planner kind: ([a-z0-9, -]+) \(default", text)
    assert listed, text
    assert tuple(k.strip() for k in listed.group(1).split(",")) == PLANNER_KINDS


def test_help_does_not_import_numpy():
    code = "import sys; from rpf_fly.cli import get_app; get_app(); print('numpy' in sys.modules)"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.stdout.strip() == "False", proc.stderr


@pytest.mark.parametrize("where", ["under a file", "in /proc"])
@pytest.mark.parametrize("distributed", [False, True])
def test_a_log_that_cannot_be_written_is_one_line_before_anything_flies(tmp_path, where, distributed):
    """``fly --log`` where no file can be made (its folder is a file; /proc, where not even root makes files):
    exit 2, one line naming the path, before any drone, Zenoh session or process is started (no traceback from
    the flight or the distributed flight's logger)."""
    from pathlib import Path

    mission = Path(__file__).resolve().parents[1] / "runtime" / "two-dongles.yaml"
    (tmp_path / "file").write_text("")
    path = tmp_path / "file" / "x.mcap" if where == "under a file" else Path("/proc/rpf-fly-test.mcap")
    result = runner.invoke(
        get_app(), ["fly", str(mission), "--dry-run", "--log", str(path)] + (["--distributed"] if distributed else [])
    )
    assert result.exit_code == 2, result.output
    line = result.output.strip()
    assert "\n" not in line and line.startswith(f"--log {path}: cannot "), line
    assert not path.exists()
