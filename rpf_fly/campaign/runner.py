"""The campaigns, flown one run after another and judged: a lab's campaign on its own mission (`mission_campaign`,
``rpf-fly campaign``) and the maintainers' over several shipped missions (`maintainers_campaign`,
tools/fault_campaign.py). docs/fault-campaign.md says what each flies and judges.

Every run is a real-time dry run in a process of its own, so the runs go one at a time: two at once on a small host
would make the simulated worlds fall behind and the verdicts the host's.
"""

from __future__ import annotations

import contextlib
import random
import shlex
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from rpf_fly.campaign.calm_host import wait_for_a_calm_host
from rpf_fly.campaign.flights import FlightRecord, LabRecord, fly_against_lab, fly_dry_run
from rpf_fly.campaign.judge import Verdict, judge_flight, judge_lab
from rpf_fly.campaign.missions import (
    DYNAMICS,
    FIXED_MISSIONS,
    RANDOM_MISSIONS,
    ROOT,
    mission_path,
    with_dynamics,
    with_extpose,
    with_planner_kind,
    with_world_seed,
)
from rpf_fly.campaign.report import as_json, markdown, source_revision
from rpf_fly.campaign.schedules import (
    ALL_KINDS,
    DEFAULTS,
    LAB_KINDS,
    LAB_RUNS,
    ScheduleError,
    check_kinds,
    draw_faults,
    lab_faults,
    middle_drone_fault,
)
from rpf_fly.mission import MissionError, load_mission

OnVerdict = Callable[[Verdict], None]
"""Told each run's verdict as it ends (a campaign takes minutes: the user sees it go)."""

HOST_TRIES = 3
"""A run whose host fell behind its simulated world is no evidence either way: it is flown again, this many times
in all (docs/flight.md, "When the host cannot keep up")."""
HOST_RETRY_MIN_WAIT_S = 20.0
"""How long a run whose host fell behind waits at least before it is flown again: the last run's processes finish
(its lab's world, its log) and a busy host may calm down. Flown again after a second's calm, a lab run fell behind on
all three tries on an otherwise idle 2-core host."""
HOST_RETRY_WAIT_S = 60.0
"""... and at most, for a calm host (`calm_host.wait_for_a_calm_host`)."""
NOT_EVIDENCE = "this dry run is not evidence"
"""The end of the line a dry run or lab says when its host could not keep up (`rpf_fly.emulator.host_lag`)."""


class CampaignError(ValueError):
    """Bad input to a campaign (a mission that does not load, an unknown kind, an option out of range): one line
    naming the file or option and what was expected."""


@dataclass
class CampaignResult:
    """A flown campaign: the command that reproduces it, the source it flew and every run's verdict."""

    command: str
    revision: str
    verdicts: list[Verdict]

    @property
    def passed(self) -> bool:
        """Every run passed (and there was one)."""
        return bool(self.verdicts) and all(v.passed for v in self.verdicts)

    def markdown(self) -> str:
        """The report (docs/fault-campaign.md's tables are such reports)."""
        return markdown(self.command, self.revision, self.verdicts)

    def json(self) -> dict[str, Any]:
        """The verdicts as one JSON document."""
        return as_json(self.command, self.revision, self.verdicts)


def _ignore(_: Verdict) -> None:
    return None


@contextlib.contextmanager
def _workdir(keep: Path | None) -> Iterator[Path]:
    """``keep`` (made, and left with every run's mission copy, schedule and logs), or a folder removed after."""
    if keep is not None:
        keep.mkdir(parents=True, exist_ok=True)
        yield keep.resolve()
        return
    with tempfile.TemporaryDirectory(prefix="rpf-fly-campaign-") as tmp:
        yield Path(tmp)


def host_fell_behind(record: FlightRecord) -> bool:
    """The run's simulated world fell behind its host: the flight's or its lab's events (or the flight's output,
    all a killed flight leaves) say it is not evidence."""
    topics = [record.topics] + ([record.lab_topics] if isinstance(record, LabRecord) else [])
    said = any(NOT_EVIDENCE in m.get("message", "") for t in topics for _, m in t.get("/events", []))
    return said or NOT_EVIDENCE in record.stderr or NOT_EVIDENCE in record.stdout


_Record = TypeVar("_Record", bound=FlightRecord)


def _evidence(fly: Callable[[], _Record], judge: Callable[[_Record], Verdict]) -> Verdict:
    """``fly`` until its host kept up (at most `HOST_TRIES` times) and judge that flight. A verdict flown more than
    once says so in its events; one whose host fell behind every time fails as no evidence."""
    for tries in range(1, HOST_TRIES + 1):
        record = fly()
        if not host_fell_behind(record):
            verdict = judge(record)
            if tries > 1:
                verdict.events.append(f"campaign: flown {tries} times, the host fell behind on the first {tries - 1}")
            return verdict
        if tries < HOST_TRIES:
            wait_for_a_calm_host(HOST_RETRY_WAIT_S, at_least_s=HOST_RETRY_MIN_WAIT_S)
    verdict = judge(record)
    verdict.failures.append(f"the host fell behind on each of {HOST_TRIES} tries: not evidence, fly it again")
    verdict.passed = False
    return verdict


def fly_and_judge(faults: list[dict[str, Any]], mission_file: Path, workdir: Path, tag: str = "") -> Verdict:
    """One dry run of ``mission_file`` with the schedule ``faults``, judged on its truth (flown again while its host
    fell behind, `HOST_TRIES`)."""
    return _evidence(lambda: fly_dry_run(mission_file, faults, workdir, tag), judge_flight)


def fly_and_judge_lab(fault: dict[str, Any], mission_file: Path, workdir: Path, tag: str = "") -> Verdict:
    """One run of a lab kind against a lab of its own, judged on the lab's log (flown again while its host fell
    behind, `HOST_TRIES`)."""
    return _evidence(lambda: fly_against_lab(mission_file, fault, workdir, tag), judge_lab)


def fixed_runs(mission_file: Path, kinds: list[str], workdir: Path, on_verdict: OnVerdict = _ignore) -> list[Verdict]:
    """Each dry-run kind of ``kinds`` once on ``mission_file``: its default fault, on the middle drone, at 3 s into
    the planning phase (the lab kinds are left to `lab_runs`)."""
    mission = load_mission(mission_file)
    verdicts = []
    for kind in kinds:
        if kind in LAB_KINDS:
            continue
        verdicts.append(fly_and_judge([middle_drone_fault(kind, mission)], mission_file, workdir))
        on_verdict(verdicts[-1])
    return verdicts


def random_campaign(
    runs: int,
    seed: int,
    missions: list[str],
    planners: list[str],
    workdir: Path,
    kinds: list[str] | None = None,
    extpose: bool = False,
    faults_per_run: int = 1,
    vary_world: bool = False,
    only: set[int] | None = None,
    on_verdict: OnVerdict = _ignore,
    dynamics: str | None = None,
) -> list[Verdict]:
    """``runs`` flights, each a mission and planner (``mission``: its own) drawn from ``seed`` and ``faults_per_run``
    faults of different kinds (of ``kinds``, default every dry-run kind), each with its drone, time and parameters
    drawn (`rpf_fly.campaign.schedules.draw_faults`). ``vary_world``: run k of seed S flies the simulated world of
    seed ``S * 1000 + k`` instead of every dry run's 0, so a drone's IMU bias (where it drifts blind) differs from
    run to run. ``only``: fly just these runs (every run's draw is still made, in order, so run k is the campaign's
    run k). ``dynamics``: how the simulated drones fly (`with_dynamics`; default each mission's own)."""
    rng = random.Random(seed)
    verdicts = []
    for run in range(runs):
        mission_name = rng.choice(missions)
        planner = rng.choice(planners)
        path = mission_path(mission_name)
        if planner != "mission":
            path = with_planner_kind(path, planner, workdir)
        if extpose:
            path = with_extpose(path, workdir)
        if dynamics:
            path = with_dynamics(path, dynamics, workdir)
        if vary_world:
            path = with_world_seed(path, seed * 1000 + run, workdir)
        faults, draws = draw_faults(rng, load_mission(path), kinds, faults_per_run)
        if only is not None and run not in only:
            continue
        v = fly_and_judge(faults, path, workdir, tag=f"-r{run}")
        v.params = {
            "run": run,
            "planner": planner,
            **({"world_seed": seed * 1000 + run} if vary_world else {}),
            **(
                {k: x for k, x in draws[0].items() if k not in ("kind", "drone")}
                if len(draws) == 1
                else {"faults": draws}
            ),
        }
        verdicts.append(v)
        on_verdict(v)
    return verdicts


def lab_runs(
    kinds: list[str],
    missions: list[str] | None,
    planner: str | None,
    extpose: bool,
    workdir: Path,
    dynamics: str | None = None,
) -> list[tuple[str, Path, dict[str, Any]]]:
    """The lab kinds' runs among ``kinds`` (kind, mission file, fault): `LAB_RUNS` without ``missions``, else each
    lab kind on each of those missions (`rpf_fly.campaign.schedules.lab_faults`); the lab's drones fly
    ``dynamics`` when given."""
    if missions is None:
        chosen = [
            (kind, ROOT / "missions" / f"{name}.yaml", {"kind": kind, **fields})
            for kind, name, fields in LAB_RUNS
            if kind in kinds
        ]
    else:
        chosen = [
            (f["kind"], path, f) for path in map(mission_path, missions) for f in lab_faults(load_mission(path), kinds)
        ]
    runs = []
    for kind, path, fault in chosen:
        if planner:
            path = with_planner_kind(path, planner, workdir)
        if extpose:
            path = with_extpose(path, workdir)
        if dynamics:
            path = with_dynamics(path, dynamics, workdir)
        runs.append((kind, path, fault))
    return runs


def _kinds(kinds: list[str] | None, random_runs: int) -> list[str] | None:
    """``kinds`` checked; a random campaign draws no lab kind (they fly against a lab, one fault a run)."""
    if kinds is None:
        return None
    try:
        check_kinds(kinds)
    except ScheduleError as err:
        raise CampaignError(str(err)) from None
    if random_runs and LAB_KINDS & set(kinds):
        raise CampaignError(
            f"--kinds: --random draws {', '.join(sorted(LAB_KINDS & set(kinds)))} nowhere: they fly "
            "against a lab, in the campaign without --random only"
        )
    return kinds


def _check_numbers(random_runs: int, faults_per_run: int) -> None:
    if random_runs < 0:
        raise CampaignError(f"--random: expected a number of runs, 0 or more, got {random_runs}")
    if not 1 <= faults_per_run <= len(DEFAULTS):
        raise CampaignError(f"--faults-per-run: expected 1 to {len(DEFAULTS)} faults a run, got {faults_per_run}")


def _check_dynamics(dynamics: str | None, missions: list[Path]) -> None:
    """``--dynamics``: a model the simulated drone has, and one each mission can fly (a vehicle profile,
    ``dry_run.vehicle``, sets the firmware model's gains)."""
    if dynamics is None:
        return
    if dynamics not in DYNAMICS:
        raise CampaignError(f"--dynamics: expected {' or '.join(DYNAMICS)}, got {dynamics!r}")
    if dynamics == "first-order":
        for path in missions:
            try:
                vehicle = load_mission(path).dry_run.vehicle
            except MissionError as err:
                raise CampaignError(str(err)) from None
            if vehicle is not None:
                raise CampaignError(
                    f"--dynamics first-order: {path} gives a vehicle profile (dry_run.vehicle), "
                    "which sets the firmware model's gains: it flies firmware only"
                )


def _check_out(out: Path | None) -> None:
    if out is not None and not out.parent.is_dir():
        raise CampaignError(f"--out: {out}: its folder {out.parent} does not exist")


def mission_campaign(
    mission_file: Path,
    kinds: list[str] | None = None,
    random_runs: int = 0,
    seed: int = 0,
    faults_per_run: int = 2,
    out: Path | None = None,
    keep: Path | None = None,
    on_verdict: OnVerdict = _ignore,
    dynamics: str | None = None,
) -> CampaignResult:
    """A lab's campaign on its own mission before a first flight. Without ``random_runs``: each kind of ``kinds``
    (default every kind) on its own dry run, its default fault on the middle drone, the lab kinds against a lab of
    their own (the kill in each phase, the unplug of the highest dongle). With ``random_runs``: that many dry runs,
    each with ``faults_per_run`` faults of different kinds drawn from ``seed`` (drone, time, parameters) in a
    simulated world of its own. ``dynamics``: how the simulated drones fly (``first-order`` or ``firmware``; default
    the mission's own ``dry_run.dynamics``), in every run, the labs' too. The report goes to ``out`` when given. Bad
    input is a `CampaignError` before anything flies."""
    try:
        mission = load_mission(mission_file)
    except MissionError as err:
        raise CampaignError(str(err)) from None
    except OSError as err:
        raise CampaignError(f"{mission_file}: {err.strerror or err}") from None
    _check_numbers(random_runs, faults_per_run)
    checked = _kinds(kinds, random_runs)
    _check_dynamics(dynamics, [mission_file])
    _check_out(out)
    command = f"rpf-fly campaign {shlex.quote(str(mission_file))}"
    mission_file = mission_file.resolve()  # the runs fly in their work folder
    command += f" --kinds {','.join(checked)}" if checked is not None else ""
    if random_runs:
        command += f" --random {random_runs} --seed {seed} --faults-per-run {faults_per_run}"
    command += f" --dynamics {dynamics}" if dynamics else ""
    with _workdir(keep) as workdir:
        if dynamics:
            mission_file = with_dynamics(mission_file, dynamics, workdir)
        if random_runs:
            verdicts = random_campaign(
                random_runs,
                seed,
                [str(mission_file)],
                ["mission"],
                workdir,
                checked,
                faults_per_run=faults_per_run,
                vary_world=True,
                on_verdict=on_verdict,
            )
        else:
            every = checked or list(ALL_KINDS)
            verdicts = fixed_runs(mission_file, every, workdir, on_verdict)
            for fault in lab_faults(mission, every):
                verdicts.append(fly_and_judge_lab(fault, mission_file, workdir))
                on_verdict(verdicts[-1])
    result = CampaignResult(command, source_revision(), verdicts)
    if out is not None:
        out.write_text(result.markdown())
    return result


def default_report(
    planner: str | None, random_runs: int, seed: int, faults_per_run: int, extpose: bool, dynamics: str | None = None
) -> Path:
    """Where the maintainers' campaign writes its report: docs/fault-campaign/<name>.md, the name saying what flew
    (fixed, the planner's kind, random or compound with the seed; -extpose; -firmware on the firmware model)."""
    variant = ("-extpose" if extpose else "") + ("-firmware" if dynamics == "firmware" else "")
    if random_runs:
        name = f"{'compound' if faults_per_run > 1 else 'random'}{variant}-seed{seed}"
    else:
        name = f"{planner or 'fixed'}{variant}"
    return ROOT / "docs" / "fault-campaign" / f"{name}.md"


def maintainers_campaign(
    missions: list[str] | None = None,
    kinds: list[str] | None = None,
    planner: str | None = None,
    random_runs: int = 0,
    seed: int = 0,
    planners: list[str] | None = None,
    faults_per_run: int = 1,
    vary_world: bool = False,
    extpose: bool = False,
    only: set[int] | None = None,
    keep: Path | None = None,
    on_verdict: OnVerdict = _ignore,
    dynamics: str | None = None,
) -> CampaignResult:
    """The maintainers' campaign over shipped missions (tools/fault_campaign.py; its options, the same names).
    Fixed: each kind on each of ``missions`` (default lab-3, circle-8-r3), ``planner`` instead of each mission's
    own; the lab kinds on `LAB_RUNS` (on ``missions`` when given). Random: `random_campaign` over ``missions``
    (default `RANDOM_MISSIONS`) and ``planners`` (default the mission's own and rpf3). ``dynamics``: every run's
    simulated drones fly that model (`with_dynamics`; default each mission's own)."""
    _check_numbers(random_runs, faults_per_run)
    checked = _kinds(kinds, random_runs)
    flown = missions or (RANDOM_MISSIONS if random_runs else FIXED_MISSIONS).split(",")
    labs = [] if random_runs or missions else [name for _k, name, _f in LAB_RUNS]
    _check_dynamics(dynamics, [mission_path(name) for name in dict.fromkeys(flown + labs)])
    planners = planners or ["mission", "rpf3"]
    command = "python tools/fault_campaign.py"
    command += f" --missions {','.join(missions)}" if missions else ""
    command += f" --kinds {','.join(checked)}" if checked else ""
    command += f" --planner {planner}" if planner and not random_runs else ""
    if random_runs:
        command += f" --random {random_runs} --seed {seed} --planners {','.join(planners)}"
        command += f" --faults-per-run {faults_per_run}" if faults_per_run != 1 else ""
        command += " --vary-world" if vary_world else ""
        command += f" --only {','.join(map(str, sorted(only)))}" if only else ""
    command += " --extpose" if extpose else ""
    command += f" --dynamics {dynamics}" if dynamics else ""
    with _workdir(keep) as workdir:
        if random_runs:
            verdicts = random_campaign(
                random_runs,
                seed,
                missions or RANDOM_MISSIONS.split(","),
                planners,
                workdir,
                checked,
                extpose,
                faults_per_run,
                vary_world,
                only,
                on_verdict,
                dynamics,
            )
        else:
            every = checked or list(ALL_KINDS)
            verdicts = []
            for name in missions or FIXED_MISSIONS.split(","):
                path = mission_path(name)
                path = with_planner_kind(path, planner, workdir) if planner else path
                path = with_extpose(path, workdir) if extpose else path
                path = with_dynamics(path, dynamics, workdir) if dynamics else path
                verdicts += fixed_runs(path, every, workdir, on_verdict)
            for _kind, path, fault in lab_runs(every, missions, planner, extpose, workdir, dynamics):
                verdicts.append(fly_and_judge_lab(fault, path, workdir))
                on_verdict(verdicts[-1])
    return CampaignResult(command, source_revision(), verdicts)
