"""What is checked before anything connects: the mission and its fault schedule loaded, its planner made once, its
mocap server resolved, its radio budget and Crazyradios, the running lab, the flight log's folder.

Each check raises :class:`~rpf_fly.app.errors.UserError` with the one line the commands print (``FILE:LINE:
FIELD: problem`` for a mission's field, docs/mission-format.md) and their exit code, so every command that flies a
mission (``fly``, ``check``, ``worker``, ``lab``, ``scenario``) refuses it alike and before a drone is touched.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rpf_fly.app.errors import UserError

if TYPE_CHECKING:
    from rpf_fly.flight.faults import Fault
    from rpf_fly.flight.lab import LabInfo
    from rpf_fly.mission import Mission
    from rpf_fly.radio.budget import DongleLoad

PlannerFactory = Callable[[Any], Any]
"""A flight's planner factory: the drone (its mission entry) to its own planner instance."""


def load_mission(mission_path: Path) -> Mission:
    """The mission at ``mission_path``; an invalid one is one line ``FILE:LINE: FIELD: problem``."""
    from rpf_fly.mission import MissionError
    from rpf_fly.mission import load_mission as load

    try:
        return load(mission_path)
    except MissionError as err:
        raise UserError(str(err)) from None


def load_faults(path: Path, mission: Mission) -> list[Fault]:
    """The fault schedule at ``path`` for ``mission`` (docs/faults.md); an invalid one is one line."""
    from rpf_fly.flight.faults import load_faults as load
    from rpf_fly.mission import MissionError

    try:
        return load(path, mission)
    except MissionError as err:
        raise UserError(str(err)) from None


def at(mission_path: Path, problem: str) -> str:
    """``FILE:LINE: FIELD: problem`` for a problem of the mission's ``FIELD`` found after loading (``problem`` starts
    with the field): the field's line in the file (docs/mission-format.md's convention), not 0, the command line's."""
    from rpf_fly.mission import field_line

    return f"{mission_path}:{field_line(mission_path, problem.split(':', 1)[0])}: {problem}"


def real_flight_problem(mission: Mission) -> str | None:
    """Why ``mission`` cannot fly real drones (``FIELD: problem``), or None (rpf_fly/flight/session.py)."""
    from rpf_fly.flight.session import real_flight_problem as problem

    return problem(mission)


def resolve_server(mission: Mission, mission_path: Path) -> None:
    """An unresolvable ``mocap.server`` is an invalid mission: one line, before anything connects."""
    from rpf_fly.flight.session import UnresolvableServer, resolve_mocap_server

    try:
        resolve_mocap_server(mission)
    except UnresolvableServer as err:
        raise UserError(at(mission_path, f"{err.field}: {err}")) from None


def require_library(mission: Mission, dry_run: bool, mocap: str | None = None) -> None:
    """A flight that needs the optional motioncapture package and lacks it: one line naming the extra, exit 1."""
    from rpf_fly.flight.session import motioncapture_missing

    missing = motioncapture_missing(mission, dry_run, mocap)
    if missing:
        raise UserError(f"mocap: {missing}", code=1)


def check_radio_budget(mission: Mission, mission_path: Path) -> list[DongleLoad]:
    """Refuse a mission that asks a dongle for more than it carries (one line, before anything connects), unless it
    says ``radio.allow_over_budget: true``; the per-dongle loads otherwise (docs/radio.md)."""
    from rpf_fly.radio.budget import over_budget_message, radio_loads

    loads = radio_loads(mission)
    over = [load for load in loads if load.over]
    if over and not mission.radio.allow_over_budget:
        raise UserError(at(mission_path, f"radio: {over_budget_message(over[0])}"))
    return loads


def check_radios(mission: Mission, skip_dongles: tuple[int, ...] = (), only_dongle: int | None = None) -> None:
    """Every ``radio://`` drone's Crazyradio on USB, before any link is tried: else one line. A distributed flight
    checks the dongles of this host only: not ``skip_dongles`` (remote workers'), or ``only_dongle`` (a worker's)."""
    from rpf_fly.radio.budget import dongle_of
    from rpf_fly.radio.dongles import radio_problem

    drones = [
        d
        for d in mission.drones
        if dongle_of(d.uri) not in skip_dongles and (only_dongle is None or dongle_of(d.uri) == only_dongle)
    ]
    problem = radio_problem(d.uri for d in drones)
    if problem:
        raise UserError(problem)


def planner_factory(mission: Mission, mission_path: Path) -> PlannerFactory:
    """Each drone gets its own planner instance (its own ONNX session for learned planners); one is made now, so an
    unusable policy is refused before anything connects."""
    from rpf_fly.planning.factory import UnsupportedPlanner, mission_planner, obstacle_set
    from rpf_fly.planning.onnx_policy import PolicyError

    obstacles = obstacle_set(mission.obstacles)
    try:
        mission_planner(mission, obstacles=obstacles)  # fail early, before anything connects
    except (UnsupportedPlanner, PolicyError) as err:
        raise UserError(at(mission_path, f"planner.policy: {err}")) from None
    return lambda drone: mission_planner(mission, obstacles=obstacles)


def lab_info(mission: Mission) -> LabInfo:
    """The running lab's info (rpf_fly/flight/lab.py), checked against ``mission``'s drones: one line when none runs
    or it has not every drone."""
    from rpf_fly.flight.dry_run import uri_address
    from rpf_fly.flight.lab import LabNotRunning, read_lab

    try:
        info = read_lab()
    except LabNotRunning as err:
        raise UserError(f"--lab: {err}") from None
    missing = [d.name for d in mission.drones if uri_address(d.uri) not in info.addresses.values()]
    if missing:
        raise UserError(
            f"--lab: the running lab ({info.mission}) has no drone at the address of "
            f"{', '.join(missing)}: start the lab with this mission"
        )
    return info


def check_log_path(log_path: Path) -> None:
    """The flight log's folder made and writable before anything connects (one line, nothing armed)."""
    try:
        log_path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise UserError(f"--log {log_path}: cannot make its folder: {err.strerror or err}") from None
    existed = log_path.exists()
    try:  # a real try: permissions alone do not say it (root may write anywhere but /proc, a read-only mount)
        with open(log_path, "ab"):
            pass
        if not existed:
            log_path.unlink()
    except OSError as err:
        raise UserError(f"--log {log_path}: cannot write it: {err.strerror or err}") from None


def dongles(text: str | None) -> tuple[int, ...]:
    """``--remote-dongles K[,K...]``: the dongle numbers."""
    if not text:
        return ()
    try:
        return tuple(int(part) for part in text.split(",") if part.strip())
    except ValueError:
        raise UserError(f"--remote-dongles: expected dongle numbers such as 1,2, got {text!r}") from None


def endpoints(values: tuple[str, ...], option: str) -> tuple[str, ...]:
    """Zenoh endpoints given with ``option`` (``--listen``, ``--connect``), each ``PROTO/HOST:PORT``."""
    for value in values:
        proto, sep, rest = value.partition("/")
        if not sep or proto not in ("tcp", "udp", "tls", "quic") or ":" not in rest:
            raise UserError(f"{option}: expected a Zenoh endpoint such as tcp/127.0.0.1:7447, got {value!r}")
    return values
