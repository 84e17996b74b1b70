"""Fly a dynamics scenario offline on the simulated Crazyflie (cf_drone.py), write its trace, compute its figures.

Scenario file (YAML): `name`, `start` [x, y, z], `duration_s`, and either `stream_hz` + `setpoints` (list of
[t_s, x, y, z]: absolute position setpoints, yaw 0, each sent at every stream tick k / stream_hz from its time until
the next listed one) with an optional `hold_at` (from the first stream tick at or after it, the stream sends the
drone's own x, y at that tick and the last setpoint's z), or `commands` (list of [t_s, "takeoff", height_m,
duration_s], [t_s, "go_to", x, y, z, duration_s], [t_s, "land", height_m, duration_s]: cflib's high-level commands,
absolute, yaw 0, each sent once at t_s).

Start states: a setpoint scenario starts from a settled hover at `start` (`CfDrone.hovering`: 10 s of hover before
t = 0); a command scenario from the floor under `start` (z 0), motors off, 1 s before t = 0. A setpoint or command
acts from the instant it is sent (no radio or mocap latency).

Trace (JSON, strict: no NaN or Infinity): `name`, `t` (50 Hz samples at 0.004 + 0.02 k s before `duration_s`, the
sample instants of the reference traces this is compared with), `sp` (the setpoint in effect, or the high-level
plan's position; the start at z 0 before any plan), `pos` (true position), `tilt_deg` (angle between the body z
axis and the vertical), `figures`.

Figures (`figures(trace, scenario)`), by scenario kind (from its name: `step`, `carrot`, `hold`, `circle`, `hl`):
- settling time to a target within a band from a start time over a set of samples: the time of the last sample at
  or after the start whose value lies outside the band, minus the start (0 if none); infinite ("not settled") if
  the set's last sample lies outside.
- step (the setpoint jumps at t = 0 from the start to start + X along x): `rise_s` (first sample with x >= 0.9 X
  minus first with x >= 0.1 X), `overshoot_cm` (largest x minus X, or 0), `settle_s` (x to X within 2 % of X from
  0), `peak_speed_m_s` (largest forward difference of x), `z_dev_cm` (largest |z - start z|), `peak_tilt_deg`.
- carrot (moves along x at v for T s, then stays at v T; T the last listed setpoint's time): `lag_cm` (mean of
  setpoint x - x over T - 1 <= t < T), `overshoot_cm` (largest x - v T, or 0), `settle_s` (to v T within 2 cm from
  T), `peak_tilt_deg`, `peak_tilt_after_stop_deg` (t >= T).
- hold (a carrot whose stream becomes the drone's own position at T = hold_at): `lag_cm` as the carrot's,
  `speed_after_hold_m_s` (forward difference of x at the first sample with t >= T), `overshoot_cm` (largest x minus
  the hold point, the setpoint x of that sample, or 0), `settle_s` (to the hold point within 2 cm from T),
  `peak_tilt_deg`, `peak_tilt_after_stop_deg`.
- circle (radius R about the z axis, two laps), over the samples t >= t_last / 2: `along_cm` (mean of R x the
  wrapped angle of the setpoint minus the drone's, about the origin), `radial_cm` (mean distance from the z axis
  minus R), `err_mean_cm` / `err_max_cm` (horizontal distance setpoint to drone), `peak_tilt_deg`.
- hl (take-off at t_to0 to h in T_to, go_to along x to x_g at t_g in T_g, land at t_l in T_l; "plan" is `sp`;
  windows include both ends, times relative to the take-off command): `takeoff_lag_max_cm` (largest |plan z - z|
  over [0, T_to + 1]), `takeoff_overshoot_cm` (largest z over [0, t_g] minus h, or 0), `takeoff_settle_s` (z to h
  within 2 cm from T_to over [0, t_g]), `z_err_at_goto_cm` (z of the last sample at or before t_g minus h),
  `goto_lag_max_cm` (largest |plan x - x| over [t_g, t_g + T_g + 1]), `goto_overshoot_cm` (largest x over
  [t_g, t_l] minus x_g, or 0), `goto_settle_s` (x to x_g within 2 cm from t_g + T_g over [t_g, t_l]),
  `land_lag_max_cm` (largest |plan z - z| over [t_l, t_l + T_l]), `touchdown_after_land_s` (first sample at or after
  t_l with z < 0.01 m, minus t_l; None if none), `peak_tilt_deg`.
Distances in cm are 100 x metres. These are the definitions of the Crazyflie dynamics reference this model is
checked against (docs/dynamics.md).

Run: ``python -m rpf_fly.emulator.cf_scenario SCENARIO.yaml... [--out DIR]`` prints each scenario's figures and
writes `<name>.json` traces into DIR.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from .cf_drone import CfDrone

SAMPLE_PERIOD_S = 0.02
SAMPLE_OFFSET_S = 0.004
"""The trace's samples: 0.004 + 0.02 k s (50 Hz), as the reference's."""
HOVER_SETTLE_S = 10.0
FLOOR_LEAD_S = 1.0
NOT_SETTLED = "not settled"


@dataclass
class Scenario:
    name: str
    start: tuple[float, float, float]
    duration_s: float
    stream_hz: float | None = None
    setpoints: list[tuple[float, float, float, float]] = field(default_factory=list)
    hold_at: float | None = None
    commands: list[list[Any]] = field(default_factory=list)

    @property
    def is_command(self) -> bool:
        return bool(self.commands)

    @property
    def kind(self) -> str:
        """step, carrot, hold, circle or hl (from the name, as the reference names its scenarios)."""
        for kind in ("step", "carrot", "hold", "circle", "hl"):
            if re.search(rf"(^|_){kind}(_|$)", self.name):
                return kind
        if self.is_command:
            return "hl"
        if self.hold_at is not None:
            return "hold"
        return "step" if len(self.setpoints) == 1 else "carrot"

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Scenario:
        x, y, z = (float(v) for v in data["start"])
        setpoints = [_setpoint_row(row) for row in data.get("setpoints") or []]
        commands = [list(row) for row in data.get("commands") or []]
        if bool(setpoints) == bool(commands):
            raise ValueError(f"scenario {data.get('name')!r}: give either setpoints or commands")
        if setpoints and not data.get("stream_hz"):
            raise ValueError(f"scenario {data.get('name')!r}: setpoints need stream_hz")
        hold_at = data.get("hold_at")
        return cls(
            str(data["name"]),
            (x, y, z),
            float(data["duration_s"]),
            float(data["stream_hz"]) if data.get("stream_hz") else None,
            setpoints,
            float(hold_at) if hold_at is not None else None,
            commands,
        )

    @classmethod
    def load(cls, path: str | Path) -> Scenario:
        return cls.from_dict(yaml.safe_load(Path(path).read_text(encoding="utf-8")))


# Scenarios of the reference's kinds -----------------------------------------------------------------------------


def step_scenario(
    distance_m: float,
    *,
    name: str | None = None,
    height_m: float = 1.0,
    duration_s: float = 6.0,
    stream_hz: float = 10.0,
) -> Scenario:
    """A step of `distance_m` along x from a hover at (0, 0, height) at t = 0."""
    return Scenario(
        name or f"step_{distance_m:g}", (0.0, 0.0, height_m), duration_s, stream_hz, [(0.0, distance_m, 0.0, height_m)]
    )


def _setpoint_row(row: Any) -> tuple[float, float, float, float]:
    """A scenario file's setpoint ``[t, x, y, z]`` as numbers."""
    t, x, y, z = (float(v) for v in row)
    return t, x, y, z


def _carrot_points(
    speed: float, move_s: float, stream_hz: float, height_m: float
) -> list[tuple[float, float, float, float]]:
    n = round(move_s * stream_hz)
    return [(round(k / stream_hz, 9), round(speed * k / stream_hz, 9), 0.0, height_m) for k in range(n + 1)]


def carrot_scenario(
    speed_m_s: float,
    *,
    name: str | None = None,
    move_s: float = 3.0,
    height_m: float = 1.0,
    duration_s: float = 8.0,
    stream_hz: float = 10.0,
) -> Scenario:
    """A carrot from (0, 0, height) along x at `speed_m_s` for `move_s`, then still at speed x move_s."""
    return Scenario(
        name or f"carrot_{speed_m_s:g}",
        (0.0, 0.0, height_m),
        duration_s,
        stream_hz,
        _carrot_points(speed_m_s, move_s, stream_hz, height_m),
    )


def hold_scenario(
    speed_m_s: float,
    *,
    name: str | None = None,
    hold_at: float = 3.0,
    height_m: float = 1.0,
    duration_s: float = 8.0,
    stream_hz: float = 10.0,
) -> Scenario:
    """A carrot at `speed_m_s` whose stream becomes the drone's own position at `hold_at`."""
    points = _carrot_points(speed_m_s, hold_at, stream_hz, height_m)[:-1]
    return Scenario(name or f"hold_{speed_m_s:g}", (0.0, 0.0, height_m), duration_s, stream_hz, points, hold_at)


def circle_scenario(
    radius_m: float,
    speed_m_s: float,
    *,
    name: str | None = None,
    laps: int = 2,
    height_m: float = 1.0,
    stream_hz: float = 10.0,
) -> Scenario:
    """A circle of `radius_m` about the z axis at `height_m`, counter-clockwise at `speed_m_s` from (R, 0)."""
    omega = speed_m_s / radius_m
    duration = round(laps * 2.0 * math.pi / omega, 3)
    n = math.floor(duration * stream_hz + 1e-9)
    points = [
        (
            round(k / stream_hz, 9),
            round(radius_m * math.cos(omega * k / stream_hz), 6),
            round(radius_m * math.sin(omega * k / stream_hz), 6),
            height_m,
        )
        for k in range(n + 1)
    ]
    return Scenario(
        name or f"circle_{radius_m:g}_{speed_m_s:g}", (radius_m, 0.0, height_m), duration, stream_hz, points
    )


def hl_scenario(
    height_m: float,
    takeoff_s: float,
    goto_x_m: float,
    goto_at_s: float,
    goto_s: float,
    land_at_s: float,
    land_s: float,
    *,
    name: str = "hl",
    duration_s: float | None = None,
) -> Scenario:
    """From the floor at the origin: take-off to `height_m` in `takeoff_s` at 0, go_to (goto_x_m, 0, height) at
    `goto_at_s` in `goto_s`, land at `land_at_s` in `land_s`."""
    commands = [
        [0.0, "takeoff", height_m, takeoff_s],
        [goto_at_s, "go_to", goto_x_m, 0.0, height_m, goto_s],
        [land_at_s, "land", 0.0, land_s],
    ]
    return Scenario(
        name, (0.0, 0.0, 0.0), duration_s if duration_s is not None else land_at_s + land_s + 2.0, commands=commands
    )


# Flying --------------------------------------------------------------------------------------------------------


def _ticks(t_s: float) -> int:
    return round(t_s * 1000.0)


def fly(
    scenario: Scenario,
    *,
    integrator: str = "midpoint",
    sample_offset_s: float = SAMPLE_OFFSET_S,
    sample_period_s: float = SAMPLE_PERIOD_S,
) -> dict[str, Any]:
    """Fly `scenario` from its start state; return its trace (module doc), figures included."""
    if scenario.is_command:
        drone = CfDrone((scenario.start[0], scenario.start[1], 0.0), t_s=-FLOOR_LEAD_S, integrator=integrator)
        drone.step(FLOOR_LEAD_S)
    else:
        drone = CfDrone.hovering(scenario.start, t_s=0.0, settle_s=HOVER_SETTLE_S, integrator=integrator)
    end_tick = _ticks(scenario.duration_s)
    # what happens at which tick
    sends: dict[int, Any] = {}
    if scenario.is_command:
        for row in scenario.commands:
            sends.setdefault(_ticks(float(row[0])), []).append(row)
    else:
        assert scenario.stream_hz is not None
        j = 0
        while True:
            t = j / scenario.stream_hz
            if t > scenario.duration_s + 1e-9:
                break
            sends[_ticks(t)] = t
            j += 1
    samples = []
    t = sample_offset_s
    while t < scenario.duration_s - 1e-9:  # as the reference: no sample at the end instant itself
        samples.append(t)
        t = sample_offset_s + len(samples) * sample_period_s
    sample_ticks = {_ticks(t): t for t in samples}
    trace: dict[str, Any] = {"name": scenario.name, "t": [], "sp": [], "pos": [], "tilt_deg": []}
    listed = scenario.setpoints
    index = -1
    sp = (scenario.start[0], scenario.start[1], scenario.start[2])
    held: tuple[float, float, float] | None = None
    for tick in range(0, end_tick + 1):
        if tick in sample_ticks:
            ts = sample_ticks[tick]
            if scenario.is_command:
                plan = drone.plan_position(ts)
                shown = plan if plan is not None else (scenario.start[0], scenario.start[1], 0.0)
            else:
                shown = sp
            trace["t"].append(round(ts, 6))
            trace["sp"].append([float(v) for v in shown])
            trace["pos"].append(list(drone.position))
            trace["tilt_deg"].append(drone.tilt_deg)
        if tick in sends:
            if scenario.is_command:
                for row in sends[tick]:
                    _command(drone, row)
            else:
                t_send = sends[tick]
                if scenario.hold_at is not None and t_send >= scenario.hold_at - 1e-9:
                    if held is None:
                        x, y, _ = drone.position
                        held = (x, y, sp[2])
                    sp = held
                else:
                    while index + 1 < len(listed) and listed[index + 1][0] <= t_send + 1e-9:
                        index += 1
                    if index >= 0:
                        sp = listed[index][1:4]
                drone.send_position(sp[0], sp[1], sp[2], 0.0)
        if tick < end_tick:
            drone.step(0.001)
    trace["figures"] = figures(trace, scenario)
    return trace


def _command(drone: CfDrone, row: Sequence[Any]) -> None:
    kind = str(row[1])
    if kind == "takeoff":
        drone.takeoff(float(row[2]), float(row[3]))
    elif kind == "land":
        drone.land(float(row[2]), float(row[3]))
    elif kind == "go_to":
        drone.go_to(float(row[2]), float(row[3]), float(row[4]), float(row[5]))
    else:
        raise ValueError(f"unknown command {kind!r}")


# Figures -------------------------------------------------------------------------------------------------------


def settling_time(t: Sequence[float], values: Sequence[float], target: float, band: float, start: float) -> float:
    """Settling time (module doc): inf when the set's last sample lies outside the band."""
    if not t:
        return 0.0
    if abs(values[-1] - target) > band:
        return math.inf
    last = None
    for ti, v in zip(t, values):
        if ti >= start and abs(v - target) > band:
            last = ti
    return 0.0 if last is None else last - start


def _window(t: Sequence[float], lo: float, hi: float, *, hi_open: bool = False) -> list[int]:
    return [i for i, ti in enumerate(t) if ti >= lo and (ti < hi if hi_open else ti <= hi)]


def figures(trace: dict[str, Any], scenario: Scenario, *, band_scale: float = 1.0) -> dict[str, Any]:
    """The figures of `trace` (module doc); settling times that never settle are `math.inf`. ``band_scale``
    widens (> 1) or narrows (< 1) every settling band: a trace whose error lingers near a band's edge settles at
    very different times in bands a few millimetres apart, and a comparison of settling times reads the bracket."""
    t = [float(v) for v in trace["t"]]
    sp = trace["sp"]
    pos = trace["pos"]
    tilt = [float(v) for v in trace["tilt_deg"]] if "tilt_deg" in trace else None
    x = [p[0] for p in pos]
    kind = scenario.kind
    out: dict[str, Any] = {}
    if kind == "step":
        x0 = scenario.start[0]
        big_x = scenario.setpoints[-1][1] - x0
        rel = [v - x0 for v in x]
        first10 = next(t[i] for i, v in enumerate(rel) if v >= 0.1 * big_x)
        first90 = next(t[i] for i, v in enumerate(rel) if v >= 0.9 * big_x)
        out["rise_s"] = first90 - first10
        out["overshoot_cm"] = max(0.0, max(rel) - big_x) * 100.0
        out["settle_s"] = settling_time(t, rel, big_x, 0.02 * band_scale * abs(big_x), 0.0)
        out["peak_speed_m_s"] = max((x[i + 1] - x[i]) / (t[i + 1] - t[i]) for i in range(len(t) - 1))
        out["z_dev_cm"] = max(abs(p[2] - scenario.start[2]) for p in pos) * 100.0
        if tilt is not None:
            out["peak_tilt_deg"] = max(tilt)
    elif kind in ("carrot", "hold"):
        x0 = scenario.start[0]
        big_t = scenario.hold_at if kind == "hold" else scenario.setpoints[-1][0]
        assert big_t is not None
        lag = _window(t, big_t - 1.0, big_t, hi_open=True)
        out["lag_cm"] = sum(sp[i][0] - x[i] for i in lag) / len(lag) * 100.0
        after = _window(t, big_t, math.inf)
        if kind == "carrot":
            goal = scenario.setpoints[-1][1]
            out["overshoot_cm"] = max(0.0, max(x) - goal) * 100.0
            out["settle_s"] = settling_time(t, x, goal, 0.02 * band_scale, big_t)
        else:
            i = after[0]
            hold = sp[i][0]
            out["speed_after_hold_m_s"] = (x[i + 1] - x[i]) / (t[i + 1] - t[i])
            out["overshoot_cm"] = max(0.0, max(x) - hold) * 100.0
            out["settle_s"] = settling_time(t, x, hold, 0.02 * band_scale, big_t)
        del x0
        if tilt is not None:
            out["peak_tilt_deg"] = max(tilt)
            out["peak_tilt_after_stop_deg"] = max(tilt[i] for i in after)
    elif kind == "circle":
        radius = math.hypot(scenario.setpoints[0][1], scenario.setpoints[0][2])
        lap = _window(t, t[-1] / 2.0, math.inf)
        along = radial = err_sum = 0.0
        err_max = 0.0
        for i in lap:
            a_sp = math.atan2(sp[i][1], sp[i][0])
            a = math.atan2(pos[i][1], pos[i][0])
            d = (a_sp - a + math.pi) % (2.0 * math.pi) - math.pi
            along += radius * d
            radial += math.hypot(pos[i][0], pos[i][1]) - radius
            err = math.hypot(sp[i][0] - pos[i][0], sp[i][1] - pos[i][1])
            err_sum += err
            err_max = max(err_max, err)
        n = len(lap)
        out["along_cm"] = along / n * 100.0
        out["radial_cm"] = radial / n * 100.0
        out["err_mean_cm"] = err_sum / n * 100.0
        out["err_max_cm"] = err_max * 100.0
        if tilt is not None:
            out["peak_tilt_deg"] = max(tilt[i] for i in lap)
    elif kind == "hl":
        out.update(_hl_figures(t, sp, pos, scenario, band_scale))
        if tilt is not None:
            out["peak_tilt_deg"] = max(tilt)
    else:  # pragma: no cover - kind is one of the above
        raise ValueError(kind)
    return out


def _hl_figures(
    t: list[float], sp: list[list[float]], pos: list[list[float]], scenario: Scenario, band_scale: float = 1.0
) -> dict[str, Any]:
    cmds = {str(row[1]): row for row in scenario.commands}
    t0, h, t_to = float(cmds["takeoff"][0]), float(cmds["takeoff"][2]), float(cmds["takeoff"][3])
    go = cmds["go_to"]
    t_g, x_g, t_gd = float(go[0]) - t0, float(go[2]), float(go[5])
    t_l, t_ld = float(cmds["land"][0]) - t0, float(cmds["land"][3])
    rel = [ti - t0 for ti in t]
    z = [p[2] for p in pos]
    x = [p[0] for p in pos]
    out: dict[str, Any] = {}
    w = _window(rel, 0.0, t_to + 1.0)
    out["takeoff_lag_max_cm"] = max(abs(sp[i][2] - z[i]) for i in w) * 100.0
    w = _window(rel, 0.0, t_g)
    out["takeoff_overshoot_cm"] = max(0.0, max(z[i] for i in w) - h) * 100.0
    out["takeoff_settle_s"] = settling_time([rel[i] for i in w], [z[i] for i in w], h, 0.02 * band_scale, t_to)
    out["z_err_at_goto_cm"] = (z[w[-1]] - h) * 100.0
    w = _window(rel, t_g, t_g + t_gd + 1.0)
    out["goto_lag_max_cm"] = max(abs(sp[i][0] - x[i]) for i in w) * 100.0
    w = _window(rel, t_g, t_l)
    out["goto_overshoot_cm"] = max(0.0, max(x[i] for i in w) - x_g) * 100.0
    out["goto_settle_s"] = settling_time([rel[i] for i in w], [x[i] for i in w], x_g, 0.02 * band_scale, t_g + t_gd)
    w = _window(rel, t_l, t_l + t_ld)
    out["land_lag_max_cm"] = max(abs(sp[i][2] - z[i]) for i in w) * 100.0
    touch = next((rel[i] for i in range(len(rel)) if rel[i] >= t_l and z[i] < 0.01), None)
    out["touchdown_after_land_s"] = None if touch is None else touch - t_l
    return out


def json_figures(figs: dict[str, Any]) -> dict[str, Any]:
    """Figures as strict JSON holds them: an infinite settling time is "not settled"."""
    return {k: (NOT_SETTLED if isinstance(v, float) and math.isinf(v) else v) for k, v in figs.items()}


def write_trace(trace: dict[str, Any], path: str | Path, *, digits: int = 5) -> None:
    """Write `trace` as strict JSON (positions rounded to `digits`, tilts to 3 decimals)."""
    out = dict(trace)
    out["sp"] = [[round(v, digits) for v in row] for row in trace["sp"]]
    out["pos"] = [[round(v, digits) for v in row] for row in trace["pos"]]
    out["tilt_deg"] = [round(v, 3) for v in trace["tilt_deg"]]
    out["figures"] = json_figures(trace["figures"])
    out.setdefault("source", "rpf_fly.emulator.cf_scenario")
    out.setdefault("sample_hz", 1.0 / SAMPLE_PERIOD_S)
    Path(path).write_text(json.dumps(out, allow_nan=False) + "\n", encoding="utf-8")


def _fmt(value: Any) -> str:
    return f"{value:.2f}" if isinstance(value, float) else str(value)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scenarios", nargs="+", type=Path)
    parser.add_argument("--out", type=Path, default=None, help="folder for the <name>.json traces")
    parser.add_argument("--integrator", choices=("midpoint", "rk4"), default="midpoint")
    parser.add_argument(
        "--reference",
        type=Path,
        default=None,
        help="folder of reference traces <name>.json: print a Markdown table of their figures "
        "(`figures`, on a 200 Hz record) beside this model's (on its 200 Hz record too)",
    )
    args = parser.parse_args(argv)
    if args.reference is not None:
        print("| scenario | figure | reference | this model | difference |")
        print("|---|---|---|---|---|")
    for path in args.scenarios:
        scenario = Scenario.load(path)
        trace = fly(scenario, integrator=args.integrator)
        figs = json_figures(trace["figures"])
        if args.reference is not None:  # the reference's `figures` are of its 200 Hz record: so are these
            figs = json_figures(fly(scenario, integrator=args.integrator, sample_period_s=0.005)["figures"])
            ref = json.loads((args.reference / f"{scenario.name}.json").read_text(encoding="utf-8"))["figures"]
            for i, (key, theirs) in enumerate(ref.items()):
                mine = figs.get(key)
                diff = (
                    f"{mine - theirs:+.3f}"
                    if isinstance(mine, (int, float)) and isinstance(theirs, (int, float))
                    else ""
                )
                print(f"| {scenario.name if i == 0 else ''} | {key} | {_fmt(theirs)} | {_fmt(mine)} | {diff} |")
        else:
            print(scenario.name, json.dumps({k: (round(v, 3) if isinstance(v, float) else v) for k, v in figs.items()}))
        if args.out is not None:
            args.out.mkdir(parents=True, exist_ok=True)
            write_trace(trace, args.out / f"{scenario.name}.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
