"""``rpf-fly fly --foxglove [PORT]``: the short form read as ``--foxglove-port PORT``, never at the cost of the
mission path or another option that follows the flag (rpf_fly/cli/live_opts.py)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from rpf_fly.cli.live_opts import foxglove_port_argv

ROOT = Path(__file__).resolve().parents[2]


def test_a_port_after_the_flag_is_the_port_and_anything_else_stays_what_it_was(tmp_path, monkeypatch) -> None:
    assert foxglove_port_argv(["fly", "m.yaml", "--foxglove", "9000", "--dry-run"]) == [
        "fly",
        "m.yaml",
        "--foxglove-port",
        "9000",
        "--dry-run",
    ]
    assert foxglove_port_argv(["fly", "m.yaml", "--foxglove=9001"]) == ["fly", "m.yaml", "--foxglove-port", "9001"]
    for args in (
        ["fly", "--foxglove", "missions/lab-3.yaml", "--dry-run"],  # the mission, not a port
        ["fly", "m.yaml", "--foxglove", "--dry-run"],
        ["fly", "m.yaml", "--foxglove"],
        ["review", "--foxglove", "9000"],
    ):  # only fly has the option
        assert foxglove_port_argv(args) == args
    monkeypatch.chdir(tmp_path)
    (tmp_path / "8765").write_text("name: a mission file named like a port\n")
    assert foxglove_port_argv(["fly", "--foxglove", "8765"]) == ["fly", "--foxglove", "8765"]


def test_the_console_script_reads_foxglove_port_before_anything_connects() -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "rpf_fly", "fly", "missions/lab-3.yaml", "--dry-run", "--foxglove", "70000"],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
    )
    assert proc.returncode == 2, proc.stderr
    assert (
        proc.stderr.strip()
        .splitlines()[-1]
        .endswith("--foxglove-port: expected a port 0..65535 (0: any free port), got 70000")
    )
    assert "Traceback" not in proc.stderr
