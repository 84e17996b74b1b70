"""The mission a replay flies (rpf_fly/flight/replay.py): the one in the log's metadata, with its policy file
found again (by the SHA-256 the log recorded) when its path does not resolve, or another planner named for the
replay.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from rpf_fly.flight.agent import PlannerLike
from rpf_fly.flight.replay_inputs import ReplayError
from rpf_fly.mission.model import Drone, Mission


@dataclass
class ReplaySetup:
    """The mission to replay with (the logged one, its planner possibly replaced), the planner factory, and what
    the replay must say about them."""

    mission: Mission
    factory: Callable[[Drone], PlannerLike]
    same_as_flown: bool
    tolerance: float
    warnings: list[str] = field(default_factory=list)


def _with_policy(text: str, policy: Path | None) -> str:
    """The mission text with ``planner.policy`` set to ``policy`` (absolute), or without a policy at all (kind
    ``apf``, for a replay that names its own planner). Only used when the logged policy path does not resolve:
    it was relative to the mission's folder, which the log does not record."""
    import yaml

    doc = yaml.safe_load(text)
    planner = doc.get("planner") if isinstance(doc, dict) else None
    if not isinstance(planner, dict):
        return text
    if policy is None:
        planner.pop("policy", None)
        planner["kind"] = "apf"
    else:
        planner["policy"] = str(policy)
    return yaml.safe_dump(doc, sort_keys=False)


def find_flown_policy(text: str, kind: str, log: Path, sha256: str) -> Path | None:
    """The flown policy file, found by its SHA-256 (``mission.policy_sha256``): the mission's ``planner.policy``
    (or ``policies/<kind>.onnx``) next to the log or here, then a file of that name in ``policies/`` here, next to
    the log, above it, or in this checkout. None if no file there has that hash."""
    import yaml

    from rpf_fly.log.metadata import file_sha256

    if not sha256:
        return None
    try:
        doc = yaml.safe_load(text)
        raw = str(doc["planner"].get("policy") or f"policies/{kind}.onnx")
    except (yaml.YAMLError, KeyError, TypeError, AttributeError):
        raw = f"policies/{kind}.onnx"
    name = Path(raw).name
    here, beside = Path.cwd(), log.parent
    checkout = Path(__file__).resolve().parents[2]
    candidates = [beside / raw, here / raw] + [
        d / name
        for d in (here / "policies", beside, beside / "policies", beside.parent / "policies", checkout / "policies")
    ]
    for candidate in candidates:
        try:
            if candidate.is_file() and file_sha256(candidate) == sha256:
                return candidate.resolve()
        except OSError:
            continue
    return None


def shipped_policy(kind: str, log: Path) -> Path | None:
    """``policies/<kind>.onnx`` for a policy kind named with ``--planner`` alone: here, next to the log, or in
    this checkout (None: let the mission loader say where it looked)."""
    checkout = Path(__file__).resolve().parents[2]
    for folder in (Path.cwd(), log.parent, checkout):
        candidate = folder / "policies" / f"{kind}.onnx"
        if candidate.is_file():
            return candidate.resolve()
    return None


def logged_mission(meta: dict[str, str], log: Path, kind: str | None, policy: Path | None) -> Mission:
    """The mission of the log's metadata, its policy resolved (see :func:`find_flown_policy`)."""
    from rpf_fly.mission import MissionError, parse_mission

    text = meta["yaml"]
    flown_sha = meta.get("policy_sha256", "")
    try:
        try:
            return parse_mission(text, log)  # a relative policy is looked up next to the log first, then here
        except MissionError as err:
            if err.field != "planner.policy":
                raise
            found = find_flown_policy(text, meta.get("planner", ""), log, flown_sha)
            if found is None and kind is None and policy is None:
                raise
            return parse_mission(_with_policy(text, found), log)
    except MissionError as err:
        hint = ""
        if err.field == "planner.policy":
            hint = "; give --policy PATH" + (f" (the flown policy had sha256 {flown_sha[:12]}...)" if flown_sha else "")
        raise ReplayError(f"{log}: metadata mission.yaml line {err.line}: {err.field}: {err.message}{hint}") from None
