"""The review figure of real logs (``sim --log`` and dry runs through the CLI): which panels it has, one time axis,
goals in their drone's colour, the legend off the arena, events named, interruptions marked."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.colors import to_rgba  # noqa: E402

from rpf_fly.log.reader import read_log  # noqa: E402
from rpf_fly.log.review import review  # noqa: E402
from rpf_fly.log.review_plot import labelled_events, plot_review, review_figure  # noqa: E402
from rpf_fly.log.review_series import obstacle_clearance, pose_series  # noqa: E402

# Its module and session fixtures fly once: the tests sharing them run on one xdist worker (pyproject: --dist
# loadgroup).
pytestmark = pytest.mark.xdist_group("cli_flights")

TIME_PANELS = ("altitude", "tracking", "separation", "clearance", "battery", "events")


def figure_of(path):  # type: ignore[no-untyped-def]
    data = read_log(path)
    result = review(data)
    return data, result, review_figure(data, result)


def panels(fig) -> dict:  # type: ignore[no-untyped-def]
    return {ax.get_label(): ax for ax in fig.axes}


def by_gid(ax, gid: str) -> list:  # type: ignore[no-untyped-def]
    return [a for a in ax.get_children() if a.get_gid() == gid]


@pytest.fixture(scope="module")
def dry_figure(clean_cli_flight):  # type: ignore[no-untyped-def]
    data, result, fig = figure_of(clean_cli_flight.log)
    yield data, result, fig
    plt.close(fig)


def test_a_dry_run_has_every_panel_on_one_time_axis(dry_figure):
    _, result, fig = dry_figure
    axes = panels(fig)
    assert set(axes) == {"xy", *TIME_PANELS}
    events = axes["events"]
    for name in TIME_PANELS:
        assert axes[name].get_shared_x_axes().joined(axes[name], events), name  # the tracking panel too
        assert axes[name].get_xlim() == events.get_xlim()
    assert events.get_xlim()[1] == pytest.approx(1.01 * result.duration_s)


def test_goals_in_their_drones_colour_joined_to_the_start(dry_figure):
    data, result, fig = dry_figure
    xy = panels(fig)["xy"]
    scenario = result.scenario
    for i, drone in enumerate(result.drones):
        (track,) = by_gid(xy, f"track:{drone}")
        (goal,) = by_gid(xy, f"goal:{drone}")
        (line,) = by_gid(xy, f"start-goal:{drone}")
        assert to_rgba(goal.get_markerfacecolor()) == to_rgba(track.get_color()) == to_rgba(line.get_color())
        assert goal.get_xydata()[0] == pytest.approx(scenario["goals"][i])
        first = pose_series(data, drone, result.start_ns).values[0, :2]
        assert line.get_xydata()[0] == pytest.approx(first) and line.get_xydata()[1] == pytest.approx(
            scenario["goals"][i]
        )
        assert line.get_linewidth() < track.get_linewidth()  # thin
    colours = {to_rgba(by_gid(xy, f"goal:{d}")[0].get_markerfacecolor()) for d in result.drones}
    assert len(colours) == len(result.drones)


def test_the_legend_is_off_the_arena(dry_figure):
    _, _, fig = dry_figure
    xy = panels(fig)["xy"]
    renderer = fig.canvas.get_renderer()
    legend = xy.get_legend().get_window_extent(renderer)
    arena = xy.get_window_extent(renderer)
    assert legend.y1 <= arena.y0  # below the axes: it covers no goal


def test_the_clearance_panel_is_against_r(dry_figure):
    data, result, fig = dry_figure
    ax = panels(fig)["clearance"]
    (r_line,) = by_gid(ax, "r")
    assert r_line.get_ydata()[0] == pytest.approx(result.scenario["safety_radius"])
    c = obstacle_clearance(data, "cf2", result.start_ns, result.scenario)
    pose = pose_series(data, "cf2", result.start_ns).values[0]
    # cf2 starts at (-1, 0), the pole of radius 0.1 stands at (0, 0.9): centre to surface
    assert c.values[0] == pytest.approx(np.hypot(pose[0] - 0.0, pose[1] - 0.9) - 0.1, abs=1e-6)
    # the metric is the swarm's: the smallest clearance of any drone (which one passes nearest depends on the model)
    nearest = min(obstacle_clearance(data, d, result.start_ns, result.scenario).values.min() for d in result.drones)
    assert result.metrics.min_obstacle_clearance_m == pytest.approx(nearest, abs=0.05)


def test_events_are_named_first_of_each_kind(dry_figure):
    _, result, fig = dry_figure
    named = labelled_events(result.events)
    texts = [t for _, t in named]
    assert any(t.startswith("swarm: flying") for t in texts) and any(t.startswith("swarm: done") for t in texts)
    assert len(named) < len(result.events)  # repeats are counted, not named again
    assert any("(x3)" in t for t in texts)  # e.g. every drone's take-off
    labels = by_gid(panels(fig)["events"], "event-label")
    numbers = sorted(int(n) for a in labels for n in a.get_text().replace("-", ",").split(","))
    assert numbers[0] == 1 and numbers[-1] == len(named)
    assert by_gid(panels(fig)["events"], "interruption") == []


def test_an_interrupted_flight_is_marked_and_named(stopped_cli_flight, tmp_path):
    data, result, fig = figure_of(stopped_cli_flight.log)
    try:
        for name in TIME_PANELS:
            lines = by_gid(panels(fig)[name], "interruption")
            assert len(lines) == 1 and lines[0].get_xdata()[0] == pytest.approx(result.interruptions[0].t_s)
        texts = [t for e, t in labelled_events(result.events)]
        assert any("interrupted" in t for t in texts) and any("second Ctrl-C" in t for t in texts)
        assert "INTERRUPTED (signal)" in fig._suptitle.get_text()
    finally:
        plt.close(fig)


def test_a_simulated_log_has_no_tracking_or_battery_panel(lab_log, tmp_path):
    path, _ = lab_log
    data, result, fig = figure_of(path)
    try:
        assert set(panels(fig)) == {"xy", "altitude", "separation", "clearance", "events"}
    finally:
        plt.close(fig)
    png = plot_review(data, result, tmp_path / "sim.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_errors_are_always_named():
    from rpf_fly.log.review import ReviewEvent

    events = [
        ReviewEvent(1.0, 4, "link lost", "cf1", "link"),
        ReviewEvent(2.0, 4, "link lost", "cf2", "link"),
        ReviewEvent(3.0, 2, "arrived", "cf1", "arrived"),
        ReviewEvent(4.0, 2, "arrived", "cf2", "arrived"),
    ]
    texts = [t for _, t in labelled_events(events)]
    assert texts == ["cf1: link lost", "cf2: link lost", "cf1: arrived (x2)"]


def marker_boxes(fig, ax) -> list:  # type: ignore[no-untyped-def]
    """The event triangles of the timeline, in display pixels."""
    from matplotlib.transforms import Bbox

    boxes = []
    for line in ax.get_lines():
        if line.get_marker() == "v":
            x, y = ax.transData.transform((line.get_xdata()[0], line.get_ydata()[0]))
            half = line.get_markersize() * fig.dpi / 72 / 2
            boxes.append(Bbox.from_extents(x - half, y - half, x + half, y + half))
    return boxes


@pytest.mark.parametrize("flight", ["clean_cli_flight", "stopped_cli_flight"])
def test_event_numbers_cover_no_marker_and_no_other_number(flight, request):
    """An interruption and the events of its instant share one time: each number still has a spot of its own,
    on a white ground (the interruption's line does not strike through it)."""
    _, _, fig = figure_of(request.getfixturevalue(flight).log)
    try:
        ax = panels(fig)["events"]
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        labels = by_gid(ax, "event-label")
        boxes = [label.get_window_extent(renderer) for label in labels]
        markers = marker_boxes(fig, ax)
        for i, box in enumerate(boxes):
            assert not any(box.overlaps(m) for m in markers), labels[i].get_text()
            assert not any(box.overlaps(other) for other in boxes[i + 1 :]), labels[i].get_text()
            assert labels[i].get_bbox_patch() is not None
    finally:
        plt.close(fig)


@pytest.mark.parametrize("flight", ["clean_cli_flight", "stopped_cli_flight", "lab_log"])
def test_no_time_panel_legend_covers_a_curve(flight, request):
    log = request.getfixturevalue(flight)
    _, _, fig = figure_of(log[0] if flight == "lab_log" else log.log)
    try:
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        assert [a.get_text() for a in by_gid(panels(fig)["clearance"], "r-label")] == ["r = 0.1 m"]
        for name in ("tracking", "separation", "clearance"):
            ax = panels(fig).get(name)
            if ax is None or ax.get_legend() is None:  # a simulated log tracks nothing; clearance names r on it
                continue
            box = ax.get_legend().get_window_extent(renderer)
            for line in ax.get_lines():
                if line.get_gid() in ("interruption", "r", "2r"):  # vertical, or the threshold the legend names
                    continue
                points = ax.transData.transform(np.column_stack([line.get_xdata(), line.get_ydata()]))
                inside = (
                    (box.x0 < points[:, 0])
                    & (points[:, 0] < box.x1)
                    & (box.y0 < points[:, 1])
                    & (points[:, 1] < box.y1)
                )
                assert not inside.any(), (name, line.get_label(), int(inside.sum()))
    finally:
        plt.close(fig)


def test_a_label_counts_only_events_that_are_the_same_thing():
    """Three faults injected into cf2 are three labels, not ``cf2: injected occlusion (x3)``; two occlusions share
    one; a take-off commanded is not a drone airborne."""
    from rpf_fly.log.review import ReviewEvent

    events = [
        ReviewEvent(1.0, 2, "take-off commanded: 3 drone(s) to 0.60 m in 2 s", "flight", "takeoff"),
        ReviewEvent(3.0, 2, "airborne at 0.60 m: planning", "cf1", "takeoff"),
        ReviewEvent(3.1, 2, "airborne at 0.59 m: planning", "cf2", "takeoff"),
        ReviewEvent(4.0, 2, "injected occlusion for 0.6 s", "cf2", "fault"),
        ReviewEvent(6.0, 2, "injected gust for 1 s: accel (0.0, 1.5, 0.0)", "cf2", "fault"),
        ReviewEvent(8.0, 2, "injected low_battery", "cf2", "fault"),
        ReviewEvent(9.0, 2, "injected occlusion for 0.3 s", "cf1", "fault"),
    ]
    assert [t for _, t in labelled_events(events)] == [
        "take-off commanded: 3 drone(s) to 0.60 m in 2 s",
        "cf1: airborne at 0.60 m: planning (x2)",
        "cf2: injected occlusion for 0.6 s (x2)",
        "cf2: injected gust for 1 s: accel (0.0, 1.5, 0.0)",
        "cf2: injected low_battery",
    ]


def test_every_flight_phase_has_a_colour_of_its_own():
    from rpf_fly.flight.phases import DronePhase
    from rpf_fly.log.review_plot import STATE_COLOURS

    assert {p.value for p in DronePhase} <= set(STATE_COLOURS)  # waiting, ready, holding... none falls to the grey
    assert len({to_rgba(c) for c in STATE_COLOURS.values()}) == len(STATE_COLOURS)
