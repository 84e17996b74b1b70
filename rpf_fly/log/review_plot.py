"""The review's figure: one PNG with six panels (Agg backend, no display needed). Only draws; the numbers come
from :mod:`rpf_fly.log.review`.

1. XY tracks from ``/mocap`` at 1:1 aspect with obstacles, goals, starts and the arena;
2. altitude over time;
3. setpoint tracking error over time, with RMS and max per drone;
4. minimum inter-drone separation over time against ``2r``;
5. battery voltage over time;
6. event timeline (markers by level) over the flight phases of every drone (from ``/status``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rpf_fly.log import review as R
from rpf_fly.log.reader import LogData

STATE_COLOURS = {
    "connecting": "#c7c7c7", "preflight": "#dbdb8d", "armed": "#ffbb78", "takeoff": "#98df8a", "planning": "#aec7e8",
    "arrived": "#2ca02c", "hover": "#9edae5", "landing": "#c5b0d5", "landed": "#8c8c8c", "error": "#ff9896",
    "emergency": "#d62728",
}
LEVEL_COLOURS = {1: "0.5", 2: "#1f77b4", 3: "#ff7f0e", 4: "#d62728", 5: "#7f0000"}


def plot_review(data: LogData, result: R.Review, path: str | Path) -> Path:
    """Draw the review of ``data`` into a PNG at ``path``; returns the path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Circle, Patch, Rectangle

    start = result.start_ns
    end_s = result.duration_s
    drones = result.drones
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    colour = {d: colours[i % len(colours)] for i, d in enumerate(drones)}
    scenario = result.scenario or {}
    poses = {d: R.pose_series(data, d, start) for d in drones}

    fig, axes = plt.subplots(3, 2, figsize=(13, 14), dpi=100)
    ax_xy, ax_z, ax_err, ax_sep, ax_bat, ax_ev = axes.ravel()
    title = f"{result.mission or result.path.name}: {result.planner or '?'}, seed {result.seed}"
    if result.metrics is not None:
        m = result.metrics
        title += (f"  |  {m.reached}/{m.drones} reached, "
                  f"{m.collisions_drone_drone + m.collisions_drone_obstacle} collisions")
    if result.truncated:
        title += "  |  TRUNCATED LOG"
    fig.suptitle(title, fontsize=12)

    # 1. XY
    arena = scenario.get("arena")
    if arena:
        (x0, x1), (y0, y1) = arena["x"], arena["y"]
        ax_xy.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ls="--", lw=1.0, ec="0.5"))
        ax_xy.set_xlim(x0 - 0.3, x1 + 0.3)
        ax_xy.set_ylim(y0 - 0.3, y1 + 0.3)
    for o in scenario.get("obstacles", []):
        if o["shape"] == "circle":
            ax_xy.add_patch(Circle(o["center"], o["radius"], fc="0.6", ec="0.3"))
        else:
            (bx0, by0), (bx1, by1) = o["min"], o["max"]
            ax_xy.add_patch(Rectangle((bx0, by0), bx1 - bx0, by1 - by0, fc="0.6", ec="0.3"))
    for i, d in enumerate(drones):
        s = poses[d]
        if s.t.size:
            ax_xy.plot(s.values[:, 0], s.values[:, 1], lw=1.4, color=colour[d], label=d)
            ax_xy.plot(s.values[0, 0], s.values[0, 1], "o", ms=6, mfc="white", mec=colour[d])
        goals = scenario.get("goals")
        if goals and i < len(goals):
            ax_xy.plot(goals[i][0], goals[i][1], "*", ms=11, mfc="gold", mec="k")
    ax_xy.set_aspect("equal")
    ax_xy.set_xlabel("x [m]")
    ax_xy.set_ylabel("y [m]")
    ax_xy.set_title("XY tracks (/mocap)", fontsize=10)
    handles = [Line2D([], [], ls="", marker="o", mfc="white", mec="k", label="start"),
               Line2D([], [], ls="", marker="*", ms=11, mfc="gold", mec="k", label="goal")]
    if len(drones) <= 12:
        handles = [Line2D([], [], color=colour[d], lw=2, label=d) for d in drones] + handles
    ax_xy.legend(handles=handles, loc="upper right", fontsize=7, framealpha=0.85)
    ax_xy.grid(True, lw=0.3, alpha=0.5)

    # 2. altitude
    for d in drones:
        s = poses[d]
        if s.t.size:
            ax_z.plot(s.t, s.values[:, 2], lw=1.0, color=colour[d])
    ztop = max([float(np.nanmax(s.values[:, 2])) for s in poses.values() if s.t.size] or [1.0])
    if arena and arena.get("z"):
        ztop = max(ztop, float(arena["z"][1]))
    ax_z.set_ylim(0, ztop * 1.05 + 0.05)
    ax_z.set_xlabel("t [s]")
    ax_z.set_ylabel("z [m]")
    ax_z.set_title("altitude (/mocap)", fontsize=10)

    # 3. tracking error
    all_err = []
    for d in drones:
        e = R.tracking_error(data, d, start)
        if e.t.size:
            rms, peak = R.rms_max(e.values)
            ax_err.plot(e.t, e.values, lw=1.0, color=colour[d], label=f"{d}: RMS {rms:.3f}, max {peak:.3f} m")
            all_err.append(e.values)
    if all_err:
        rms, peak = R.rms_max(np.concatenate(all_err))
        ax_err.set_title(f"setpoint tracking error |setpoint - pose|: RMS {rms:.3f} m, max {peak:.3f} m", fontsize=10)
        if len(drones) <= 8:
            ax_err.legend(fontsize=7, loc="upper right")
    else:
        ax_err.set_title("setpoint tracking error: no setpoints or poses", fontsize=10)
    ax_err.set_xlabel("t [s]")
    ax_err.set_ylabel("error [m]")

    # 4. separation
    sep = R.min_separation(data, drones, start)
    r = scenario.get("safety_radius")
    if sep.t.size:
        ax_sep.plot(sep.t, sep.values, lw=1.2, color="k", label=f"min separation ({sep.values.min():.3f} m)")
    if r is not None:
        ax_sep.axhline(2 * r, color="#d62728", ls="--", lw=1.0, label=f"2r = {2 * r:g} m")
    ax_sep.set_title("minimum inter-drone separation (planar)", fontsize=10)
    ax_sep.set_xlabel("t [s]")
    ax_sep.set_ylabel("distance [m]")
    ax_sep.set_ylim(bottom=0)
    ax_sep.legend(fontsize=7, loc="upper right")

    # 5. battery
    any_battery = False
    for d in drones:
        b = R.battery_series(data, d, start)
        if b.t.size:
            ax_bat.plot(b.t, b.values, lw=1.0, color=colour[d], label=d)
            any_battery = True
    if not any_battery:
        ax_bat.text(0.5, 0.5, "no battery data", ha="center", va="center", transform=ax_bat.transAxes, color="0.5")
    ax_bat.set_title("battery (/status)", fontsize=10)
    ax_bat.set_xlabel("t [s]")
    ax_bat.set_ylabel("voltage [V]")

    # 6. events over flight phases
    seen_states: dict[str, None] = {}
    for row, d in enumerate(drones):
        for t0, t1, state in R.phases(data, d, start, end_s):
            ax_ev.broken_barh([(t0, max(t1 - t0, 1e-3))], (-row - 1.4, 0.8),
                              facecolors=STATE_COLOURS.get(state, "#e0e0e0"))
            seen_states[state] = None
    for t, level, *_ in result.events:
        ax_ev.plot(t, level, "v", ms=7, color=LEVEL_COLOURS.get(level, "0.3"))
    ax_ev.set_yticks(list(range(1, 6)) + [-row - 1 for row in range(len(drones))])
    ax_ev.set_yticklabels(["debug", "info", "warning", "error", "fatal"] + list(drones), fontsize=7)
    ax_ev.set_ylim(-len(drones) - 0.8, 5.8)
    ax_ev.set_xlim(-0.02 * end_s - 0.05, 1.02 * end_s + 0.05)
    ax_ev.set_xlabel("t [s]")
    ax_ev.set_title(f"events ({len(result.events)}) and flight phases (/status)", fontsize=10)
    if seen_states:
        ax_ev.legend(handles=[Patch(color=STATE_COLOURS.get(s, "#e0e0e0"), label=s) for s in seen_states],
                     fontsize=7, loc="upper right", ncol=2)
    for ax in (ax_z, ax_err, ax_sep, ax_bat, ax_ev):
        ax.grid(True, lw=0.3, alpha=0.5)

    path = Path(path)
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    fig.savefig(path)
    plt.close(fig)
    return path
