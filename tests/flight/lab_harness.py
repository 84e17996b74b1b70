"""``rpf-fly lab`` in a process of its own, with its own lab file, for the tests that fly against a lab."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path


class LabProcess:
    """``rpf-fly lab MISSION --log <tmp>/lab.mcap``, its lab file in ``tmp_path``; `run` and `start` run other
    ``rpf-fly`` commands against it; `stop` is SIGTERM (the lab's output back)."""

    def __init__(self, tmp_path: Path, mission: Path) -> None:
        self.env = dict(os.environ, PYTHONUNBUFFERED="1", RPF_FLY_LAB=str(tmp_path / "lab.json"))
        self.log = tmp_path / "lab.mcap"
        self.tmp_path = tmp_path
        self.mission = mission
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "rpf_fly", "lab", str(mission), "--log", str(self.log)],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env=self.env,
            cwd=tmp_path,
        )
        deadline = time.monotonic() + 60
        while not (tmp_path / "lab.json").exists():
            assert self.proc.poll() is None, self.proc.stdout.read()  # type: ignore[union-attr]
            assert time.monotonic() < deadline, "the lab did not start"
            time.sleep(0.05)

    def run(self, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
        return subprocess.run(
            [sys.executable, "-m", "rpf_fly", *args],
            capture_output=True,
            text=True,
            env=self.env,
            cwd=self.tmp_path,
            timeout=timeout,
        )

    def start(self, *args: str, stdout: int = subprocess.DEVNULL) -> subprocess.Popen:
        return subprocess.Popen(
            [sys.executable, "-m", "rpf_fly", *args],
            stdout=stdout,
            stderr=subprocess.PIPE,
            text=True,
            env=self.env,
            cwd=self.tmp_path,
        )

    def stop(self) -> str:
        self.proc.send_signal(signal.SIGTERM)
        out, _ = self.proc.communicate(timeout=30)
        assert self.proc.returncode == 0, out
        return out
