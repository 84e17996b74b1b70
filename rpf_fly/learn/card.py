"""The model card: a YAML file next to each shipped policy saying exactly how it was made and how it scores."""

from __future__ import annotations

import platform
import subprocess
from pathlib import Path
from typing import Any

import yaml


def git_commit(cwd: str | Path = ".") -> str:
    """The checkout's commit, with ``-dirty`` when tracked files changed; ``unknown`` outside git."""
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=cwd, capture_output=True, text=True, timeout=10)
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=cwd,
            capture_output=True,
            text=True,
            timeout=10,
        )
    except (OSError, subprocess.TimeoutExpired):
        return "unknown"
    if commit.returncode != 0:
        return "unknown"
    return commit.stdout.strip() + ("-dirty" if dirty.stdout.strip() else "")


def machine() -> dict[str, Any]:
    import os

    import torch

    return {
        "python": platform.python_version(),
        "torch": str(torch.__version__),
        "cpu_cores": os.cpu_count(),
        "torch_threads": torch.get_num_threads(),
        "platform": platform.platform(),
    }


def write_card(path: str | Path, card: dict[str, Any]) -> Path:
    path = Path(path)
    path.write_text(yaml.safe_dump(card, sort_keys=False, width=110))
    return path
