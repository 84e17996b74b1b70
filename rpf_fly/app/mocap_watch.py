"""What ``rpf-fly mocap watch`` makes of the frames it shows, from NatNet or a system of the motioncapture package
alike: the counts and rates of its closing summary (:class:`WatchStats`), and whether the bodies look streamed with
the other up axis than the one assumed (:class:`UpAxisCheck`). Apart from the command so that both watch loops
(``cli/mocap_cmd.py``, ``cli/mocap_library.py``) share them without importing each other's insides.
"""

from __future__ import annotations

import math


class WatchStats:
    """What ``watch`` saw: frames, their rate, frame numbers the server skipped (frames lost on the way), and per
    body how often it was tracked. Fed one frame at a time; :meth:`summary` is the closing report."""

    def __init__(self) -> None:
        self.frames = 0
        self.first_s: float | None = None
        self.last_s: float | None = None
        self.first_number: int | None = None
        self.last_number: int | None = None
        self.missed = 0
        self.seen: dict[str, int] = {}
        self.valid: dict[str, int] = {}
        self.latencies: list[float] = []

    def add(self, frame) -> None:  # noqa: ANN001 - MocapFrame
        self.frames += 1
        self.first_s = frame.receive_time_s if self.first_s is None else self.first_s
        self.last_s = frame.receive_time_s
        if self.last_number is not None and frame.frame_number > self.last_number + 1:
            self.missed += frame.frame_number - self.last_number - 1
        if self.first_number is None:
            self.first_number = frame.frame_number
        self.last_number = frame.frame_number if self.last_number is None else max(self.last_number, frame.frame_number)
        for name, pose in frame.bodies.items():
            self.seen[name] = self.seen.get(name, 0) + 1
            self.valid[name] = self.valid.get(name, 0) + bool(pose.valid)
        if frame.latency_s is not None:
            self.latencies.append(frame.latency_s)

    @property
    def rate_hz(self) -> float | None:
        if self.frames < 2 or self.first_s is None or self.last_s is None or self.last_s <= self.first_s:
            return None
        return (self.frames - 1) / (self.last_s - self.first_s)

    def valid_pct(self, name: str) -> float:
        return 100.0 * self.valid.get(name, 0) / self.frames if self.frames else 0.0

    @property
    def span_s(self) -> float | None:
        """Seconds from the first frame's arrival to the last's (None before two frames)."""
        if self.frames < 2 or self.first_s is None or self.last_s is None:
            return None
        return self.last_s - self.first_s

    def summary(self, elapsed_s: float, stats=None) -> list[str]:  # noqa: ANN001 - MocapStats
        """The closing report: frames, the span from the first to the last and the rate over it, how long the
        watch ran (longer than the span where the stream stopped or started late), frames missed, packets dropped,
        latency; per body its valid %."""
        rate, span = self.rate_hz, self.span_s
        head = f"summary: {self.frames} frame{'' if self.frames == 1 else 's'}"
        if span is not None:
            head += f" over {span:.1f} s" + (f", {rate:.1f} Hz" if rate is not None else "") + " (first to last)"
        head += f"; watched {elapsed_s:.1f} s; {self.missed} missed (frame numbers skipped)"
        if stats is not None:
            head += f", {stats.superseded} not shown (newer frame waiting), {stats.dropped} packets dropped"
        if self.latencies:
            ordered = sorted(self.latencies)
            head += f"; latency p50 {ordered[len(ordered) // 2] * 1e3:.1f} ms, max {ordered[-1] * 1e3:.1f} ms"
        lines = [head]
        for name in sorted(self.seen):
            lines.append(f"  {name}: valid {self.valid_pct(name):5.1f} % ({self.valid.get(name, 0)}/{self.frames})")
        if not self.seen:
            lines.append("  no rigid bodies")
        return lines


FLOOR_BELOW_M = 0.05
"""A tracked body this far below z = 0 (the floor, Motive's ground plane) cannot be there: the up axis is wrong."""
FLAT_Y_M = 0.1
TALL_Z_M = 0.3
"""Bodies at rest whose y all lie within ``FLAT_Y_M`` of 0 while one's z reaches ``TALL_Z_M``: if they stand on the
floor, their height is in y, the stream's up axis is the other one."""
REST_M = 0.01
"""A body whose position spans at most this over the check's frames is at rest."""
UP_AXIS_CHECK_S = 1.0
"""The check judges the first second of frames (or all of them when the watch is shorter)."""


class UpAxisCheck:
    """Whether the bodies look streamed with the other up axis than the one ``watch`` assumed (``--up-axis``; NatNet
    does not carry Motive's Up Axis setting, so nothing else can tell): a tracked body below the floor (a Y-up
    stream read as Z-up shows a depth as its z, z -0.999), or bodies at rest all with y near 0 and z up to 0.3 m or
    more (their height is in y). Fed every frame; :meth:`add` returns the hint once, when the first second is in."""

    def __init__(self, assumed: str):
        self.assumed = assumed
        self.first_s: float | None = None
        self.positions: dict[str, list[tuple[float, float, float]]] = {}
        self.hint: str | None = None
        self.done = False

    def add(self, frame) -> str | None:  # noqa: ANN001 - MocapFrame
        if self.done:
            return None
        self.first_s = frame.receive_time_s if self.first_s is None else self.first_s
        for name, pose in frame.bodies.items():
            if pose.valid and all(math.isfinite(v) for v in pose.position):
                self.positions.setdefault(name, []).append(tuple(pose.position))
        return self.finish() if frame.receive_time_s - self.first_s >= UP_AXIS_CHECK_S else None

    def finish(self) -> str | None:
        """Judge what came so far (once): the hint, or None when the data look as assumed."""
        if self.done:
            return None
        self.done = True
        self.hint = self._judge()
        return self.hint

    def _judge(self) -> str | None:
        other = "y" if self.assumed == "z" else "z"
        means = {n: tuple(sum(p[k] for p in ps) / len(ps) for k in range(3)) for n, ps in self.positions.items()}
        if not means:
            return None
        default = " (Motive's default)" if other == "y" else ""
        fix = (
            f"the stream looks {other.upper()}-up{default}, not the "
            f"{self.assumed.upper()}-up assumed (--up-axis {self.assumed}): watch with --up-axis {other}, and fly "
            f"with mocap.up_axis: {other}"
        )
        name, lowest = min(((n, p[2]) for n, p in means.items()), key=lambda item: item[1])
        if lowest < -FLOOR_BELOW_M:
            return f"hint: {name} is at z {lowest:+.3f} m, below the floor: {fix}"
        resting = {
            n: means[n]
            for n, ps in self.positions.items()
            if max(max(p[k] for p in ps) - min(p[k] for p in ps) for k in range(3)) <= REST_M
        }
        if resting and all(abs(p[1]) <= FLAT_Y_M for p in resting.values()):
            name, top = max(((n, p[2]) for n, p in resting.items()), key=lambda item: abs(item[1]))
            if abs(top) >= TALL_Z_M:
                return (
                    f"hint: every body at rest has y within {FLAT_Y_M:g} m of 0 while {name} is at z {top:+.3f} m: "
                    f"if they stand on the floor, {fix}"
                )
        return None
