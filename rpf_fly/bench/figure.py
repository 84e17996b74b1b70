"""The bench figure: grouped bars of travel distance and smoothness per scene (mean ± std over successful runs,
success rate as markers), and the seed-0 XY trajectories of each planner on circle-8-r3, circle-8-r8 and lab-3 in a
grid of small 1:1 panels. Drawing only (Agg backend); the numbers come from :mod:`rpf_fly.bench.runner`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from rpf_fly.bench.runner import PLANNER_LABELS, Trajectory
from rpf_fly.mission.model import BoxObstacle, CircleObstacle

PLANNER_COLOURS = {
    "rpf": "#1f77b4",
    "rpf-mean": "#17becf",
    "apf": "#ff7f0e",
    "ppo": "#9467bd",
    "orca": "#2ca02c",
    "rpf3": "#d62728",
}


def plot_comparison(results: Mapping[str, Any], path: str | Path, trajectories: Sequence[Trajectory] = ()) -> Path:
    """Write the comparison PNG to ``path``: bars from the results rows, panels from ``trajectories``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    planners = list(results["planners"])
    scenes = list(results["scenes"])
    traj_scenes = list(dict.fromkeys(t.scene for t in trajectories))
    n_cols = max(len(planners), 2)
    panel = 2.6
    width = max(13.0, panel * n_cols)
    fig = plt.figure(figsize=(width, 4.4 + panel * len(traj_scenes)), dpi=110)
    outer = fig.add_gridspec(
        2 if traj_scenes else 1, 1, height_ratios=[4.4, panel * len(traj_scenes)] if traj_scenes else None, hspace=0.25
    )
    top = outer[0].subgridspec(1, 2, wspace=0.3)
    rows = {(r["planner"], r["scene"]): r for r in results["rows"]}
    for k, (metric, label) in enumerate((("travel_distance_m", "travel distance [m]"), ("smoothness", "smoothness"))):
        ax = fig.add_subplot(top[0, k])
        _bars(ax, rows, planners, scenes, metric, label)
        if k == 0:
            ax.legend(fontsize=7, loc="lower left", bbox_to_anchor=(0.0, 1.01), ncol=len(planners), frameon=False)
    fig.suptitle(
        f"rpf-fly bench, {results['episodes']} seeds per scene: bars mean ± std over successful runs, "
        "◇ success rate (right axis); trajectories: seed 0",
        fontsize=9,
    )
    if traj_scenes:
        grid = outer[1].subgridspec(len(traj_scenes), n_cols, hspace=0.3, wspace=0.1)
        by_key = {(t.scene, t.planner): t for t in trajectories}
        for i, scene in enumerate(traj_scenes):
            for j, planner in enumerate(planners):
                ax = fig.add_subplot(grid[i, j])
                _trajectory_panel(ax, by_key.get((scene, planner)), scene, planner, rows.get((planner, scene)))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)
    return path


def _bars(ax, rows, planners, scenes, metric, label) -> None:
    width = 0.8 / max(len(planners), 1)
    x = np.arange(len(scenes))
    rate_ax = ax.twinx()
    for j, planner in enumerate(planners):
        offset = x - 0.4 + (j + 0.5) * width
        means, stds, rates = [], [], []
        for scene in scenes:
            row = rows.get((planner, scene))
            s = row[metric]["successful"] if row is not None and row.get("status") == "ok" else None
            means.append(np.nan if s is None else s["mean"])
            stds.append(0.0 if s is None else s["std"])
            rates.append(np.nan if row is None or row.get("status") != "ok" else row["success_rate"])
        missing = all(row is None or row.get("status") != "ok" for row in (rows.get((planner, s)) for s in scenes))
        name = PLANNER_LABELS.get(planner, planner) + (" (missing)" if missing else "")
        colour = PLANNER_COLOURS.get(planner, None)
        ax.bar(
            offset, np.nan_to_num(means), width, yerr=stds, color=colour, label=name, capsize=2, error_kw={"lw": 0.8}
        )
        rate_ax.plot(offset, np.array(rates) * 100, ls="", marker="D", ms=4, mfc="white", mec="k", mew=0.8)
    rate_ax.set_ylim(0, 110)
    rate_ax.set_ylabel("success rate [%] (◇)", fontsize=8)
    rate_ax.tick_params(labelsize=7)
    ax.set_xticks(x)
    ax.set_xticklabels(scenes, fontsize=8, rotation=15)
    ax.set_ylabel(label + " (successful runs)", fontsize=9)
    ax.tick_params(labelsize=7)
    ax.grid(True, axis="y", lw=0.3, alpha=0.5)
    if metric == "smoothness":
        ax.set_yscale("log")


def _trajectory_panel(ax, traj: Trajectory | None, scene: str, planner: str, row) -> None:
    from matplotlib.patches import Circle, Rectangle

    name = PLANNER_LABELS.get(planner, planner)
    ax.set_xticks([])
    ax.set_yticks([])
    if traj is None:
        reason = row.get("reason", "not run") if row is not None else "not run"
        ax.text(0.5, 0.5, "missing", ha="center", va="center", fontsize=8, color="0.4", transform=ax.transAxes)
        ax.set_title(f"{scene}: {name}", fontsize=7)
        ax.set_aspect("equal")
        ax.set_xlabel(str(reason)[:40], fontsize=5, color="0.5")
        return
    x0, x1 = traj.arena_x
    y0, y1 = traj.arena_y
    ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ls="--", lw=0.6, ec="0.6"))
    for shape in traj.shapes:
        if isinstance(shape, CircleObstacle):
            ax.add_patch(Circle(shape.center, shape.radius, fc="0.65", ec="0.35", lw=0.5))
        elif isinstance(shape, BoxObstacle):
            ax.add_patch(
                Rectangle(
                    shape.min, shape.max[0] - shape.min[0], shape.max[1] - shape.min[1], fc="0.65", ec="0.35", lw=0.5
                )
            )
    colours = _drone_colours(traj.positions.shape[1])
    for i in range(traj.positions.shape[1]):
        track = traj.positions[:, i]
        ax.plot(track.real, track.imag, lw=0.9, color=colours[i])
        ax.plot(track[0].real, track[0].imag, "o", ms=2.5, mfc="white", mec=colours[i], mew=0.6)
        ax.plot(traj.goals[i].real, traj.goals[i].imag, "*", ms=4, color=colours[i])
    ax.set_aspect("equal")
    ax.set_xlim(x0 - 0.2, x1 + 0.2)
    ax.set_ylim(y0 - 0.2, y1 + 0.2)
    verdict = "ok" if traj.success else f"{traj.reached}/{traj.positions.shape[1]} reached, {traj.collisions} coll."
    ax.set_title(f"{scene}: {name} ({verdict})", fontsize=7, color="k" if traj.success else "#d62728")


def _drone_colours(n: int) -> list:
    import matplotlib

    cmap = matplotlib.colormaps["tab10"]
    return [cmap(i % 10) for i in range(n)]
