"""Where a mission's files are found: a policy (``planner.policy``, or a policy kind's default), a Zenoh config, a
vehicle profile; relative to the mission's folder, then the current one, and for a policy inside a ``policies/``
folder the shipped policies by file name (docs/mission-format.md, *Policy paths*). Why apart: the lookup is shared
by the mission's sections and the CLI's ``--policy``, and an install without a checkout changes only here.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

DEFAULT_POLICY = "policies/{kind}.onnx"
"""Where a policy kind looks for its policy when the mission names none (resolved like ``planner.policy``)."""

PROJECT_POLICIES = Path(__file__).resolve().parents[2] / "policies"
"""The project's shipped policies: the ``policies/`` folder beside the ``rpf_fly`` package (a source checkout or an
editable install). A relative policy path inside a ``policies/`` folder falls back to it by file name, so a mission
copied out of ``missions/`` keeps its ``../policies/rpf.onnx`` (docs/mission-format.md, *Policy paths*)."""


INSTALLED_POLICIES = Path("share") / "rpf_fly" / "policies"
"""Where a wheel puts the shipped policies, under its install prefix (``[tool.setuptools.data-files]`` in
pyproject.toml): a ``pip install`` that is not editable has no ``policies/`` beside the package."""


def shipped_policy_dirs() -> list[Path]:
    """The folders holding the shipped policies: :data:`PROJECT_POLICIES` (a checkout or an editable install), then
    :data:`INSTALLED_POLICIES` under the install prefix the package lies in (a venv, ``--prefix``, ``--user`` or the
    system: the prefix is a parent of ``<prefix>/lib/pythonX.Y/site-packages/rpf_fly``). Only those that exist."""
    here = Path(__file__).resolve()
    dirs = [PROJECT_POLICIES] + [parent / INSTALLED_POLICIES for parent in here.parents[2:]]
    return [d for d in dict.fromkeys(dirs) if d.is_dir()]


def search_dirs(base_dir: Path | None, cwd_first: bool = False) -> list[Path]:
    """The folders a relative path is looked up in: the mission's own (``base_dir``), then the current one; the
    current one first with ``cwd_first`` (a path given on the command line)."""
    dirs = [d for d in (base_dir, Path.cwd()) if d is not None]
    return dirs[::-1] if cwd_first else dirs


def find_file(raw: str, dirs: Sequence[Path]) -> tuple[Path | None, list[Path]]:
    """The first existing file among ``raw`` (absolute) or ``raw`` under each of ``dirs``, then, for a path inside
    a ``policies/`` folder, the shipped policies (`shipped_policy_dirs`) by file name; and every place it looked,
    each once (absolute, ``..`` folded)."""
    path = Path(raw).expanduser()
    candidates = [path] if path.is_absolute() else [d / path for d in dirs]
    if not path.is_absolute() and path.parent.name == "policies":
        candidates += [shipped / path.name for shipped in shipped_policy_dirs()]
    places = list(dict.fromkeys(Path(os.path.abspath(c)) for c in candidates))
    for place in places:
        if place.is_file():
            return place.resolve(), places
    return None, places


def looked_in(candidates: Sequence[Path]) -> str:
    """Where `find_file` looked, for the error that says a file was not found."""
    return "looked in " + ", ".join(str(c) for c in candidates)
