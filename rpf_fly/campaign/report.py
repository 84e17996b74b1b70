"""A campaign's report: one markdown table row per run, under one header line naming the command that reproduces it
and the source it flew; and the same verdicts as JSON.

The header is the whole provenance: a report says what was flown, on which code, and how many passed, nothing of
the story of the run.
"""

from __future__ import annotations

import json
import subprocess
from dataclasses import asdict
from pathlib import Path
from typing import Any

from rpf_fly.campaign.judge import Verdict

COLUMNS = ("kind", "mission", "drone", "verdict", "exit", "outcomes", "min separation", "events", "failures")


def _cell(text: str) -> str:
    return text.replace("|", "/").replace("\n", " ")


def row(v: Verdict) -> str:
    """One run's table row (the kind column carries its draw or its lab fault's fields, when any)."""
    outcomes = ", ".join(f"{n} {o}" for n, o in v.outcomes.items())
    sep = "-" if v.min_separation_m is None else f"{v.min_separation_m:.3f} m"
    kind = v.kind + (" " + json.dumps(v.params) if v.params else "")
    return (
        f"| {_cell(kind)} | {v.mission} | {v.drone or '-'} | {'pass' if v.passed else 'FAIL'} | {v.exit_code} | "
        f"{outcomes} | {sep} | {_cell('; '.join(v.events))} | {_cell('; '.join(v.failures))} |"
    )


def table(verdicts: list[Verdict]) -> str:
    """The runs' markdown table."""
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    return "\n".join(lines + [row(v) for v in verdicts]) + "\n"


def summary(verdicts: list[Verdict]) -> str:
    """``N of M pass`` and the smallest true separation between airborne drones of all runs."""
    passed = sum(v.passed for v in verdicts)
    seps = [v.min_separation_m for v in verdicts if v.min_separation_m is not None]
    closest = f", smallest true separation {min(seps):.3f} m" if seps else ""
    return f"{passed} of {len(verdicts)} pass{closest}"


def source_revision() -> str:
    """The commit the campaign flew (``+ local changes`` when the package's files differ from it), or the installed
    version outside a git checkout."""
    root = Path(__file__).resolve().parents[2]

    def git(*args: str) -> str:
        done = subprocess.run(["git", *args], capture_output=True, text=True, cwd=root, timeout=30)
        if done.returncode != 0:
            raise OSError(done.stderr.strip())
        return done.stdout.strip()

    try:
        commit = git("rev-parse", "--short", "HEAD")
        dirty = git("status", "--porcelain", "--untracked-files=no", "--", "rpf_fly")
    except (OSError, subprocess.SubprocessError):
        from importlib.metadata import PackageNotFoundError, version

        try:
            return f"rpf_fly {version('rpf_fly')}"
        except PackageNotFoundError:
            return "an unknown source"
    return commit + (" + local changes" if dirty else "")


def progress_line(v: Verdict) -> str:
    """One line as a run ends: mission, what flew, pass or FAIL and why."""
    kind = v.kind + (" " + json.dumps(v.params) if v.params else "")
    return f"{v.mission:14s} {kind:22s} {'pass' if v.passed else 'FAIL'}  {'; '.join(v.failures)}".rstrip()


def header(command: str, revision: str, verdicts: list[Verdict]) -> str:
    """The report's one header line: the command, the source it flew, how many passed."""
    return f"# Fault campaign: `{command}` on {revision}: {summary(verdicts)}\n"


def markdown(command: str, revision: str, verdicts: list[Verdict]) -> str:
    """The report file: its header line and the table."""
    return header(command, revision, verdicts) + "\n" + table(verdicts)


def as_json(command: str, revision: str, verdicts: list[Verdict]) -> dict[str, Any]:
    """The verdicts as one JSON document (every field of each `Verdict`), with what was flown."""
    passed = sum(v.passed for v in verdicts)
    return {
        "command": command,
        "revision": revision,
        "passed": passed,
        "failed": len(verdicts) - passed,
        "verdicts": [asdict(v) for v in verdicts],
    }
