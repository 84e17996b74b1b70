"""Reproduce the shipped comparison: every planner on every scene for 20 seeds with the shipped policies.

    python tools/bench_paper.py [--episodes 20] [--policies policies] [--out docs/bench]

Relative paths are taken from the repository root, wherever the script is started.
Writes ``results.json``, ``results.md`` and ``comparison.png`` into ``--out`` (docs/bench/ by default) and prints the
table and the paper's claims. Same as ``rpf-fly bench --out docs/bench`` run from the repository root, plus the
git commit of the checkout in the JSON. A policy missing from ``policies/`` gives 'missing' rows, not a failure:
rerun once the policies ship. See docs/bench.md.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

from rich.console import Console  # noqa: E402

from rpf_fly.bench.figure import plot_comparison  # noqa: E402
from rpf_fly.bench.report import print_report, results_json, write_json, write_markdown  # noqa: E402
from rpf_fly.bench.runner import PLANNERS, SCENES, BenchConfig, prepare, run_bench  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def commit() -> str | None:
    """The checkout's commit (read-only git call), or None outside a git checkout."""
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() or None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--episodes", type=int, default=20, help="seeds per scene (default 20)")
    parser.add_argument(
        "--policies", type=Path, default=Path("policies"), help="folder of <kind>.onnx (default policies)"
    )
    parser.add_argument("--out", type=Path, default=Path("docs") / "bench", help="output folder (default docs/bench)")
    args = parser.parse_args(argv)
    os.chdir(ROOT)  # relative paths (policies/, missions/, docs/bench/) are the repository's, and read so in the output

    config = BenchConfig(
        planners=PLANNERS,
        scenes=SCENES,
        episodes=args.episodes,
        policies_dir=args.policies,
        missions_dir=Path("missions"),
    )
    plan = prepare(config)
    console = Console()
    if not console.is_terminal:
        console = Console(width=140)
    for reason in dict.fromkeys(plan.missing.values()):
        console.print(f"[yellow]missing: {reason}[/yellow]")
    started = time.time()
    done = [0]

    def progress(record) -> None:  # type: ignore[no-untyped-def]
        done[0] += 1
        if done[0] % 20 == 0 or done[0] == plan.total_runs:
            console.print(f"{done[0]}/{plan.total_runs} runs, {time.time() - started:.0f} s")

    result = run_bench(plan, progress)
    results = results_json(result)
    results["commit"] = commit()
    results["wall_time_s"] = round(time.time() - started, 1)
    # Paths relative to the repository, so the shipped JSON does not name this machine's folders.
    for info in results["policies"].values():
        try:
            info["path"] = str(Path(info["path"]).resolve().relative_to(ROOT))
        except ValueError:
            pass
    args.out.mkdir(parents=True, exist_ok=True)
    written = [
        write_json(results, args.out / "results.json"),
        write_markdown(results, args.out / "results.md"),
        plot_comparison(results, args.out / "comparison.png", result.trajectories),
    ]
    print_report(results, console)
    for path in written:
        console.print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
