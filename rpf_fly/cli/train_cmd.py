"""``rpf-fly train``: PPO training with a progress bar, curves, checkpoints, ONNX export and a model card."""

from __future__ import annotations

import shlex
import sys
import time
from pathlib import Path
from typing import Literal, TypeVar

import typer

from rpf_fly.cli import app
from rpf_fly.cli.errors import fail

_Choice = TypeVar("_Choice", bound=str)
KINDS: tuple[Literal["rpf", "rpf-mean", "ppo"], ...] = ("rpf", "rpf-mean", "ppo")
ARENAS: tuple[Literal["a", "b", "both"], ...] = ("a", "b", "both")
GUIDANCE: tuple[Literal["none", "path"], ...] = ("none", "path")


def _pick(value: str, choices: tuple[_Choice, ...]) -> _Choice | None:
    """The one of ``choices`` that ``value`` names (typed as the choices are), None if none."""
    return next((c for c in choices if c == value), None)


PAPER_MISSIONS = ("arena-a-6", "arena-b-6", "circle-8-r3", "circle-8-r8", "lab-3")


@app.command()
def train(
    out: Path = typer.Option(..., "--out", help="Where to write the ONNX policy (the run folder sits beside it)."),
    kind: str = typer.Option("rpf", "--kind", help="rpf (attention), rpf-mean (RPF-2) or ppo (heading baseline)."),
    no_attention: bool = typer.Option(False, "--no-attention", help="Same as --kind rpf-mean."),
    arena: str = typer.Option("both", "--arena", help="Training arenas: a, b or both."),
    curriculum: str = typer.Option(
        "",
        "--curriculum",
        help="Comma-separated scene families to train on instead of --arena (all: every family; "
        "training seed stream, docs/bench.md).",
    ),
    guidance: str = typer.Option(
        "none",
        "--guidance",
        help="none (the paper's environment) or path (global guidance, as the product flies: RPF-3).",
    ),
    margin: float = typer.Option(
        0.0, "--margin", help="Clearance beyond contact (m) kept by the planner and asked by the reward (RPF-3: 0.05)."
    ),
    capture_radius: float = typer.Option(
        0.0,
        "--capture-radius",
        help="The planner's capture rule near the goal (m; "
        "docs/algorithm.md Arrival): 0, the paper's, turns it off; the product "
        "flies 0.3.",
    ),
    episodes: int = typer.Option(4000, "--episodes", help="Stop after this many finished arena episodes."),
    collision_penalty: float = typer.Option(500.0, "--collision-penalty", help="Reward of a collision (negated)."),
    margin_penalty: float = typer.Option(
        20.0,
        "--margin-penalty",
        help="Per step inside r + margin of an obstacle or 2r + margin of a drone (negated; with --margin).",
    ),
    max_updates: int = typer.Option(
        10_000,
        "--max-updates",
        help="Stop after this many PPO updates (whichever of --episodes and --max-updates comes first).",
    ),
    seed: int = typer.Option(0, "--seed", help="Seed of the weights, the scenes and the sampling."),
    arenas: int = typer.Option(48, "--arenas", help="Parallel arenas (6 drones each)."),
    threads: int = typer.Option(
        2,
        "--threads",
        help="torch threads (1 on a machine shared with other jobs: two "
        "threads on two busy cores spin against each other).",
    ),
    resume: bool = typer.Option(False, "--resume", help="Continue from the run folder's checkpoint."),
    eval_seeds: int = typer.Option(
        20, "--eval-seeds", help="Seeds per scene in the model card's evaluation (0: none)."
    ),
    obstacle_radius: float | None = typer.Option(
        None, "--obstacle-radius", help="Arena A obstacle radius (default 0.5 m; 0.1 m for the ppo baseline)."
    ),
    missions_dir: Path = typer.Option(Path("missions"), "--missions", help="Paper missions for the evaluation."),
    force: bool = typer.Option(False, "--force", help="Overwrite an existing policy, model card and curves at --out."),
) -> None:
    """Train a policy with PPO from the paper's reward, export it to ONNX (parity-checked) and write its model card.

    An existing policy (or its model card or curves) at --out is never overwritten without --force."""
    if no_attention:
        kind = "rpf-mean"
    kind_chosen = _pick(kind, KINDS)
    if kind_chosen is None:
        raise fail(f"--kind: expected rpf, rpf-mean or ppo, got {kind!r}")
    arena_chosen = _pick(arena, ARENAS)
    if arena_chosen is None:
        raise fail(f"--arena: expected a, b or both, got {arena!r}")
    from rpf_fly.sim.generators import FAMILIES

    families = (
        tuple(FAMILIES) if curriculum.strip() == "all" else tuple(f.strip() for f in curriculum.split(",") if f.strip())
    )
    unknown = [f for f in families if f not in FAMILIES]
    if unknown:
        raise fail(f"--curriculum: unknown scene family {unknown[0]!r} (expected all or some of {', '.join(FAMILIES)})")
    guidance_chosen = _pick(guidance, GUIDANCE)
    if guidance_chosen is None:
        raise fail(f"--guidance: expected none or path, got {guidance!r}")
    if not 0.0 <= margin < 1.0:
        raise fail(f"--margin: expected metres in [0, 1), got {margin}")
    if not 0.0 <= capture_radius < 2.0:
        raise fail(f"--capture-radius: expected metres in [0, 2), got {capture_radius}")
    if out.suffix != ".onnx":
        raise fail(f"--out: expected a path ending in .onnx, got {str(out)!r}")
    existing = [p for p in written_files(out) if p.exists()]
    if existing and not force:
        raise fail(
            f"--out: refusing to overwrite {', '.join(str(p) for p in existing)}: choose another --out, or add --force"
        )
    try:
        import torch  # noqa: F401
    except ImportError as err:
        from rpf_fly import install_hint

        raise fail(f"rpf-fly train needs torch: {install_hint('train')} (torch==2.13.0, CPU build)") from err
    from rpf_fly.learn.ppo import PPOConfig, Trainer

    radius = obstacle_radius if obstacle_radius is not None else (0.1 if kind == "ppo" else 0.5)
    config = PPOConfig(
        seed=seed,
        kind=kind_chosen,
        arena=arena_chosen,
        curriculum=families,
        episodes=episodes,
        max_updates=max_updates,
        n_arenas=arenas,
        obstacle_radius=radius,
        guidance=guidance_chosen,
        margin=margin,
        threads=threads,
        collision_penalty=collision_penalty,
        margin_penalty=margin_penalty,
        capture_radius=capture_radius,
    )
    run_dir = out.with_suffix(".run")
    command = (
        "rpf-fly train " + " ".join(shlex.quote(a) for a in sys.argv[2:]) if len(sys.argv) > 2 else "rpf-fly train"
    )
    from rpf_fly.learn.card import git_commit

    commit = git_commit()  # the code that trains: taken now, not at export time
    trainer = Trainer(config, run_dir)
    if resume:
        if not trainer.checkpoint_path.exists():
            raise fail(f"--resume: no checkpoint at {trainer.checkpoint_path}")
        trainer.load_checkpoint()
    started = time.time()
    cpu_started = time.process_time()
    _train_with_progress(trainer)
    cpu_s = time.process_time() - cpu_started
    _finish(trainer, out, command, eval_seeds, missions_dir, time.time() - started, commit, cpu_s)


def written_files(out: Path) -> tuple[Path, ...]:
    """What a training run writes beside its run folder: the policy, its model card and its curves."""
    return (out, out.with_suffix(".yaml"), out.with_suffix(".curve.csv"), out.with_suffix(".curve.png"))


def _stats(log) -> str:
    return (
        f"return {log.mean_return:7.1f}  success {log.success_rate:4.0%}  kl {log.approx_kl:.4f}  "
        f"{log.steps_per_s:6.0f} steps/s"
    )


def _train_with_progress(trainer) -> None:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from rpf_fly.cli.output import ProgressLines, console

    target = trainer.config.episodes
    out = console()
    if not out.is_terminal:  # piped: a plain line every 10 s instead of a bar
        lines = ProgressLines("train", target, "episodes")
        last: list = []

        def line(log) -> None:
            last[:] = [log]
            lines.update(min(log.episodes, target), " ".join(_stats(log).split()))

        trainer.run(line)
        if last:
            lines.update(min(last[0].episodes, target), " ".join(_stats(last[0]).split()), final=True)
        return
    with Progress(
        TextColumn("[bold]train[/bold]"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("episodes"),
        TimeElapsedColumn(),
        TextColumn("{task.fields[stats]}"),
        console=out,
        transient=False,
    ) as progress:
        task = progress.add_task("train", total=target, completed=len(trainer.episodes), stats="")

        def update(log) -> None:
            progress.update(task, completed=min(log.episodes, target), stats=_stats(log))

        trainer.run(update)


def _finish(
    trainer,
    out: Path,
    command: str,
    eval_seeds: int,
    missions_dir: Path,
    wall_s: float,
    commit: str,
    cpu_s: float | None = None,
) -> None:
    import dataclasses

    from rpf_fly.learn.card import machine, write_card
    from rpf_fly.learn.curves import plot_curves
    from rpf_fly.learn.export import check_parity, export_onnx, file_sha256

    config = trainer.config
    model = trainer.best_model()  # the weights that scored best on the validation scenes (not the paper missions)
    export_onnx(
        model,
        out,
        {
            "rpf_fly.kind": config.kind,
            "rpf_fly.preset": "robust",
            "rpf_fly.seed": str(config.seed),
            "rpf_fly.commit": commit,
            "rpf_fly.guidance": config.guidance,
            "rpf_fly.margin": str(config.margin),
        },
    )
    parity = check_parity(model, out)
    curve_csv = out.with_suffix(".curve.csv")
    curve_csv.write_text((trainer.out_dir / "training_curve.csv").read_text())
    curve_png = plot_curves(curve_csv, out.with_suffix(".curve.png"), title=f"{config.kind}, seed {config.seed}")
    card = {
        "policy": out.name,
        "kind": config.kind,
        "sha256": file_sha256(out),
        "command": command,
        "seed": config.seed,
        "commit": commit,
        "training": {
            "wall_time_s": round(trainer.wall_s, 1),
            "this_invocation_s": round(wall_s, 1),
            "cpu_time_s": None if cpu_s is None else round(cpu_s, 1),
            "load_average_at_end": _load_average(),
            "updates": trainer.update,
            "arena_episodes": len(trainer.episodes),
            "env_steps": trainer.env_steps,
            "robot_steps": trainer.env_steps * 6,
            "final_success_rate_last_200": trainer.history[-1].success_rate if trainer.history else None,
            "selected_update": trainer.best["update"] if trainer.best else trainer.update,
            "selected_validation": (
                {
                    "success_rate": trainer.best["success"],
                    "mean_return": trainer.best["return"],
                    "scenes": config.eval_episodes,
                    "seed": config.eval_seed,
                }
                if trainer.best
                else None
            ),
            "hyperparameters": dataclasses.asdict(config),
            "machine": machine(),
        },
        "export": {"opset": 17, "max_neighbours": config.max_neighbours, "parity_max_abs_diff": parity},
        "curves": {"csv": curve_csv.name, "png": curve_png.name},
    }
    if eval_seeds > 0:
        card["evaluation"] = _evaluate(out, config.kind, eval_seeds, missions_dir)
    write_card(out.with_suffix(".yaml"), card)
    typer.echo(f"policy: {out}  (parity max |ort - torch| = {parity:.2e})")
    typer.echo(f"model card: {out.with_suffix('.yaml')}  curves: {curve_png}")


def _load_average() -> list[float] | None:
    """The 1, 5 and 15 minute load averages (the machine may be shared: wall time alone misleads)."""
    import os

    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return None


def _evaluate(policy: Path, kind: str, seeds: int, missions_dir: Path) -> dict:
    """Success and path metrics on fresh arena-A scenes (seeds never used in training) and the paper missions."""
    from rpf_fly.mission import load_mission
    from rpf_fly.sim.evaluate import evaluate_arena_a, evaluate_mission, planner_settings, summarise

    result: dict = {"seeds": seeds}
    fresh = range(1_000_000, 1_000_000 + seeds)  # training scenes come from the training seed's generator
    settings = planner_settings(kind, policy.resolve())
    result["arena-a-fresh"] = summarise(evaluate_arena_a(settings, fresh))
    result["arena-a-fresh-clear0.5"] = summarise(evaluate_arena_a(settings, fresh, goal_clearance=0.5))
    for name in PAPER_MISSIONS:
        path = missions_dir / f"{name}.yaml"
        if path.exists():
            result[name] = summarise(evaluate_mission(load_mission(path), kind, policy.resolve(), range(seeds)))
    return result
