"""``rpf-fly scenario``: one drone through a dynamics scenario file (streamed setpoints, a hold, or high-level
commands), on a private simulated drone, the running lab's or a real one (rpf_fly/flight/scenario_flight.py,
docs/dynamics.md). The scenario file and the mission are checked here, the mission as every command loads it
(:mod:`rpf_fly.app.checks`); the trace comes back for the CLI to print.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rpf_fly.app import checks
from rpf_fly.app.errors import UserError

if TYPE_CHECKING:
    from rpf_fly.emulator.cf_scenario import Scenario
    from rpf_fly.flight.lab import LabInfo
    from rpf_fly.mission import Mission


@dataclass(frozen=True)
class ScenarioRequest:
    """What ``rpf-fly scenario`` is asked (its options; ``rpf-fly scenario --help``)."""

    file: Path
    dry_run: bool = False
    lab: bool = False
    mission: Path | None = None
    drone: str | None = None
    log: Path | None = None


@dataclass(frozen=True)
class ScenarioFlight:
    """A scenario past its checks: the scenario, the mission and drone that fly it, the lab, its log."""

    scenario: Scenario
    mission: Mission
    drone: str
    dry_run: bool
    lab: LabInfo | None
    log_path: Path

    def run(self, on_event: Callable[[str], None]) -> dict[str, Any]:
        """Fly it and trace it (``on_event``: what happens to the drone, one message each). The drone could not
        fly it (no link, no pose, no take-off): :class:`UserError` with exit code 1."""
        from rpf_fly.flight.scenario_flight import ScenarioError, run_scenario

        try:
            return run_scenario(
                self.scenario,
                self.mission,
                self.drone,
                dry_run=self.dry_run,
                lab=self.lab,
                log_path=self.log_path,
                on_event=on_event,
            )
        except ScenarioError as err:
            raise UserError(str(err), code=1) from None


def prepare_scenario(request: ScenarioRequest) -> ScenarioFlight:
    """The scenario file read, its mission (``--mission``, else a one-drone mission around the scenario's start
    for a simulated drone), the drone, the running lab, the log's folder made."""
    from rpf_fly.emulator.cf_scenario import Scenario
    from rpf_fly.flight.scenario_flight import scenario_mission

    file = request.file
    if request.dry_run and request.lab:
        raise UserError("--dry-run and --lab: choose one")
    try:
        loaded = Scenario.load(file)
    except FileNotFoundError:
        raise UserError(f"{file}: no such file") from None
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise UserError(
            f"{file}: not a scenario file ({err}); expected name, start, duration_s and setpoints with "
            "stream_hz, or commands (docs/dynamics.md)"
        ) from None
    if request.mission is not None:
        mission = checks.load_mission(request.mission)
    elif request.dry_run or request.lab:
        mission = scenario_mission(loaded)
    else:
        raise UserError("a real drone needs its mission (--mission MISSION), or fly the scenario with --dry-run")
    name = request.drone or mission.drones[0].name
    lab = checks.lab_info(mission) if request.lab else None
    log_path = request.log or Path("flights") / f"scenario-{loaded.name}-{datetime.now():%Y%m%d-%H%M%S}.mcap"
    log_path.parent.mkdir(parents=True, exist_ok=True)
    return ScenarioFlight(loaded, mission, name, request.dry_run, lab, log_path)
