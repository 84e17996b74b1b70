"""``rpf-fly sim --plot``: each drone in its own colour, the planner mode as the line style, goals in the drone's
colour joined to the start, the legend beside the arena."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import to_rgba  # noqa: E402

from rpf_fly.mission import load_mission, with_planner  # noqa: E402
from rpf_fly.planning.factory import make_planner  # noqa: E402
from rpf_fly.sim import SimParams, rollout, scenario_from_mission  # noqa: E402
from rpf_fly.sim.plot import MODE_STYLES, mode_runs, rollout_figure  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def run(mission: str, planner: str = "apf"):  # type: ignore[no-untyped-def]
    loaded = with_planner(load_mission(ROOT / "missions" / f"{mission}.yaml"), planner)
    scenario = scenario_from_mission(loaded, 0)
    params = SimParams(loaded.flight.speed, loaded.flight.dt, loaded.flight.goal_tolerance, loaded.sim.time_limit_s)
    return rollout(scenario, make_planner(loaded.planner, scenario.obstacles), params)


def test_mode_runs():
    assert mode_runs(np.array([0, 0, 2, 2, 1, 0, -1, -1])) == [(0, 0, 2), (2, 2, 4), (1, 4, 5), (0, 5, 6)]
    assert mode_runs(np.array([-1, -1])) == []


def test_tracks_are_coloured_by_drone_and_styled_by_mode():
    result = run("arena-a-6")  # wall-following, soft rule and APF all happen here
    fig = rollout_figure(result)
    try:
        (ax,) = fig.axes
        lines = [a for a in ax.get_lines() if (a.get_gid() or "").startswith("track:")]
        colour_of: dict[str, set] = {}
        modes_seen: set[int] = set()
        for line in lines:
            _, name, mode = line.get_gid().split(":")
            colour_of.setdefault(name, set()).add(to_rgba(line.get_color()))
            modes_seen.add(int(mode))
            assert line.get_linestyle() == MODE_STYLES[int(mode)]
        assert set(colour_of) == set(result.scenario.names)
        assert all(len(c) == 1 for c in colour_of.values())  # one colour per drone, whatever the mode
        assert len({next(iter(c)) for c in colour_of.values()}) == len(colour_of)  # and different drones differ
        assert {0, 1, 2} <= modes_seen
        assert len(set(MODE_STYLES.values())) == 3  # three modes, three styles
        for name in result.scenario.names:
            (goal,) = [a for a in ax.get_lines() if a.get_gid() == f"goal:{name}"]
            (join,) = [a for a in ax.get_lines() if a.get_gid() == f"start-goal:{name}"]
            assert {to_rgba(goal.get_markerfacecolor()), to_rgba(join.get_color())[:3] + (1.0,)} == colour_of[name]
        renderer = fig.canvas.get_renderer()
        legend, arena = ax.get_legend().get_window_extent(renderer), ax.get_window_extent(renderer)
        assert legend.x0 >= arena.x1  # beside the arena, over no goal
    finally:
        plt.close(fig)


def test_the_modes_drawn_are_the_rollouts():
    result = run("lab-3")
    fig = rollout_figure(result)
    try:
        (ax,) = fig.axes
        i = list(result.scenario.names).index("cf2")
        runs = mode_runs(result.modes[:, i])
        drawn = [a for a in ax.get_lines() if (a.get_gid() or "").startswith("track:cf2:")]
        assert [int(a.get_gid().split(":")[2]) for a in drawn] == [m for m, _, _ in runs]
        track = result.positions[:, i]
        for line, (_, a, b) in zip(drawn, runs):
            assert line.get_xdata()[0] == track[a].real and line.get_xdata()[-1] == track[b].real
    finally:
        plt.close(fig)


def test_forty_drones_legend_and_labels_are_cut_off_by_no_edge(tmp_path):
    """The 40-drone missions: beside the wide lanes arena and the square cross one, the legend (20 names, the rest
    counted, the modes) and the axis labels lie inside the figure."""
    from rpf_fly.sim.plot import plot_rollout

    for mission in ("lanes-40-4dongles", "cross-40-4dongles"):
        result = run(mission)
        fig = rollout_figure(result)
        try:
            fig.canvas.draw()
            renderer = fig.canvas.get_renderer()
            (ax,) = fig.axes
            inside = fig.bbox.padded(-1)
            for artist in (ax.get_legend(), ax.xaxis.label, ax.yaxis.label, ax.title):
                box = artist.get_window_extent(renderer)
                assert inside.contains(box.x0, box.y0) and inside.contains(box.x1, box.y1), (mission, artist, box)
        finally:
            plt.close(fig)
        png = plot_rollout(result, tmp_path / f"{mission}.png")
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
