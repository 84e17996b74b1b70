"""The families suite (``rpf-fly bench --suite families``): every planner, with and without guidance, on scenes of
every generated family (rpf_fly.sim.generators) at fresh seeds of the *bench* stream (docs/bench.md, *Scene
families*).

Per (family, planner, guidance): success, collisions, the smallest separation and obstacle clearance of any run
and how many runs came closer than ``2r + margin`` (drones) and ``r + margin`` (obstacles), travel, makespan and
smoothness; the paper's claims (a)-(e) re-judged on the families (:data:`FAMILY_CLAIMS`) for each guidance mode.

Guidance is an axis of planner settings: the modes are read from the ``guidance`` field of
:class:`~rpf_fly.mission.model.PlannerSettings` (its ``Literal`` values; ``("none",)`` while the field does not
exist), and a run with mode ``m`` flies ``replace(settings, guidance=m)``. Separation and clearance are counted
against one bar for every planner, :data:`BENCH_MARGIN` (0.05 m, ``planner.margin``'s default); each planner's own
margin is reported beside it. ``dynamics`` ``firmware`` flies every run in the flight's closed loop on the firmware
model (rpf_fly.sim.closed_loop: every planner, guidance mode and seed of a family in one simulated swarm) instead of the
kinematic world. Computation only; the Markdown is in :func:`to_markdown`. No torch.
"""

from __future__ import annotations

import dataclasses
import time
import types
import typing
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from rpf_fly.bench.claims import FAMILY_CLAIMS, evaluate_claims
from rpf_fly.bench.runner import (
    PLANNER_LABELS,
    POLICY_ACTIONS,
    BenchError,
    PolicyInfo,
    RunRecord,
    _record,
    check_dynamics,
    closed_loop_json,
    dynamics_line,
    load_policy_info,
    missing_row,
    stat,
    summarise_runs,
)
from rpf_fly.mission.model import PlannerSettings
from rpf_fly.sim.closed_loop import FirmwareParams
from rpf_fly.sim.generators import DEFAULT_MARGIN, FAMILIES, generate, split_seeds
from rpf_fly.sim.rollout import SimParams

DEFAULT_PLANNER = "default"
"""The product's default planner: ``PlannerSettings()`` as a mission without a ``planner.kind`` gets it."""
FAMILY_PLANNERS = ("rpf", "rpf-mean", "apf", "ppo", "orca", DEFAULT_PLANNER)
"""The suite's planners by default (the product's default among them, as ``default``)."""
KNOWN_PLANNERS = FAMILY_PLANNERS + ("rpf3",)
"""What ``--planners`` may name: also RPF-3 (``rpf3``) by its own name."""
SPLIT = "bench"
"""The seed stream of the suite; the trainer's curriculum draws from ``train``."""
SIM = SimParams()
"""Kinematics of every family run: 0.5 m/s, 10 Hz, goal tolerance 0.1 m, 100 s."""


def guidance_modes(settings_type: type = PlannerSettings) -> tuple[str, ...]:
    """The guidance modes the planner settings offer: the ``Literal`` values of the ``guidance`` field (also
    inside an ``Optional``), ``none`` first; ``("none",)`` while there is no such field."""
    if not any(f.name == "guidance" for f in dataclasses.fields(settings_type)):
        return ("none",)
    values = [str(v) for v in _literal_values(typing.get_type_hints(settings_type)["guidance"]) if v is not None]
    if not values:
        raise BenchError(f"{settings_type.__name__}.guidance has no Literal values to bench")
    return tuple(dict.fromkeys(["none", *values] if "none" in values else values))


def _literal_values(hint: Any) -> list[Any]:
    if typing.get_origin(hint) is typing.Literal:
        return list(typing.get_args(hint))
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        return [v for arg in typing.get_args(hint) for v in _literal_values(arg)]
    return []


def with_guidance(settings: PlannerSettings, mode: str) -> PlannerSettings:
    """The settings flown with guidance ``mode`` (unchanged for ``none`` while the field does not exist)."""
    if any(f.name == "guidance" for f in dataclasses.fields(settings)):
        if mode not in ("none", "path"):
            raise BenchError(f"guidance {mode!r}: expected none or path")
        return replace(settings, guidance="none" if mode == "none" else "path")
    if mode != "none":
        raise BenchError(f"guidance {mode!r}: the planner settings have no guidance field")
    return settings


BENCH_MARGIN = DEFAULT_MARGIN
"""m: the margin every planner's separation and clearance are counted against (``planner.margin``'s default, the
acceptance bar), whatever margin the planner itself keeps (reported beside it)."""


def planner_margin(settings: PlannerSettings) -> float | None:
    """The margin the planner keeps by its own settings (``margin_m``, else ``margin``), None where it has none."""
    value = getattr(settings, "margin_m", None)
    if value is None:
        value = getattr(settings, "margin", None)
    return None if value is None else float(value)


def default_kind() -> str:
    return PlannerSettings().kind


def label(planner: str) -> str:
    if planner == DEFAULT_PLANNER:
        return f"default ({PLANNER_LABELS.get(default_kind(), default_kind())})"
    return PLANNER_LABELS.get(planner, planner)


@dataclass(frozen=True)
class FamiliesConfig:
    """What to run: ``seeds`` bench-stream seeds ``first_seed..first_seed+N-1`` per family (``first_seed`` 0 by
    default; a later one gives scenes nobody has looked at); ``guidance`` None: every mode offered; ``dynamics``:
    ``kinematic`` or ``firmware`` (rpf_fly.sim.closed_loop.DYNAMICS); ``closed_loop``: the firmware closed loop's
    settings (the bench's are the defaults; ``plan_from="truth"`` flies the planners on the true state as it is)."""

    planners: tuple[str, ...] = FAMILY_PLANNERS
    families: tuple[str, ...] = tuple(FAMILIES)
    seeds: int = 20
    guidance: tuple[str, ...] | None = None
    policies_dir: Path = Path("policies")
    policy_paths: Mapping[str, Path] = field(default_factory=dict)
    first_seed: int = 0
    dynamics: str = "kinematic"
    closed_loop: FirmwareParams = FirmwareParams()

    def seed_list(self) -> list[int]:
        return split_seeds(SPLIT, self.seeds, self.first_seed)

    def modes(self) -> tuple[str, ...]:
        return self.guidance if self.guidance is not None else guidance_modes()


@dataclass(frozen=True)
class FamiliesPlan:
    """A checked configuration: resolved settings per planner (or why it cannot run)."""

    config: FamiliesConfig
    settings: dict[str, PlannerSettings]
    policies: dict[str, PolicyInfo]
    missing: dict[str, str]

    @property
    def total_runs(self) -> int:
        ready = [p for p in self.config.planners if p not in self.missing]
        return len(ready) * len(self.config.modes()) * len(self.config.families) * self.config.seeds


@dataclass(frozen=True)
class FamiliesResult:
    config: FamiliesConfig
    runs: list[tuple[str, RunRecord]]
    """(guidance, record) per run."""
    rows: list[dict[str, Any]]
    policies: dict[str, PolicyInfo]
    wall_s: float
    margins: dict[str, float | None]
    """Each planner's own margin (None: it has none)."""


def prepare_families(config: FamiliesConfig) -> FamiliesPlan:
    """Check names and policies; a planner whose policy is unusable gets ``missing`` rows."""
    unknown = [p for p in config.planners if p not in KNOWN_PLANNERS]
    if unknown:
        raise BenchError(f"unknown planner {unknown[0]!r} (expected some of {', '.join(KNOWN_PLANNERS)})")
    unknown = [f for f in config.families if f not in FAMILIES]
    if unknown:
        raise BenchError(f"unknown scene family {unknown[0]!r} (expected some of {', '.join(FAMILIES)})")
    if config.seeds < 1:
        raise BenchError(f"seeds must be at least 1, got {config.seeds}")
    if config.first_seed < 0:
        raise BenchError(f"first seed must be at least 0, got {config.first_seed}")
    check_dynamics(config.dynamics)
    offered = guidance_modes()
    unknown = [m for m in config.modes() if m not in offered]
    if unknown or not config.modes():
        raise BenchError(f"unknown guidance {(unknown or [''])[0]!r} (the planner settings offer {', '.join(offered)})")
    settings: dict[str, PlannerSettings] = {}
    policies: dict[str, PolicyInfo] = {}
    missing: dict[str, str] = {}
    for planner in config.planners:
        kind = default_kind() if planner == DEFAULT_PLANNER else planner
        base = PlannerSettings() if planner == DEFAULT_PLANNER else replace(PlannerSettings(), kind=kind, policy=None)
        if kind in POLICY_ACTIONS and (planner != DEFAULT_PLANNER or base.policy is None):
            path = config.policy_paths.get(kind) or Path(config.policies_dir) / f"{kind}.onnx"
            info = policies.get(kind) or load_policy_info(kind, path)
            policies[kind] = info
            if info.missing:
                missing[planner] = info.missing
                continue
            base = replace(base, policy=info.path)
        settings[planner] = base
    return FamiliesPlan(config, settings, policies, missing)


def run_families(
    plan: FamiliesPlan, on_run: Callable[[RunRecord], None] | None = None, jobs: int = 1
) -> FamiliesResult:
    """Every (family, planner, guidance, seed); ``on_run`` after each run (progress). ``jobs > 1`` runs the
    (family, planner, guidance) groups in that many worker processes (spawned); the results are the same, in the
    same order (every run is independent and seeded)."""
    config = plan.config
    started = time.perf_counter()
    seeds = config.seed_list()
    tasks: list[tuple[str, str, str]] = [
        (f, p, m) for f in config.families for p in config.planners for m in config.modes()
    ]
    done: dict[int, tuple[list[RunRecord], str | None]] = {}
    todo = [(k, t) for k, t in enumerate(tasks) if t[1] not in plan.missing]

    def finished(k: int, outcome: tuple[list[RunRecord], str | None], report: bool) -> None:
        done[k] = outcome
        if report and on_run is not None:
            for record in outcome[0]:
                on_run(record)

    if config.dynamics == "firmware":  # one swarm per family: its groups' records come when its last run ends
        by_family: dict[str, list[tuple[int, tuple[PlannerSettings, str, str]]]] = {}
        for k, (family, planner, mode) in todo:
            by_family.setdefault(family, []).append((k, (plan.settings[planner], planner, mode)))

        def flown(family: str, outcomes: list[tuple[list[RunRecord], str | None]]) -> None:
            for (k, _), outcome in zip(by_family[family], outcomes):
                finished(k, outcome, True)

        if jobs <= 1:
            for family, items in by_family.items():
                flown(family, _run_family_firmware(family, seeds, [group for _, group in items], config.closed_loop))
        else:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor, as_completed

            with ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
                jobs_of = {
                    pool.submit(
                        _run_family_firmware, family, seeds, [group for _, group in items], config.closed_loop
                    ): family
                    for family, items in by_family.items()
                }
                for family_done in as_completed(jobs_of):
                    flown(jobs_of[family_done], family_done.result())
    elif jobs <= 1:
        for k, (family, planner, mode) in todo:
            finished(k, _run_group(family, seeds, plan.settings[planner], planner, mode, on_run), False)
    else:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor, as_completed

        with ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
            futures = {
                pool.submit(_run_group, family, seeds, plan.settings[planner], planner, mode): k
                for k, (family, planner, mode) in todo
            }
            for future in as_completed(futures):
                finished(futures[future], future.result(), True)
    runs: list[tuple[str, RunRecord]] = []
    rows: list[dict[str, Any]] = []
    margins: dict[str, float | None] = {}
    for k, (family, planner, mode) in enumerate(tasks):
        if planner in plan.missing:
            rows.append(_missing(planner, family, mode, plan.missing[planner]))
            continue
        records, error = done[k]
        runs += [(mode, r) for r in records]
        if error is not None:
            rows.append(_missing(planner, family, mode, error))
            continue
        settings = with_guidance(plan.settings[planner], mode)
        margins[planner] = planner_margin(settings)
        row = summarise_family(planner, family, mode, records, settings.safety_radius, BENCH_MARGIN)
        rows.append({**row, "planner_margin_m": planner_margin(settings)})
    return FamiliesResult(config, runs, rows, dict(plan.policies), time.perf_counter() - started, margins)


def _run_group(
    family: str,
    seeds: Sequence[int],
    base: PlannerSettings,
    planner: str,
    mode: str,
    on_run: Callable[[RunRecord], None] | None = None,
) -> tuple[list[RunRecord], str | None]:
    """The runs of one (family, planner, guidance) over the seeds, or the reason it cannot run."""
    from rpf_fly.planning.factory import UnsupportedPlanner
    from rpf_fly.planning.onnx_policy import PolicyError
    from rpf_fly.sim.evaluate import run_scenario

    settings = with_guidance(base, mode)
    records: list[RunRecord] = []
    try:
        for seed in seeds:
            run = run_scenario(generate(family, seed, split=SPLIT), settings, SIM, seed, family, keep=True)
            record = _record(run, planner, family)
            records.append(record)
            if on_run is not None:
                on_run(record)
    except (UnsupportedPlanner, PolicyError) as err:
        return records, str(err)
    return records, None


def _run_family_firmware(
    family: str,
    seeds: Sequence[int],
    groups: Sequence[tuple[PlannerSettings, str, str]],
    closed_loop: FirmwareParams = FirmwareParams(),
) -> list[tuple[list[RunRecord], str | None]]:
    """Every (planner, guidance) group ``(settings, planner, mode)`` of one family over the seeds on the firmware
    model, all in one simulated swarm (a swarm's tick costs little more for all of them than for one group); per
    group its records, or the reason it cannot run (its planner could not be made: no run of it flies)."""
    from rpf_fly.planning.factory import AnyPlanner, UnsupportedPlanner, make_planner
    from rpf_fly.planning.onnx_policy import PolicyError
    from rpf_fly.sim.closed_loop import run_firmware

    scenes = [generate(family, seed, split=SPLIT) for seed in seeds]
    errors: list[str | None] = []
    flown: list[tuple[int, PlannerSettings, AnyPlanner, int]] = []  # (group, settings, planner, seed index)
    for g, (base, _, mode) in enumerate(groups):
        settings = with_guidance(base, mode)
        try:
            made = [make_planner(settings, sc.obstacles, (sc.arena_x, sc.arena_y), sc.goals) for sc in scenes]
        except (UnsupportedPlanner, PolicyError) as err:
            errors.append(str(err))
            continue
        errors.append(None)
        flown += [(g, settings, planner, i) for i, planner in enumerate(made)]
    runs = run_firmware(
        [scenes[i] for *_, i in flown],
        [st for _, st, _, _ in flown],
        SIM,
        [seeds[i] for *_, i in flown],
        [family] * len(flown),
        closed_loop,
        keep=True,
        planners=[pl for _, _, pl, _ in flown],
    )
    records: list[list[RunRecord]] = [[] for _ in groups]
    for (g, _, _, _), run in zip(flown, runs):
        records[g].append(_record(run, groups[g][1], family))
    return list(zip(records, errors))


def _missing(planner: str, family: str, mode: str, reason: str) -> dict[str, Any]:
    return {**missing_row(planner, family, reason), "guidance": mode}


def summarise_family(
    planner: str, family: str, mode: str, runs: Sequence[RunRecord], safety_radius: float, margin: float
) -> dict[str, Any]:
    """The bench row (rpf_fly.bench.runner.summarise_runs) plus guidance, separation and clearance."""
    row = summarise_runs(planner, family, runs)
    row["guidance"] = mode
    sep_bar, clear_bar = round(2 * safety_radius + margin, 9), round(safety_radius + margin, 9)  # 0.1 + 0.05
    seps = [r.min_separation_m for r in runs if r.min_separation_m is not None]
    clears = [r.min_obstacle_clearance_m for r in runs if r.min_obstacle_clearance_m is not None]
    row["margin_m"] = margin
    row["min_separation_m"] = {**(stat(seps) or {}), "min": min(seps)} if seps else None
    row["min_obstacle_clearance_m"] = {**(stat(clears) or {}), "min": min(clears)} if clears else None
    row["below_margin"] = {
        "separation_bar_m": sep_bar,
        "clearance_bar_m": clear_bar,
        "runs_separation": sum(1 for s in seps if s < sep_bar),
        "runs_clearance": sum(1 for c in clears if c < clear_bar),
    }
    return row


# -- results document --------------------------------------------------------------------------------------------


def results_json(result: FamiliesResult, command: str = "") -> dict[str, Any]:
    """The families results: settings, policies, rows, every run (with its guidance), claims per guidance mode."""
    c = result.config
    doc: dict[str, Any] = {
        "bench": "rpf-fly bench --suite families",
        "version": 1,
        "dynamics": c.dynamics,
        **closed_loop_json(c.dynamics, c.closed_loop),
        "command": command,
        "wall_s": round(result.wall_s, 1),
        "split": SPLIT,
        "seeds": {"first": c.seed_list()[0], "count": c.seeds},
        "families": list(c.families),
        "family_about": {f: FAMILIES[f].about for f in c.families},
        "planners": list(c.planners),
        "default_kind": default_kind(),
        "guidance": list(c.modes()),
        "bench_margin_m": BENCH_MARGIN,
        "planner_margins_m": dict(result.margins),
        "sim": dataclasses.asdict(SIM),
        "policies": {kind: info.to_json_dict() for kind, info in result.policies.items()},
        "rows": result.rows,
        "runs": [{**r.to_json_dict(), "guidance": mode} for mode, r in result.runs],
    }
    doc["claims"] = {mode: [cl.to_json_dict() for cl in claims_for(doc, mode)] for mode in c.modes()}
    return doc


def claims_for(results: Mapping[str, Any], mode: str) -> list:
    """Claims (a)-(e) judged on the rows and runs of one guidance mode (FAMILY_CLAIMS' scenes)."""
    subset = {
        "rows": [r for r in results["rows"] if r.get("guidance") == mode],
        "runs": [r for r in results["runs"] if r.get("guidance") == mode],
    }
    return evaluate_claims(subset, FAMILY_CLAIMS)


# -- Markdown ----------------------------------------------------------------------------------------------------


def _n(value: float | None, digits: int) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def _ms(s: Mapping[str, float] | None, digits: int) -> str:
    if not s:
        return "-"
    return f"{s['mean']:.{digits}f}" if s["n"] <= 1 else f"{s['mean']:.{digits}f}±{s['std']:.{digits}f}"


def _who(row: Mapping[str, Any]) -> str:
    return label(row["planner"])


def to_markdown(results: Mapping[str, Any]) -> str:
    """Overview (success per family), per family a safety table and a path table, then the claims per guidance
    mode. Every line at most 110 columns."""
    fams = list(results["families"])
    modes = list(results["guidance"])
    rows = list(results["rows"])
    seeds = results["seeds"]
    lines = [
        "# rpf-fly bench: scene families",
        "",
        f"{seeds['count']} seeds per family from the `{results['split']}` stream (seeds {seeds['first']}.."
        f"{seeds['first'] + seeds['count'] - 1}; training draws from",
        "`train`: docs/bench.md, *Scene families*).",
        f"Guidance modes: {', '.join(modes)}. Default planner: `{results['default_kind']}`. "
        f"Wall time: {results['wall_s']:.0f} s.",
        f"Margin m of the counts: {results.get('bench_margin_m', 0.05):g} m for every planner (r = 0.1 m).",
        dynamics_line(results),
    ]
    if results.get("command"):
        lines += ["", "```", results["command"], "```"]
    lines += ["", "## Policies", ""]
    for kind, info in results.get("policies", {}).items():
        lines.append(
            f"- `{kind}`: **missing**: {info['missing']}"
            if "missing" in info
            else f"- `{kind}`: `{Path(info['path']).name}` sha256 `{info['sha256'][:16]}…`"
        )
    if not results.get("policies"):
        lines.append("No learned planner in this run.")
    lines += ["", "## Success (successful runs / runs)", ""]
    short = {f: f[:8] for f in fams}
    header = ["planner", "guid."] + [short[f] for f in fams]
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    by_key = {(r["planner"], r["scene"], r.get("guidance")): r for r in rows}
    for planner in results["planners"]:
        for mode in modes:
            cells = [label(planner), mode]
            for f in fams:
                r = by_key.get((planner, f, mode))
                cells.append("miss." if r is None or r["status"] != "ok" else f"{r['successes']}/{r['runs']}")
            lines.append("| " + " | ".join(cells) + " |")
    lines += [
        "",
        "Per family: **safety** (coll.: collision events drone-drone/drone-obstacle; failed: runs by cause",
        "collision/stalled/timeout; sep: smallest drone-drone distance of any run, `<2r+m`: runs below",
        "2r + margin; clr: smallest obstacle clearance, `<r+m`: runs below r + margin) and **paths** (means",
        "± std over successful runs; travel, all: over every run where a drone arrived).",
        "",
    ]
    for f in fams:
        lines += [f"### {f}", "", f"{results.get('family_about', {}).get(f, '')}", ""]
        head = [
            "planner",
            "guid.",
            "success",
            "reached",
            "coll. dd/do",
            "failed c/s/t",
            "sep [m]",
            "<2r+m",
            "clr [m]",
            "<r+m",
        ]
        lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        fam_rows = [r for r in rows if r["scene"] == f]
        for r in fam_rows:
            if r["status"] != "ok":
                lines.append(f"| {_who(r)} | {r['guidance']} | missing |" + " |" * (len(head) - 3))
                continue
            c, fr, b = r["collisions"], r["failed_runs"], r["below_margin"]
            sep, clr = r["min_separation_m"], r["min_obstacle_clearance_m"]
            lines.append(
                "| "
                + " | ".join(
                    [
                        _who(r),
                        r["guidance"],
                        f"{r['successes']}/{r['runs']}",
                        f"{r['reached_rate']:.0%}",
                        f"{c['drone_drone']}/{c['drone_obstacle']}",
                        f"{fr['collision']}/{fr['stalled']}/{fr['timeout']}",
                        _n(sep["min"] if sep else None, 3),
                        str(b["runs_separation"]) if sep else "-",
                        _n(clr["min"] if clr else None, 3),
                        str(b["runs_clearance"]) if clr else "-",
                    ]
                )
                + " |"
            )
        lines.append("")
        head = ["planner", "guid.", "travel [m]", "makespan [s]", "smoothness", "travel, all"]
        lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for r in fam_rows:
            if r["status"] != "ok":
                continue
            every = r["travel_distance_m"]["all"]
            lines.append(
                "| "
                + " | ".join(
                    [
                        _who(r),
                        r["guidance"],
                        _ms(r["travel_distance_m"]["successful"], 2),
                        _ms(r["makespan_s"]["successful"], 1),
                        _ms(r["smoothness"]["successful"], 4),
                        "-" if every is None else f"{_ms(every, 2)} ({every['n']})",
                    ]
                )
                + " |"
            )
        lines.append("")
    import textwrap

    for mode in modes:
        lines += [
            f"## The paper's claims, guidance {mode}",
            "",
            "Judged as docs/bench.md, *The claims on the families*, says; the numbers are in the JSON.",
            "",
        ]
        for cl in results["claims"][mode]:
            text = f"- **({cl['id']}) {cl['status']}**: {cl['statement']}." + (f" {cl['note']}." if cl["note"] else "")
            lines += textwrap.wrap(text, width=110, subsequent_indent="  ", break_on_hyphens=False)
        lines.append("")
    return "\n".join(lines)
