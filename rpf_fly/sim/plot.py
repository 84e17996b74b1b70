"""Plots of a rollout: XY trajectories at 1:1 aspect with obstacles, arena, starts, goals and the planner mode.

Computation lives in :mod:`rpf_fly.sim.rollout` and :mod:`rpf_fly.sim.metrics`; this module only draws. Uses the
Agg backend (no display needed).
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np

from rpf_fly.mission.model import BoxObstacle, CircleObstacle
from rpf_fly.sim.metrics import Metrics
from rpf_fly.sim.rollout import Rollout

MODE_COLOURS = {0: "#1f77b4", 1: "#d62728", 2: "#ff7f0e"}
MODE_LABELS = {0: "APF", 1: "wall-following (mode A)", 2: "soft rule (mode B)"}


def plot_rollout(result: Rollout, path: str | Path, metrics: Optional[Metrics] = None, title: str = "") -> Path:
    """Draw the rollout's trajectories into a PNG at ``path``; returns the path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection
    from matplotlib.lines import Line2D
    from matplotlib.patches import Circle, Rectangle

    scenario = result.scenario
    fig, ax = plt.subplots(figsize=(7.5, 7.5), dpi=120)
    x0, x1 = scenario.arena_x
    y0, y1 = scenario.arena_y
    ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ls="--", lw=1.0, ec="0.5"))
    for shape in scenario.shapes:
        if isinstance(shape, CircleObstacle):
            ax.add_patch(Circle(shape.center, shape.radius, fc="0.6", ec="0.3"))
        elif isinstance(shape, BoxObstacle):
            w, h = shape.max[0] - shape.min[0], shape.max[1] - shape.min[1]
            ax.add_patch(Rectangle(shape.min, w, h, fc="0.6", ec="0.3"))

    pos = result.positions
    for i, name in enumerate(scenario.names):
        track = pos[:, i]
        segments = np.stack([np.stack([track[:-1].real, track[:-1].imag], -1), np.stack([track[1:].real, track[1:].imag], -1)], 1)
        modes = result.modes[:, i]
        keep = modes >= 0
        colours = [MODE_COLOURS[int(m)] for m in modes[keep]]
        ax.add_collection(LineCollection(segments[keep], colors=colours, linewidths=1.6))
        ax.plot(track[0].real, track[0].imag, "o", ms=6, mfc="white", mec="k")
        goal = scenario.goals[i]
        ax.plot(goal.real, goal.imag, "*", ms=11, mfc="gold", mec="k")
        ax.annotate(name, (track[0].real, track[0].imag), textcoords="offset points", xytext=(4, 4), fontsize=8)

    handles = [Line2D([], [], color=c, lw=2, label=MODE_LABELS[m]) for m, c in MODE_COLOURS.items()]
    handles += [
        Line2D([], [], ls="", marker="o", mfc="white", mec="k", label="start"),
        Line2D([], [], ls="", marker="*", ms=11, mfc="gold", mec="k", label="goal"),
    ]
    ax.legend(handles=handles, loc="upper right", fontsize=8, framealpha=0.85)
    ax.set_aspect("equal")
    pad = 0.3
    ax.set_xlim(x0 - pad, x1 + pad)
    ax.set_ylim(y0 - pad, y1 + pad)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, lw=0.3, alpha=0.5)
    heading = title or scenario.name
    if metrics is not None:
        heading += (
            f"  ({metrics.planner or 'planner'}: {metrics.reached}/{metrics.drones} reached, "
            f"{metrics.collisions_drone_drone + metrics.collisions_drone_obstacle} collisions)"
        )
    ax.set_title(heading, fontsize=10)
    path = Path(path)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path
