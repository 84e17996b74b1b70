"""The review's figure: one PNG (Agg backend, no display needed). Only draws; the numbers come from
:mod:`rpf_fly.log.review`.

Left, the XY tracks from ``/mocap`` at 1:1 aspect with obstacles, the arena, each drone's start (circle) and goal
(star) in the drone's colour joined by a thin line, the legend below the arena. Right, the time panels, all on one
shared time axis (seconds from the start of the log), a panel only where the log has its data:

1. altitude;
2. setpoint tracking error with RMS and max per drone (not for a simulated log: its setpoint is one planning step
   ahead by construction, not a drone's tracking);
3. minimum inter-drone separation against ``2r`` (two drones or more);
4. obstacle clearance, each drone's distance to the nearest obstacle surface, against ``r`` (obstacles only);
5. battery voltage (battery telemetry only);
6. events (markers by level; the first event of each kind named, every error and interruption always) over each
   drone's flight phases (its ``/status`` states). An interruption is a red line through every time panel.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from rpf_fly.log import review as R
from rpf_fly.log import review_series as series
from rpf_fly.log.reader import LogData

if TYPE_CHECKING:
    from matplotlib.axes import Axes

STATE_COLOURS = {
    # a flight's drone phases (rpf_fly.flight.phases.DronePhase), each its own colour
    "waiting": "#c7c7c7",
    "ready": "#dbdb8d",
    "takeoff": "#98df8a",
    "planning": "#aec7e8",
    "holding": "#ffbb78",
    "arrived": "#2ca02c",
    "landing": "#c5b0d5",
    "landed": "#7f7f7f",
    "failed": "#ff9896",
    "grounded": "#8c564b",
    "link_lost": "#e377c2",
    "emergency": "#d62728",
    # a simulation's last state, and the states of older logs
    "hover": "#9edae5",
    "connecting": "#f7b6d2",
    "preflight": "#bcbd22",
    "armed": "#ff7f0e",
    "error": "#c49c94",
}
"""The flight phases' colours in the events panel and its legend: every state its own (a state not here is
``UNKNOWN_STATE_COLOUR``)."""
UNKNOWN_STATE_COLOUR = "#e0e0e0"
LEVEL_COLOURS = {1: "0.5", 2: "#1f77b4", 3: "#ff7f0e", 4: "#d62728", 5: "#7f0000"}
ALWAYS_LABELLED = ("interrupt", "error", "emergency", "loop", "touchdown")
"""Event kinds labelled every time (with every event of level error or fatal)."""


def event_key(event: R.ReviewEvent) -> str:
    """What "the same kind of event" means for labelling: the flight event's kind and what its message says it is
    (the message up to its first ": ", drone names and numbers taken out), so that one label never stands for
    different things (an injected occlusion, gust and low battery are three faults; a take-off commanded is not a
    drone airborne); each swarm phase apart; for logs without kinds, such as simulated ones, the message with the
    drone names and numbers taken out."""
    import re

    if event.kind == "phase" and event.name == "flight":
        return event.message.split(" (")[0]  # each of the swarm's phases is its own milestone
    if event.kind == "phase":
        return "phase " + event.message.split(":")[0]  # a drone's phases: the first drone ready, arrived, landed...
    if event.kind:
        return f"{event.kind}: " + re.sub(r"\b(cf\w*|\d[\d.]*)\b", "#", event.message.split(": ")[0])
    return re.sub(r"\b(cf\w*|\d[\d.]*)\b", "#", event.message)[:24]


def labelled_events(events: list[R.ReviewEvent]) -> list[tuple[R.ReviewEvent, str]]:
    """The events to name on the figure, with their text: the first of each kind (:func:`event_key`), every error or
    worse, every interruption. A repeated kind says so (``kind (x3)``): the events it counts are the same thing."""
    counts: dict[str, int] = {}
    for e in events:
        counts[event_key(e)] = counts.get(event_key(e), 0) + 1
    seen: set[str] = set()
    out = []
    for e in events:
        key = event_key(e)
        always = e.level >= 4 or e.kind in ALWAYS_LABELLED
        if key in seen and not always:
            continue
        seen.add(key)
        who = f"{e.name}: " if e.name and e.name not in ("flight", "sim", "rpf_fly") else ""
        text = f"{who}{e.message}"
        text = text if len(text) <= 64 else text[:63] + "…"
        if counts[key] > 1 and not always:
            text += f" (x{counts[key]})"
        out.append((e, text))
    return out


MAX_LISTED = 28
"""Named events listed under the XY panel (the rest are counted)."""


def _event_list(fig, ax_xy, legend, named: list[tuple[R.ReviewEvent, str]], cuts: list[R.Interruption]) -> None:
    """The named events, numbered as on the events panel, listed under the XY panel's legend in their level's
    colour; then each interruption."""
    renderer = fig.canvas.get_renderer()
    box = ax_xy.get_position()
    bottom = fig.transFigure.inverted().transform(legend.get_window_extent(renderer))[0][1]
    inch = 1.0 / fig.get_figheight()
    top = bottom - 0.15 * inch
    fig.text(box.x0, top, "events named on the timeline", fontsize=9, fontweight="bold", va="top")
    lines = [
        (f"{k + 1:>2}  {e.t_s:7.2f} s  {text}", LEVEL_COLOURS.get(e.level, "0.3"))
        for k, (e, text) in enumerate(named[:MAX_LISTED])
    ]
    if len(named) > MAX_LISTED:
        lines.append((f"... and {len(named) - MAX_LISTED} more (rpf-fly review prints every warning)", "0.4"))
    for cut in (c for c in cuts if c.how == "killed"):  # a signal or an error is an event listed above
        at = f"{cut.t_s:7.2f} s" if cut.t_s is not None else "      - "
        text = f" !  {at}  interrupted ({cut.how}): {cut.message}"
        lines.append((text if len(text) <= 90 else text[:89] + "…", "#d62728"))
    for k, (text, colour) in enumerate(lines):
        fig.text(box.x0, top - (0.22 + 0.15 * k) * inch, text, fontsize=7.5, family="monospace", va="top", color=colour)


LABEL_SPOTS = (
    (0, 6, "center", "bottom"),
    (0, -7, "center", "top"),
    (0, 17, "center", "bottom"),
    (0, -18, "center", "top"),
    (7, 0, "left", "center"),
    (-7, 0, "right", "center"),
)
"""Where an event's number may go, in points from its marker, tried in this order: above, below, higher, lower,
right, left; the first spot that covers no marker and no label already placed is taken."""


def _event_labels(fig, ax, clusters: list[tuple[float, int, list[int]]]) -> None:
    """Number the events on the timeline, each cluster once, where its number covers no other marker and no
    other number (an interruption and the events of its instant share one time), on a white ground so the
    interruption's line does not strike through it."""
    from matplotlib.transforms import Bbox

    renderer = fig.canvas.get_renderer()
    markers = []
    for line in ax.get_lines():
        if line.get_gid() == "event-marker":
            x, y = ax.transData.transform((line.get_xdata()[0], line.get_ydata()[0]))
            half = line.get_markersize() * fig.dpi / 72.0 / 2.0
            markers.append(Bbox.from_extents(x - half, y - half, x + half, y + half))
    placed: list = []

    def put(text: str, t: float, level: int, spot: tuple[int, int, str, str]):
        dx, dy, ha, va = spot
        return ax.annotate(
            text,
            (t, level),
            xytext=(dx, dy),
            textcoords="offset points",
            fontsize=7,
            fontweight="bold",
            color=LEVEL_COLOURS.get(level, "0.3"),
            ha=ha,
            va=va,
            gid="event-label",
            zorder=4,
            bbox={"boxstyle": "square,pad=0.1", "fc": "white", "ec": "none", "alpha": 0.85},
        )

    for t, level, numbers in clusters:
        text = ",".join(map(str, numbers)) if len(numbers) <= 3 else f"{numbers[0]}-{numbers[-1]}"
        for spot in LABEL_SPOTS:
            label = put(text, t, level, spot)
            box = label.get_window_extent(renderer)
            if not any(box.overlaps(other) for other in markers + placed):
                break
            label.remove()
        else:  # no free spot: the first one
            box = put(text, t, level, LABEL_SPOTS[0]).get_window_extent(renderer)
        placed.append(box)


def _legend_clear_of_data(fig, ax) -> None:
    """Raise the top of a time panel so that its legend (upper right) sits above the curves instead of on them:
    the panel's range so far keeps its share below the legend."""
    renderer = fig.canvas.get_renderer()
    frame = ax.get_window_extent(renderer)
    share = ax.get_legend().get_window_extent(renderer).height / max(frame.height, 1.0) + 0.05
    if share >= 0.7:
        return  # a legend taller than most of the panel: left where it is
    bottom, top = ax.get_ylim()
    ax.set_ylim(bottom, bottom + (top - bottom) / (1.0 - share))


def plot_review(data: LogData, result: R.Review, path: str | Path) -> Path:
    """Draw the review of ``data`` into a PNG at ``path``; returns the path."""
    import matplotlib.pyplot as plt

    fig = review_figure(data, result)
    path = Path(path)
    fig.savefig(path)
    plt.close(fig)
    return path


def review_figure(data: LogData, result: R.Review):
    """The review's figure (a matplotlib Figure on the Agg backend). Its axes are labelled ``xy`` and by panel
    (``altitude``, ``tracking``, ``separation``, ``clearance``, ``battery``, ``events``); the artists a reader looks
    for carry a ``gid`` (``track:<drone>``, ``goal:<drone>``, ``start-goal:<drone>``, ``r``, ``2r``,
    ``interruption``, ``event-marker``, ``event-label``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Circle, Patch, Rectangle

    start = result.start_ns
    end_s = max(result.duration_s, 1e-3)
    drones = result.drones
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    colour = {d: colours[i % len(colours)] for i, d in enumerate(drones)}
    scenario = result.scenario or {}
    poses = {d: series.pose_series(data, d, start) for d in drones}
    tracking = {d: series.tracking_error(data, d, start) for d in drones} if result.source != "sim" else {}
    tracking = {d: e for d, e in tracking.items() if e.t.size}
    batteries = {d: b for d in drones if (b := series.battery_series(data, d, start)).t.size}
    clearances = {d: c for d in drones if (c := series.obstacle_clearance(data, d, start, scenario)).t.size}
    r = scenario.get("safety_radius")

    panels = ["altitude"]
    panels += ["tracking"] if tracking else []
    panels += ["separation"] if len(drones) >= 2 else []
    panels += ["clearance"] if clearances else []
    panels += ["battery"] if batteries else []
    panels += ["events"]
    event_rows = 5 + len(drones)
    heights = [1.0] * (len(panels) - 1) + [max(1.4, 0.16 * event_rows)]
    fig = plt.figure(figsize=(17, max(10.0, 2.0 * sum(heights) + 1.2)), dpi=100)
    grid = fig.add_gridspec(
        len(panels),
        2,
        width_ratios=(1.0, 1.35),
        height_ratios=heights,
        hspace=0.32,
        wspace=0.14,
        left=0.05,
        right=0.98,
        top=0.94,
        bottom=0.95 / max(10.0, 2.0 * sum(heights) + 1.2),
    )
    ax_xy = fig.add_subplot(grid[:, 0], label="xy")
    axes: dict[str, Axes] = {}
    first: Axes | None = None
    for row, name in enumerate(panels):
        ax = fig.add_subplot(grid[row, 1], sharex=first, label=name)
        first = first or ax
        axes[name] = ax
    title = f"{result.mission or result.path.name}: {result.planner or '?'}, seed {result.seed}"
    if result.source:
        title += f" ({result.source})"
    if result.metrics is not None:
        m = result.metrics
        title += (
            f"  |  {m.reached}/{m.drones} reached, {m.collisions_drone_drone + m.collisions_drone_obstacle} collisions"
        )
    if result.interrupted:
        title += "  |  INTERRUPTED (" + ", ".join(dict.fromkeys(c.how for c in result.interruptions)) + ")"
    if result.truncated:
        title += "  |  TRUNCATED LOG"
    fig.suptitle(title, fontsize=13)

    # XY tracks, starts and goals in each drone's colour, the legend below the arena.
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
    goals = scenario.get("goals") or []
    starts = scenario.get("starts") or []
    for i, d in enumerate(drones):
        s = poses[d]
        begin = tuple(s.values[0, :2]) if s.t.size else (tuple(starts[i]) if i < len(starts) else None)
        if s.t.size:
            ax_xy.plot(s.values[:, 0], s.values[:, 1], lw=1.5, color=colour[d], zorder=3, gid=f"track:{d}")
        if begin is not None:
            ax_xy.plot(*begin, "o", ms=7, mfc="white", mec=colour[d], mew=1.6, zorder=4)
        if i < len(goals):
            if begin is not None:
                ax_xy.plot(
                    [begin[0], goals[i][0]],
                    [begin[1], goals[i][1]],
                    ls="-",
                    lw=0.6,
                    color=colour[d],
                    alpha=0.45,
                    zorder=2,
                    gid=f"start-goal:{d}",
                )
            ax_xy.plot(goals[i][0], goals[i][1], "*", ms=15, mfc=colour[d], mec="k", mew=0.7, zorder=5, gid=f"goal:{d}")
    ax_xy.set_aspect("equal")
    ax_xy.set_xlabel("x [m]")
    ax_xy.set_ylabel("y [m]")
    ax_xy.set_title("XY tracks (/mocap)", fontsize=10)
    ax_xy.grid(True, lw=0.3, alpha=0.5)
    handles = [Line2D([], [], color=colour[d], lw=2, label=d) for d in drones[:16]]
    handles += [
        Line2D([], [], ls="", marker="o", mfc="white", mec="k", label="start"),
        Line2D([], [], ls="", marker="*", ms=13, mfc="0.8", mec="k", label="goal (drone's colour)"),
        Line2D([], [], ls="-", lw=0.6, color="k", alpha=0.45, label="start to goal"),
    ]
    ax_xy.set_anchor("N")
    legend = ax_xy.legend(
        handles=handles,
        loc="upper center",
        bbox_to_anchor=(0.5, -0.07),
        ncol=min(6, len(handles)),
        fontsize=8,
        frameon=False,
    )

    # altitude
    ax = axes["altitude"]
    for d in drones:
        s = poses[d]
        if s.t.size:
            ax.plot(s.t, s.values[:, 2], lw=1.0, color=colour[d])
    ztop = max([float(np.nanmax(s.values[:, 2])) for s in poses.values() if s.t.size] or [1.0])
    if arena and arena.get("z"):
        ztop = max(ztop, float(arena["z"][1]))
    ax.set_ylim(0, ztop * 1.05 + 0.05)
    ax.set_ylabel("z [m]")
    ax.set_title("altitude (/mocap)", fontsize=10)

    # setpoint tracking error
    if "tracking" in axes:
        ax = axes["tracking"]
        for d, e in tracking.items():
            rms, peak = series.rms_max(e.values)
            ax.plot(e.t, e.values, lw=1.0, color=colour[d], label=f"{d}: RMS {rms:.3f}, max {peak:.3f} m")
        judged = [x for x in result.tracking_expected.values() if x.expected_m is not None]
        if judged:  # what a drone of the log's kind trails by while cruising at the flown speed
            bands = [band for x in judged if (band := x.band_m) is not None]  # each judged drone has its band
            low, high = (float(np.median([b[k] for b in bands])) for k in (0, 1))
            lag_s = judged[0].lag_s
            speed = float(np.median([x.speed_m_s for x in judged]))
            ax.axhspan(
                low, high, color="0.85", zorder=0, label=f"expected while cruising: {lag_s:g} s x {speed:.2f} m/s"
            )
        rms, peak = series.rms_max(np.concatenate([e.values for e in tracking.values()]))
        ax.set_title(f"setpoint tracking error |setpoint - pose|: RMS {rms:.3f} m, max {peak:.3f} m", fontsize=10)
        ax.set_ylabel("error [m]")
        ax.set_ylim(bottom=0)
        if len(tracking) <= 8:  # in rows of up to 4 drones, so that it stays above the curves
            ax.legend(fontsize=7, loc="upper right", ncol=1 if len(tracking) <= 3 else min(4, -(-len(tracking) // 2)))

    # separation
    if "separation" in axes:
        ax = axes["separation"]
        sep = series.min_separation(data, drones, start)
        if sep.t.size:
            ax.plot(sep.t, sep.values, lw=1.2, color="k", label=f"min separation ({sep.values.min():.3f} m)")
        if r is not None:
            ax.axhline(2 * r, color="#d62728", ls="--", lw=1.0, label=f"2r = {2 * r:g} m", gid="2r")
        ax.set_title("minimum inter-drone separation (planar, centre to centre)", fontsize=10)
        ax.set_ylabel("distance [m]")
        ax.set_ylim(bottom=0)
        ax.legend(fontsize=7, loc="upper right")

    # obstacle clearance
    if "clearance" in axes:
        ax = axes["clearance"]
        lowest = min(float(c.values.min()) for c in clearances.values())
        for d, c in clearances.items():
            ax.plot(c.t, c.values, lw=1.0, color=colour[d])
        if r is not None:
            ax.axhline(r, color="#d62728", ls="--", lw=1.0, label=f"r = {r:g} m", gid="r")
            # named on its line, not in a legend: the panel is cut at the 95th percentile, so a legend at the top
            # would sit on the clearances above it
            ax.annotate(
                f"r = {r:g} m",
                (1.0, r),
                xycoords=("axes fraction", "data"),
                xytext=(-4, 2),
                textcoords="offset points",
                ha="right",
                va="bottom",
                fontsize=7,
                color="#d62728",
                gid="r-label",
            )
        top = max(float(np.percentile(c.values, 95)) for c in clearances.values())
        ax.set_ylim(min(0.0, lowest - 0.05), max(top, 2.5 * (r or 0.1)) * 1.1)
        ax.set_title(f"obstacle clearance (centre to the nearest surface): min {lowest:.3f} m", fontsize=10)
        ax.set_ylabel("distance [m]")

    # battery
    if "battery" in axes:
        ax = axes["battery"]
        for d, b in batteries.items():
            ax.plot(b.t, b.values, lw=1.0, color=colour[d])
        ax.set_title("battery (/status)", fontsize=10)
        ax.set_ylabel("voltage [V]")

    # events over flight phases
    ax = axes["events"]
    seen_states: dict[str, None] = {}
    for row, d in enumerate(drones):
        for t0, t1, state in series.phases(data, d, start, end_s):
            ax.broken_barh(
                [(t0, max(t1 - t0, 1e-3))], (-row - 1.4, 0.8), facecolors=STATE_COLOURS.get(state, UNKNOWN_STATE_COLOUR)
            )
            seen_states[state] = None
    for event in result.events:
        ax.plot(
            event.t_s, event.level, "v", ms=7, color=LEVEL_COLOURS.get(event.level, "0.3"), zorder=3, gid="event-marker"
        )
    named = labelled_events(result.events)
    clusters: list[tuple[float, int, list[int]]] = []  # events close in time on one level share one label
    for k, (event, _text) in enumerate(named):
        near = [c for c in clusters if c[1] == event.level and abs(c[0] - event.t_s) < 0.02 * end_s]
        if near:
            near[0][2].append(k + 1)
        else:
            clusters.append((event.t_s, event.level, [k + 1]))
    for cut in result.interruptions:
        if cut.how == "killed" and cut.t_s is not None:  # no event says so: the log just ends
            ax.annotate(
                "killed: the log ends here",
                (cut.t_s, 5.0),
                xytext=(-4, 6),
                textcoords="offset points",
                fontsize=7,
                color="#d62728",
                ha="right",
                va="bottom",
                fontweight="bold",
            )
    ax.set_yticks(list(range(1, 6)) + [-row - 1 for row in range(len(drones))])
    ax.set_yticklabels(["debug", "info", "warning", "error", "fatal"] + list(drones), fontsize=7)
    ax.set_ylim(-len(drones) - 0.8, 6.6)
    ax.set_title(
        f"events ({len(result.events)}; the first of each kind named) and flight phases (/status)", fontsize=10
    )
    if seen_states:
        spot = ax.get_position()
        fig.legend(
            handles=[Patch(color=STATE_COLOURS.get(s, UNKNOWN_STATE_COLOUR), label=s) for s in seen_states],
            fontsize=7.5,
            loc="lower center",
            bbox_to_anchor=(spot.x0 + spot.width / 2, 0.0),
            ncol=min(11, len(seen_states)),
            frameon=False,
            title="flight phases",
            title_fontsize=7.5,
        )

    # the shared time axis, interruptions through every panel
    for name, panel in axes.items():
        panel.grid(True, lw=0.3, alpha=0.5)
        for cut in result.interruptions:
            if cut.t_s is not None:
                panel.axvline(cut.t_s, color="#d62728", lw=1.2, ls="-", alpha=0.7, gid="interruption")
        if name != "events":
            panel.tick_params(labelbottom=False)
    assert first is not None  # panels always holds the altitude and the events
    first.set_xlim(-0.01 * end_s, 1.01 * end_s)
    axes["events"].set_xlabel("t [s] (from the start of the log)")

    fig.canvas.draw()  # the layout (aspect, legend) settled: labels, legends and the list are placed on it
    _event_labels(fig, axes["events"], clusters)
    for name in ("tracking", "separation", "clearance"):
        if name in axes and axes[name].get_legend() is not None:
            _legend_clear_of_data(fig, axes[name])
    _event_list(fig, ax_xy, legend, named, result.interruptions)
    return fig
