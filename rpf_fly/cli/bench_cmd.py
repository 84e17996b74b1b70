"""``rpf-fly bench``: the paper's comparison (planners x scenes x seeds), its table, claims, JSON, Markdown, figure."""

from __future__ import annotations

from pathlib import Path

import typer

from rpf_fly.cli import app
from rpf_fly.cli.errors import fail

_PLANNERS = "rpf,rpf-mean,apf,ppo,orca,rpf3"  # rpf_fly.bench.runner.PLANNERS (not imported: the CLI starts fast)
_SCENES = "arena-a-6,arena-b-6,circle-8-r3,circle-8-r8,lab-3,arena-a-fresh"
_DYNAMICS = ("kinematic", "firmware")  # rpf_fly.sim.closed_loop.DYNAMICS (a test keeps them equal)


@app.command()
def bench(
    suite: str = typer.Option(
        "paper", "--suite", help="paper: the paper missions and arena-a-fresh; families: the generated scene families."
    ),
    episodes: int = typer.Option(
        20, "--episodes", help="Seeds per scene (start jitter 0..N-1; fresh arena-A seeds 1000000..)."
    ),
    seeds: int | None = typer.Option(
        None, "--seeds", help="Seeds per scene or family (overrides --episodes; families: bench-stream seeds 0..N-1)."
    ),
    dynamics: str = typer.Option(
        "kinematic",
        "--dynamics",
        help="kinematic: drones move along their planned headings; firmware: the flight's "
        "closed loop on the simulated Crazyflie firmware (docs/bench.md).",
    ),
    first_seed: int = typer.Option(
        0, "--first-seed", help="families suite: the first bench-stream seed (seeds FIRST..FIRST+N-1; default 0)."
    ),
    planners: str | None = typer.Option(
        None, "--planners", help=f"Comma-separated planner kinds (paper: {_PLANNERS}; families: also default)."
    ),
    scenes: str = typer.Option(_SCENES, "--scenes", help="Comma-separated scenes: paper missions and arena-a-fresh."),
    families: str | None = typer.Option(None, "--families", help="families suite: comma-separated families (all)."),
    jobs: int = typer.Option(1, "--jobs", help="families suite: worker processes (same results; default 1)."),
    guidance: str | None = typer.Option(
        None, "--guidance", help="families suite: comma-separated guidance modes (every mode the planner offers)."
    ),
    policies: Path = typer.Option(Path("policies"), "--policies", help="Folder of <kind>.onnx policies."),
    policy: list[str] = typer.Option(
        [], "--policy", help="KIND=PATH: a policy for one learned kind (rpf, rpf-mean, ppo, rpf3); repeatable."
    ),
    missions: Path = typer.Option(Path("missions"), "--missions", help="Folder of the paper missions."),
    json_output: bool = typer.Option(
        False, "--json", help="Print the results JSON to stdout instead of the table (progress goes to stderr)."
    ),
    json_file: Path | None = typer.Option(None, "--json-file", help="Also write the results JSON to this file."),
    markdown: Path | None = typer.Option(None, "--markdown", help="Write the results as Markdown."),
    figure: Path | None = typer.Option(None, "--figure", help="Write the comparison figure (PNG)."),
    out: Path | None = typer.Option(
        None,
        "--out",
        help="Write results.json, results.md and comparison.png into this folder (families suite: "
        "families.json and families.md).",
    ),
) -> None:
    """Run every planner on every scene for each seed; print success, collisions, path metrics and the paper's claims.

    A learned planner whose policy file is absent or unusable gets 'missing' rows with the reason; the rest runs.
    """
    from rpf_fly.bench.runner import BenchConfig, BenchError, prepare, run_bench

    if suite not in ("paper", "families"):
        raise fail(f"--suite: expected paper or families, got {suite!r}")
    if dynamics not in _DYNAMICS:
        raise fail(f"--dynamics: expected {' or '.join(_DYNAMICS)}, got {dynamics!r}")
    if seeds is not None:
        episodes = seeds
    paths = {}
    for item in policy:
        kind, sep, raw = item.partition("=")
        if not sep or not kind or not raw:
            raise fail(f"--policy: expected KIND=PATH, got {item!r}")
        paths[kind.strip()] = Path(raw)
    from rpf_fly.bench.runner import POLICY_ACTIONS

    unknown = [k for k in paths if k not in POLICY_ACTIONS]
    if unknown:
        raise fail(f"--policy: {unknown[0]!r} is not a learned planner kind ({', '.join(POLICY_ACTIONS)})")
    if first_seed and suite != "families":
        raise fail("--first-seed: only the families suite takes it (the paper suite's seeds are fixed per scene)")
    if suite == "families":
        _families(
            episodes,
            planners,
            families,
            guidance,
            policies,
            paths,
            json_output,
            json_file,
            markdown,
            figure,
            out,
            jobs,
            first_seed,
            dynamics,
        )
        return
    if families is not None or guidance is not None or jobs != 1:
        raise fail("--families, --guidance and --jobs belong to --suite families")
    config = BenchConfig(
        planners=_split(planners or _PLANNERS),
        scenes=_split(scenes),
        episodes=episodes,
        policies_dir=policies,
        policy_paths=paths,
        missions_dir=missions,
        dynamics=dynamics,
    )
    try:
        plan = prepare(config)
    except BenchError as err:
        raise fail(f"rpf-fly bench: {err}") from err
    from rpf_fly.bench.report import REPORT_WIDTH
    from rpf_fly.cli.output import console as make_console

    console = make_console(pipe_width=REPORT_WIDTH)  # piped: the report as laid out, 100 columns
    errors = make_console(stderr=True)
    for reason in dict.fromkeys(plan.missing.values()):
        errors.print(f"[yellow]missing: {reason}[/yellow]")
    result = _run_with_progress(plan, run_bench, errors)

    from rpf_fly.bench.report import print_report, results_json, write_json, write_markdown

    results = results_json(result)
    written = []
    if out is not None:
        written += [write_json(results, out / "results.json"), write_markdown(results, out / "results.md")]
        written.append(_figure(results, result, out / "comparison.png"))
    if json_file is not None:
        written.append(write_json(results, json_file))
    if markdown is not None:
        written.append(write_markdown(results, markdown))
    if figure is not None:
        written.append(_figure(results, result, figure))
    if json_output:
        from rpf_fly.bench.report import dumps

        typer.echo(dumps(results))
        for path in written:
            errors.print(f"wrote {path}")
        return
    print_report(results, console)
    for path in written:
        console.print(f"wrote {path}")


def _families(
    episodes,
    planners,
    families,
    guidance,
    policies,
    paths,
    json_output,
    json_file,
    markdown,
    figure,
    out,
    jobs,
    first_seed=0,
    dynamics="kinematic",
) -> None:
    """``--suite families``: run, print the Markdown report (at most 110 columns), write what was asked for."""
    from rpf_fly.bench.families import (
        FAMILY_PLANNERS,
        FamiliesConfig,
        prepare_families,
        results_json,
        run_families,
        to_markdown,
    )
    from rpf_fly.bench.report import dumps, write_json
    from rpf_fly.bench.runner import BenchError
    from rpf_fly.cli.output import console as make_console
    from rpf_fly.sim.generators import FAMILIES

    if figure is not None:
        raise fail("--figure: the families suite draws no figure (its tables are in the Markdown)")
    config = FamiliesConfig(
        planners=_split(planners) if planners else FAMILY_PLANNERS,
        families=_split(families) if families else tuple(FAMILIES),
        seeds=episodes,
        guidance=_split(guidance) if guidance else None,
        policies_dir=policies,
        policy_paths=paths,
        first_seed=first_seed,
        dynamics=dynamics,
    )
    try:
        plan = prepare_families(config)
    except BenchError as err:
        raise fail(f"rpf-fly bench: {err}") from err
    console = make_console(pipe_width=110)
    errors = make_console(stderr=True)
    for reason in dict.fromkeys(plan.missing.values()):
        errors.print(f"[yellow]missing: {reason}[/yellow]")
    if jobs < 1:
        raise fail(f"--jobs: expected at least 1, got {jobs}")
    import functools

    result = _run_with_progress(plan, functools.partial(run_families, jobs=jobs), errors)
    command = f"rpf-fly bench --suite families --seeds {config.seeds}"
    if config.first_seed:
        command += f" --first-seed {config.first_seed}"
    if config.families != tuple(FAMILIES):
        command += f" --families {','.join(config.families)}"
    if config.planners != FAMILY_PLANNERS:
        command += f" --planners {','.join(config.planners)}"
    if config.guidance is not None:
        command += f" --guidance {','.join(config.guidance)}"
    if config.dynamics != "kinematic":
        command += f" --dynamics {config.dynamics}"
    command += "".join(f" --policy {k}={v}" for k, v in paths.items())
    if jobs != 1:
        command += f" --jobs {jobs}"
    results = results_json(result, command)
    text = to_markdown(results)
    written = []
    if out is not None:
        written.append(write_json(results, out / "families.json"))
        (out / "families.md").write_text(text + "\n")
        written.append(out / "families.md")
    if json_file is not None:
        written.append(write_json(results, json_file))
    if markdown is not None:
        markdown.parent.mkdir(parents=True, exist_ok=True)
        markdown.write_text(text + "\n")
        written.append(markdown)
    if json_output:
        typer.echo(dumps(results))
        for path in written:
            errors.print(f"wrote {path}")
        return
    console.print(text, markup=False, highlight=False, soft_wrap=True)
    for path in written:
        console.print(f"wrote {path}")


def _split(text: str) -> tuple[str, ...]:
    return tuple(part.strip() for part in text.split(",") if part.strip())


def _figure(results, result, path: Path) -> Path:
    from rpf_fly.bench.figure import plot_comparison

    return plot_comparison(results, path, result.trajectories)


def _run_with_progress(plan, run_bench, console):
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    from rpf_fly.cli.output import ProgressLines

    if not console.is_terminal:  # piped: a plain line every 10 s instead of a bar
        lines = ProgressLines("bench", plan.total_runs, "runs", stream=console.file)
        done = [0]

        def line(record) -> None:
            done[0] += 1
            verdict = "ok" if record.success else (record.failure or "failed")
            lines.update(done[0], f"{record.planner} {record.scene} seed {record.seed}: {verdict}")

        return run_bench(plan, line)
    with Progress(
        TextColumn("[bold]bench[/bold]"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("runs"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        TextColumn("{task.fields[now]}"),
        console=console,
        transient=False,
    ) as progress:
        task = progress.add_task("bench", total=plan.total_runs, now="")

        def advance(record) -> None:
            verdict = "ok" if record.success else (record.failure or "failed")
            progress.update(task, advance=1, now=f"{record.planner} {record.scene} seed {record.seed}: {verdict}")

        return run_bench(plan, advance)
