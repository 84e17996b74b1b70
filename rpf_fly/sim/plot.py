"""Plots of a rollout: XY trajectories at 1:1 aspect with obstacles, arena, starts, goals and the planner mode.

Each drone has its own colour (its track, its start circle, its goal star and a thin line from start to goal), so
crossing tracks can be told apart; the planner's mode is the line style along the track (solid APF, dashed
wall-following, dotted soft rule). The legend sits beside the arena, never over it; the constrained layout makes
room for it and the axis labels whatever the arena's shape (a 40-drone legend beside a square arena is cut off by
no edge).

Computation lives in :mod:`rpf_fly.sim.rollout` and :mod:`rpf_fly.sim.metrics`; this module only draws. Uses the
Agg backend (no display needed).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rpf_fly.mission.model import BoxObstacle, CircleObstacle
from rpf_fly.sim.metrics import Metrics
from rpf_fly.sim.rollout import Rollout

MODE_STYLES = {0: "-", 1: "--", 2: ":"}
"""Line style of each planner mode: 0 APF, 1 wall-following (mode A), 2 soft rule (mode B)."""
MODE_LABELS = {0: "APF", 1: "wall-following (mode A)", 2: "soft rule (mode B)"}


def mode_runs(modes: np.ndarray) -> list[tuple[int, int, int]]:
    """``(mode, first step, last step + 1)`` of each run of one mode (steps with mode -1, arrived, dropped)."""
    runs: list[tuple[int, int, int]] = []
    for k, mode in enumerate(int(m) for m in modes):
        if mode < 0:
            continue
        if runs and runs[-1][0] == mode and runs[-1][2] == k:
            runs[-1] = (mode, runs[-1][1], k + 1)
        else:
            runs.append((mode, k, k + 1))
    return runs


def plot_rollout(result: Rollout, path: str | Path, metrics: Metrics | None = None, title: str = "") -> Path:
    """Draw the rollout's trajectories into a PNG at ``path``; returns the path."""
    import matplotlib.pyplot as plt

    fig = rollout_figure(result, metrics, title)
    path = Path(path)
    fig.savefig(path, bbox_inches="tight", pad_inches=0.15)  # a wide arena leaves no empty bands above and below
    plt.close(fig)
    return path


def rollout_figure(result: Rollout, metrics: Metrics | None = None, title: str = ""):
    """The figure of :func:`plot_rollout` (Agg backend). Artists carry a ``gid``: ``track:<drone>:<mode>`` per
    run of one mode, ``goal:<drone>``, ``start:<drone>``, ``start-goal:<drone>``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Circle, Rectangle

    scenario = result.scenario
    names = list(scenario.names)
    fig, ax = plt.subplots(figsize=(9.5, 7.5), dpi=120, layout="constrained")
    x0, x1 = scenario.arena_x
    y0, y1 = scenario.arena_y
    ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ls="--", lw=1.0, ec="0.5"))
    for shape in scenario.shapes:
        if isinstance(shape, CircleObstacle):
            ax.add_patch(Circle(shape.center, shape.radius, fc="0.6", ec="0.3"))
        elif isinstance(shape, BoxObstacle):
            w, h = shape.max[0] - shape.min[0], shape.max[1] - shape.min[1]
            ax.add_patch(Rectangle(shape.min, w, h, fc="0.6", ec="0.3"))

    palette = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    if len(names) > len(palette):
        palette = [plt.get_cmap("tab20")(k % 20) for k in range(len(names))]
    pos = result.positions
    seen_modes: set[int] = set()
    for i, name in enumerate(names):
        colour = palette[i % len(palette)]
        track = pos[:, i]
        for mode, a, b in mode_runs(result.modes[:, i]):
            seen_modes.add(mode)
            part = track[a : b + 1]  # positions a..b: the steps a..b-1 of this mode
            ax.plot(
                part.real,
                part.imag,
                color=colour,
                lw=1.7,
                ls=MODE_STYLES.get(mode, "-"),
                zorder=3,
                solid_capstyle="butt",
                dash_capstyle="butt",
                gid=f"track:{name}:{mode}",
            )
        start, goal = track[0], scenario.goals[i]
        ax.plot(
            [start.real, goal.real],
            [start.imag, goal.imag],
            ls="-",
            lw=0.6,
            color=colour,
            alpha=0.45,
            zorder=2,
            gid=f"start-goal:{name}",
        )
        ax.plot(start.real, start.imag, "o", ms=7, mfc="white", mec=colour, mew=1.6, zorder=4, gid=f"start:{name}")
        ax.plot(goal.real, goal.imag, "*", ms=15, mfc=colour, mec="k", mew=0.7, zorder=5, gid=f"goal:{name}")
        ax.annotate(
            name,
            (start.real, start.imag),
            textcoords="offset points",
            xytext=(5, 5),
            fontsize=8,
            color=colour,
            fontweight="bold",
            zorder=6,
        )

    handles = [Line2D([], [], color=palette[i % len(palette)], lw=2.2, label=name) for i, name in enumerate(names[:20])]
    if len(names) > 20:
        handles.append(Line2D([], [], ls="", label=f"... {len(names) - 20} more"))
    handles.append(Line2D([], [], ls="", label=""))
    handles += [
        Line2D([], [], color="k", lw=1.7, ls=MODE_STYLES[m], label=MODE_LABELS[m])
        for m in sorted(MODE_STYLES)
        if m in seen_modes or m == 0
    ]
    handles += [
        Line2D([], [], ls="", marker="o", mfc="white", mec="k", label="start"),
        Line2D([], [], ls="", marker="*", ms=13, mfc="0.8", mec="k", label="goal (drone's colour)"),
        Line2D([], [], ls="-", lw=0.6, color="k", alpha=0.45, label="start to goal"),
    ]
    ax.legend(
        handles=handles,
        loc="upper left",
        bbox_to_anchor=(1.02, 1.0),
        fontsize=8,
        frameon=False,
        borderaxespad=0.0,
        handlelength=3.0,
    )
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
    return fig
