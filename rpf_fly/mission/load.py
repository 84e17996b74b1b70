"""Load a mission YAML file into validated :mod:`rpf_fly.mission.model` dataclasses.

Validation is strict: a mission that would arm a drone must be exactly what its author meant. Every problem raises
:class:`~rpf_fly.mission.errors.MissionError` as ``FILE:LINE: FIELD: message``, where the line is that of the
offending value (of the mapping when a required key is missing; of the formation for drones it generated). Checks
run in two stages: each section's shape, types and ranges (in document order; within a mapping, its keys before
its values; speeds, rates and drone-scale lengths within what the firmware allows, so that a value written in the
wrong unit says so), then the layout of the whole mission (starts and goals against the arena, the obstacles and
each other; the flight height and circles against the arena; the mocap rate against the pose timeout). The format
and every check are described in docs/mission-format.md.

This module is the API (`parse_mission`, `load_mission`, `field_line`, `with_planner`); the parts: the file's
grammar (parser.py, with `expand_formation`), each section's keys and ranges (sections.py), the typed reads of a
value (checker.py), the layout checks (layout.py), where a mission's files are found (policy_paths.py) and the
radio URIs (radio_uri.py).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from . import model as m
from .errors import MissionError
from .layout import check_layout
from .parser import MissionParser
from .policy_paths import DEFAULT_POLICY, find_file, looked_in, search_dirs
from .sections import PLANNER_SPEC
from .yaml_nodes import ROOT, YNode, compose

STRING_SOURCE = "<string>"
"""The file name in errors for text parsed without a source path."""


def parse_mission(text: str, source: Path | str | None = None) -> m.Mission:
    """Validate mission YAML ``text``. ``source`` (the file it came from) names the file in errors, gives the
    default mission name (its stem) and the directory a relative ``planner.policy`` is looked up in first."""
    src = Path(source) if source is not None else None
    file = str(src) if src is not None else STRING_SOURCE
    root = compose(text, file)
    if root is None:
        raise MissionError(file, 1, ROOT, "empty mission file")
    parser = MissionParser(file, src.parent if src is not None else None)
    return parser.parse(root, text, src)


def load_mission(path: str | Path) -> m.Mission:
    """Read and validate the mission file at ``path`` (UTF-8 YAML). Raises :class:`MissionError`."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except FileNotFoundError:
        raise MissionError(p, 0, ROOT, "no such file") from None
    except OSError as exc:
        raise MissionError(p, 0, ROOT, f"cannot read the file: {exc.strerror or exc}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise MissionError(p, line, ROOT, f"not UTF-8 text (byte 0x{data[exc.start]:02x})") from None
    return parse_mission(text.removeprefix("\ufeff"), p)


def field_line(path: str | Path, field: str) -> int:
    """The line of the dotted ``field`` (``mocap.server``) in the mission file at ``path``, for a problem found
    after loading (a host that does not resolve): the line of its nearest written parent when the field is left
    to its default, 0 when the file no longer reads as YAML."""
    try:
        node = compose(Path(path).read_text(encoding="utf-8").removeprefix("\ufeff"), str(path))
    except (OSError, UnicodeDecodeError, MissionError):
        return 0
    line = 0
    for key in field.split("."):
        if node is None or not node.is_map or key not in node.mapping:
            break
        node = node.mapping[key]
        line = node.key_line
    return line


def with_planner(mission: m.Mission, kind: str, policy: str | Path | None = None, **overrides: Any) -> m.Mission:
    """``mission`` flown with another planner: the CLI's ``--planner``, ``--policy`` and planner overrides such as
    ``wall_following=False`` (``--no-wall-following``). ``overrides`` are PlannerSettings fields (``lam`` for
    lambda). Everything is re-validated; errors read ``FILE:0: --option: message`` (line 0: the command line).

    ``policy`` is looked up as an absolute path, else relative to the current directory, else to the mission's
    directory. Without it, the mission's policy is kept when ``kind`` is the mission's kind; a policy kind
    otherwise looks for ``policies/<kind>.onnx`` (mission directory, current directory, the shipped ``policies/``);
    other kinds drop it.
    """
    file = str(mission.source) if mission.source is not None else STRING_SOURCE
    base_dir = mission.source.parent if mission.source is not None else None
    check = MissionParser(file, base_dir)  # the planner section's readers, as the mission file's were read

    def cli_error(option: str, message: str) -> MissionError:
        return MissionError(file, 0, option, message)

    kind = check.choice(YNode(kind, 0, 0, "--planner", str(kind)), m.PLANNER_KINDS, what="planner kind")
    if policy is not None:
        found, looked = find_file(str(policy), search_dirs(base_dir, cwd_first=True))
        if found is None:
            raise cli_error("--policy", f"policy file {str(policy)!r} not found ({looked_in(looked)})")
    elif kind == mission.planner.kind:
        found = mission.planner.policy
    elif kind in m.POLICY_KINDS:
        raw = DEFAULT_POLICY.format(kind=kind)
        found, looked = find_file(raw, search_dirs(base_dir))
        if found is None:
            raise cli_error(
                "--planner",
                f"planner kind {kind!r} needs a policy: give --policy, or provide the "
                f"default {raw!r} ({looked_in(looked)})",
            )
    else:
        found = None

    by_field = {name: (key, reader) for key, (name, reader) in PLANNER_SPEC.items() if name not in ("kind", "policy")}
    values: dict[str, Any] = {}
    for name, value in overrides.items():
        if name not in by_field:
            raise TypeError(
                f"with_planner() got an unknown planner override {name!r}; "
                f"expected one of {', '.join(sorted(by_field))}"
            )
        key, reader = by_field[name]
        option = "--" + key.replace("_", "-")
        raw_text = str(value).lower() if isinstance(value, bool) else str(value)
        values[name] = reader(check, YNode(value, 0, 0, option, raw_text))
    planner = dataclasses.replace(mission.planner, kind=kind, policy=found, **values)
    updated = dataclasses.replace(mission, planner=planner)

    option = "--safety-radius" if "safety_radius" in overrides else "--planner"

    def layout_error(path: str, message: str, at: Sequence[str] = ()) -> MissionError:
        return cli_error(option, f"{path}: {message}")

    check_layout(updated, layout_error)
    return updated
