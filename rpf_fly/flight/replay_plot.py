"""The replay's figure (``rpf-fly replay --plot``): per drone, the heading of the logged and of the replayed
direction over time, and the direction difference on a log scale beside it. Only draws (Agg backend); the numbers
come from :mod:`rpf_fly.flight.replay`.

Headings are the angle of each planning tick's direction (degrees, counter-clockwise from +x), the logged one
unwrapped so a turn through +-180 degrees stays one line, the replayed one drawn at the logged one plus the angle
between them (wrapped to +-180), so the gap on the plot is the difference of the decisions; a zero direction
(stalled, faulted) leaves a gap. Ticks
whose replayed mode is not the logged one are marked with a cross, the first divergence with a vertical line.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from rpf_fly.flight.replay_result import ReplayResult, TickComparison

FLOOR = 1e-17
"""Direction differences are drawn on a log axis; an exact match (0) sits on this floor."""


def _heading_deg(direction: complex) -> float:
    return math.degrees(math.atan2(direction.imag, direction.real)) if abs(direction) > 0 else math.nan


def _unwrapped(values: list[float]) -> np.ndarray:
    """Unwrap degrees across finite runs (NaN gaps stay gaps)."""
    out = np.array(values, dtype=float)
    finite = np.isfinite(out)
    if finite.any():
        out[finite] = np.degrees(np.unwrap(np.radians(out[finite])))
    return out


def plot_replay(result: ReplayResult, path: str | Path, title: str = "") -> Path:
    """Draw ``result`` into a PNG at ``path``: one row per replayed drone (headings left, difference right)."""
    import matplotlib.pyplot as plt

    fig = replay_figure(result, title)
    out = Path(path)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def replay_figure(result: ReplayResult, title: str = ""):
    """The figure of :func:`plot_replay`, not yet saved. Every panel is on one time axis (the drones' rows can be
    compared tick for tick, as the review figure's panels)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    drones = [d for d in result.drones.values() if d.ticks]
    rows = max(1, len(drones))
    fig, axes = plt.subplots(
        rows, 2, figsize=(13, 2.6 * rows + 0.8), squeeze=False, sharex=True, gridspec_kw={"width_ratios": [3, 2]}
    )
    starts = [c.t_ns for d in drones for c in d.ticks]
    t0 = min(starts) if starts else 0
    for (ax, ax_diff), drone in zip(axes, drones):
        ticks: list[TickComparison] = drone.ticks
        t = np.array([(c.t_ns - t0) / 1e9 for c in ticks])
        logged = _unwrapped([_heading_deg(c.logged_direction) for c in ticks])
        # the replayed heading drawn as the logged one plus their difference wrapped to (-180, 180]: the gap on the
        # plot is the angle between the two decisions (where the logged heading is zero, unwrapped on its own)
        gap = np.array([_heading_deg(c.replayed_direction) for c in ticks]) - np.array(
            [_heading_deg(c.logged_direction) for c in ticks]
        )
        gap = (gap + 180.0) % 360.0 - 180.0
        replayed = np.where(
            np.isfinite(logged), logged + gap, _unwrapped([_heading_deg(c.replayed_direction) for c in ticks])
        )
        ax.plot(t, logged, "-", color="#1f77b4", lw=2.2, label="logged")
        what = result.planner + (f", {result.policy.name}" if result.policy is not None else "")
        ax.plot(t, replayed, "--", color="#ff7f0e", lw=1.4, label=f"replayed ({what})")
        changed = [i for i, c in enumerate(ticks) if c.replayed_mode != c.logged_mode]
        if changed:
            ax.plot(t[changed], replayed[changed], "x", color="#d62728", ms=6, label="mode differs")
        first = drone.first_divergence_tick
        if first is not None:
            at = next(c.t_ns for c in ticks if c.tick == first)
            for a in (ax, ax_diff):
                a.axvline((at - t0) / 1e9, color="#d62728", lw=0.8, ls=":")
        ax.set_ylabel(f"{drone.name}\nheading [deg]")
        ax.grid(alpha=0.3)
        ax.legend(loc="best", fontsize=8)
        diff = np.maximum([c.direction_diff for c in ticks], FLOOR)
        ax_diff.semilogy(t, diff, ".", color="#2ca02c", ms=3, label=f"per tick (0 drawn at {FLOOR:g})")
        ax_diff.axhline(result.tolerance, color="0.4", lw=0.8, ls="--", label=f"tolerance {result.tolerance:g}")
        ax_diff.set_ylim(FLOOR / 2, 4)
        ax_diff.set_ylabel("|d_replay - d_log|")
        ax_diff.grid(alpha=0.3, which="both")
        ax_diff.legend(loc="best", fontsize=7, framealpha=0.6)
        verdict = "reproduced" if first is None else f"first divergence at tick {first}"
        ax_diff.set_title(
            f"max {drone.max_direction_diff:.2g}, mode differs on {drone.mode_changes} ticks: {verdict}", fontsize=9
        )
    if not drones:
        axes[0][0].text(0.5, 0.5, "no planning ticks to compare", ha="center", va="center")
    axes[-1][0].set_xlabel("time since the first planning tick [s]")
    axes[-1][1].set_xlabel("time since the first planning tick [s]")
    fig.suptitle(title or f"replay: {result.planner}")
    fig.tight_layout()
    return fig
