"""The missions a campaign flies: shipped ones by name, and copies that change one thing (the planner, the extpos
packet, the simulated drones' dynamics, the simulated world's seed) so one campaign can fly the same scenes another
way.

A copy keeps the mission's name (the report reads as the original's) and lives in the campaign's work folder; its
policy and vehicle profile paths are made absolute, so it still finds them from there.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import yaml

ROOT = Path(__file__).resolve().parents[2]
"""The source tree (its missions/ folder holds the shipped missions the maintainers' campaigns fly)."""

FIXED_MISSIONS = "lab-3,circle-8-r3"
"""The fixed campaign's missions."""
RANDOM_MISSIONS = "lab-3,circle-8-r3,arena-a-6,arena-b-6,u-trap"
"""The shipped missions the random campaign draws from (the 40-drone ones are the distributed flight's)."""
DYNAMICS = ("first-order", "firmware")
"""How a dry run's simulated drones may fly (``dry_run.dynamics``, docs/dynamics.md "The simulated drone")."""


def mission_path(name: str) -> Path:
    """A shipped mission by name (``lab-3``, ``campaign/pillars-6``), or any mission file by path (``my/lab.yaml``)."""
    if name.endswith((".yaml", ".yml")) or (Path(name).exists() and Path(name).is_file()):
        return Path(name).resolve()
    return ROOT / "missions" / f"{name}.yaml"


def _copy(mission_path: Path, workdir: Path, suffix: str, change: Callable[[dict[str, Any]], None]) -> Path:
    """A copy of the mission in ``workdir`` (same name, policy path absolute) with ``change`` applied to its
    document."""
    doc = yaml.safe_load(mission_path.read_text())
    change(doc)
    policy = (doc.get("planner") or {}).get("policy")
    if policy and (mission_path.parent / policy).exists():
        doc["planner"]["policy"] = str((mission_path.parent / policy).resolve())
    vehicle = (doc.get("dry_run") or {}).get("vehicle")
    if isinstance(vehicle, str) and (mission_path.parent / vehicle).exists():
        doc["dry_run"]["vehicle"] = str((mission_path.parent / vehicle).resolve())
    doc.setdefault("name", mission_path.stem)
    copy = workdir / f"{mission_path.stem}.{suffix}.yaml"
    copy.write_text(yaml.safe_dump(doc, sort_keys=False))
    return copy


def with_extpose(mission_path: Path, workdir: Path) -> Path:
    """A copy whose mocap poses reach the estimators as extpose (position and orientation: ``radio.extpos:
    extpose``), so the campaign flies the path where a wrong orientation matters."""

    def change(doc: dict[str, Any]) -> None:
        doc["radio"] = {**(doc.get("radio") or {}), "extpos": "extpose"}

    return _copy(mission_path, workdir, "extpose", change)


def with_dynamics(mission_path: Path, dynamics: str, workdir: Path) -> Path:
    """A copy whose simulated drones fly ``dynamics`` (``dry_run.dynamics``: ``first-order``, the emulator's lag,
    or ``firmware``, the firmware's PID cascade on the identified body; a lab started on the copy flies it too), so
    a campaign's verdicts can be had on either model."""
    if dynamics not in DYNAMICS:
        raise ValueError(f"dynamics: expected {' or '.join(DYNAMICS)}, got {dynamics!r}")

    def change(doc: dict[str, Any]) -> None:
        doc["dry_run"] = {**(doc.get("dry_run") or {}), "dynamics": dynamics}

    return _copy(mission_path, workdir, dynamics, change)


def with_planner_kind(mission_path: Path, kind: str, workdir: Path) -> Path:
    """A copy flying planner ``kind`` with that kind's default policy."""

    def change(doc: dict[str, Any]) -> None:
        doc["planner"] = {**{k: v for k, v in (doc.get("planner") or {}).items() if k != "policy"}, "kind": kind}

    return _copy(mission_path, workdir, kind, change)


def with_world_seed(mission_path: Path, seed: int, workdir: Path) -> Path:
    """A copy whose dry run draws its simulated world from ``seed`` (``dry_run.seed``: the drones' IMU biases, so
    where a blind drone drifts; turbulence, radio loss and mocap jitter)."""

    def change(doc: dict[str, Any]) -> None:
        doc["dry_run"] = {**(doc.get("dry_run") or {}), "seed": seed}

    return _copy(mission_path, workdir, f"seed{seed}", change)
