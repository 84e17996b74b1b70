"""Fit a drone's closed-loop response: the firmware gains under which the offline model, replaying the drone's
setpoint stream from its start state, flies where the drone flew.

What is fitted, per axis whose setpoint moved at least `MIN_TRAVEL_M` in the window (an axis held still says
nothing of its gains; they stay the firmware's, or the start's): the position loop's P gain (``posCtlPid.xKp``,
``yKp``, ``zKp``), the velocity loop's (``velCtlPid.vxKp``, ``vyKp``, ``vzKp``) and the height's I gain
(``posCtlPid.zKi``). The position gain sets how far the drone trails a moving setpoint (about 1 / kp of its speed),
the velocity gain how fast and how damped it gets there (the overshoot and the settling after a stop): both show in
any record with a move and a stop. The height's integrator is the only position integrator the firmware runs (x's
and y's are 0): it takes a climb's lag away and winds up under a take-off, and it shows. Replaying the dry run's
log of tests/calibrate (a carrot along x, y and z at 0.5, 0.4, 0.2 m/s for 3 s, then still) with one gain changed
moves that axis by, RMS: zKi halved 12 mm, a velocity P gain 10 % up 2.9 mm (x) or 0.9 mm (z), vxKi halved
1.2 mm, vzKi halved 2.8 mm. Not fitted (kept): the velocity loops' integrators, whose work is the drag's small
steady error and the hover's thrust (millimetres, a few mocap noise widths, and they trade against the P gains),
and the D gains (0 in the firmware; its PIDs differentiate the measurement, so a D gain acts as more damping,
which the velocity gain already fits).

How: Levenberg-Marquardt on the logarithms of the gains (a step is a ratio; a gain stays positive) and a delay,
the residual the measured positions minus the model's on all three axes. The delay: a log's setpoints are stamped
when the ground station sent them and its poses when they arrived, so the replay's positions are compared
`delay_s` later (from `MIN_DELAY_S` to `MAX_DELAY_S`, first by a search on the firmware's gains; a trace has none:
its positions are the truth at its own instants). The replay's controller sees its state as late as the poses are
(`replay`'s ``late_s``: the mocap's latency against the truth, or the first delay found where there is no truth).
The Jacobian of the gains is by forward differences, one replay per kind of gain with every fitted axis's gain of
that kind changed at once (the axes barely couple: a change of x's gains moves y and z by well under a millimetre),
refreshed after a rejected step and otherwise updated by Broyden's rule from each trial, so most iterations cost
one replay; the delay's column is the model's velocity. Stops when a step changes every gain by under 0.3 % and
the delay by under 0.5 ms, or lowers the squared error by under `MIN_GAIN`, or after `MAX_ITERATIONS`.

The mocap's latency and noise: against a dry run's ``/truth`` where the log has it (the shift that best lays the
poses on the truth, and the poses' scatter about it where the drone is nearly still); otherwise the noise from the
poses' second differences (white noise of std s gives second differences of std s sqrt(6); a flight's own
acceleration adds 0.1 mm a frame at 1 m/s^2 and 100 Hz) and the latency the fitted delay, which then includes the
radio's latency of the setpoints.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from rpf_fly.emulator.cf_controller import CfGains

from .record import FlightRecord
from .replay import Track, replay

AXES = ("x", "y", "z")
GAINS = {
    "x": ("posCtlPid.xKp", "velCtlPid.vxKp"),
    "y": ("posCtlPid.yKp", "velCtlPid.vyKp"),
    "z": ("posCtlPid.zKp", "velCtlPid.vzKp", "posCtlPid.zKi"),
}
"""The gains fitted per axis, in kinds (position P, velocity P, position I): the Jacobian's replays change every
fitted axis's gain of one kind at once."""
NOT_FITTED = (
    "posCtlPid.xKi",
    "posCtlPid.yKi",
    "posCtlPid.xKd",
    "posCtlPid.yKd",
    "posCtlPid.zKd",
    "velCtlPid.vxKi",
    "velCtlPid.vyKi",
    "velCtlPid.vzKi",
    "velCtlPid.vxKd",
    "velCtlPid.vyKd",
    "velCtlPid.vzKd",
)
"""Kept at the firmware's values, or the start's (module doc: why they are not fitted)."""
MIN_TRAVEL_M = 0.1
"""An axis whose setpoint spans less than this in the window is not fitted."""
MIN_DELAY_S = -0.05
MAX_DELAY_S = 0.1
"""The delay's range: from a model 50 ms slower than the drone to one 100 ms ahead of the poses."""
DELAY_STEP_S = 0.001
MAX_TRUTH_LAG_S = 0.2
STILL_M_S = 0.05
"""The mocap's noise is measured against the truth where the drone moves slower than this (at least 100 poses)."""
"""The longest mocap latency measured against a dry run's truth (a profile's is at most 2 s, a dry run's own 10 ms)."""
FD_STEP = 0.05
"""The forward difference's step in log gain (5 %)."""
MAX_STEP = 0.5
"""The largest change of a log gain in one iteration (a factor of 1.65)."""
MAX_ITERATIONS = 12
MIN_GAIN = 0.002
"""A step that lowers the squared error by less than this share ends the fit: the bottom of the valley, where the
gains move by well under 1 % (the replay's own resolution: the 1 ms tick, the setpoints' stamps)."""
UNEXPLAINED_M = 0.005
"""A residual over this (or 5 mocap noise widths) is reported: the fit explains the flight badly (a dry run's flight
with the changed gains of tests/calibrate leaves 2-3 mm at 1 mm of noise)."""
TOLERANCE = 3e-3


@dataclass
class FitResult:
    """What `fit` found for one record."""

    params: dict[str, float]
    """The fitted gains by firmware name, over the start's (``fit(start=...)``)."""
    not_identified: dict[str, str]
    """Gains of axes that did not move, and why (they stay the firmware's)."""
    delay_s: float
    residual_rms_m: float
    """RMS over the window's samples of the 3-D distance between measured and replayed positions."""
    residual_max_m: float
    residual_axis_rms_m: dict[str, float]
    default_residual_rms_m: float
    """The same with the firmware's default gains: what the fit gained."""
    latency_s: float
    latency_from: str
    """``truth`` (measured against a dry run's truth), ``fit`` (the fitted delay: radio and mocap together) or
    ``none`` (a trace: true positions)."""
    noise_m: float
    iterations: int
    replays: int
    samples: int
    history: list[dict[str, float]] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    """Why the fit may not describe the drone: the record's own warnings, a residual the model does not explain."""


def _best_delay(
    track: Track, t: np.ndarray, measured: np.ndarray, axes: list[int], fixed: float | None
) -> tuple[float, np.ndarray]:
    """The delay (from `MIN_DELAY_S` to `MAX_DELAY_S` by 5 ms, then by 1 ms about the best; or ``fixed``) that best
    lays the replay on ``measured`` along ``axes``, and the model's positions with it."""
    if fixed is not None:
        return fixed, track.at(t - fixed)
    best = (math.inf, 0.0)
    for d in np.arange(MIN_DELAY_S, MAX_DELAY_S + 1e-9, DELAY_STEP_S * 5):
        cost = float(np.sum((measured[:, axes] - track.at(t - d)[:, axes]) ** 2))
        best = min(best, (cost, float(d)))
    lo, hi = max(MIN_DELAY_S, best[1] - 5 * DELAY_STEP_S), min(MAX_DELAY_S, best[1] + 5 * DELAY_STEP_S)
    for d in np.arange(lo, hi + 1e-9, DELAY_STEP_S):
        cost = float(np.sum((measured[:, axes] - track.at(t - d)[:, axes]) ** 2))
        best = min(best, (cost, float(d)))
    return best[1], track.at(t - best[1])


def mocap_against_truth(record: FlightRecord) -> tuple[float, float] | None:
    """(latency, noise) of the logged poses against the dry run's truth over the window: the shift (0 to
    `MAX_TRUTH_LAG_S`, by 0.5 ms) that minimises their distance, and their per-axis scatter about the truth so
    shifted where the drone is nearly still (`STILL_M_S`); None without truth."""
    truth = record.truth
    if truth is None or len(truth) < 10:
        return None
    t, pos = record.positions[:, 0], record.positions[:, 1:]
    inside = (t > truth[0, 0] + 0.05) & (t < truth[-1, 0])
    if inside.sum() < 10:
        return None
    t, pos = t[inside], pos[inside]
    best = (math.inf, 0.0)
    for lag in np.arange(0.0, MAX_TRUTH_LAG_S + 1e-9, 0.0005):
        shifted = np.column_stack([np.interp(t - lag, truth[:, 0], truth[:, i]) for i in (1, 2, 3)])
        best = min(best, (float(np.mean((pos - shifted) ** 2)), float(lag)))
    lag = best[1]
    # the noise where the drone is nearly still: there a frame a few ms later than the others is no error
    speed = np.linalg.norm(np.gradient(truth[:, 1:], truth[:, 0], axis=0), axis=1)
    still = np.interp(t - lag, truth[:, 0], speed) < STILL_M_S
    if still.sum() >= 100:
        t, pos = t[still], pos[still]
    shifted = np.column_stack([np.interp(t - lag, truth[:, 0], truth[:, i]) for i in (1, 2, 3)])
    return lag, math.sqrt(float(np.mean((pos - shifted) ** 2)))


def noise_from_frames(frames: np.ndarray) -> float:
    """Per-axis white-noise std of consecutive mocap positions: the robust spread (1.4826 MAD) of their second
    differences over sqrt(6)."""
    if len(frames) < 5:
        return 0.0
    second = np.diff(frames[:, 1:], n=2, axis=0).ravel()
    mad = float(np.median(np.abs(second - np.median(second))))
    return 1.4826 * mad / math.sqrt(6.0)


def fit(
    record: FlightRecord,
    *,
    start: dict[str, float] | None = None,
    progress: Callable[[str], None] = lambda message: None,
) -> FitResult:
    """Fit ``record`` (module doc). ``start``: firmware parameters to start from (an earlier profile's; default
    the firmware's): the fitted gains start at theirs, and the others are replayed as they say and kept."""
    sp = record.setpoints
    first = record.start_position  # the drone hovered there before: a step from it is travel too
    travel = {
        a: float(max(np.max(sp[:, 1 + i]), first[i]) - min(np.min(sp[:, 1 + i]), first[i])) for i, a in enumerate(AXES)
    }
    fitted_axes = [a for a in AXES if travel[a] >= MIN_TRAVEL_M]
    not_identified = {}
    for a in AXES:
        if a not in fitted_axes:
            why = f"its setpoint moved {travel[a]:.3f} m along {a} (at least {MIN_TRAVEL_M:g} m needed)"
            not_identified.update({name: why for name in GAINS[a]})
    defaults = CfGains().params()
    base = dict(start or {})
    chosen = [
        (a, k, name) for a in fitted_axes for k, name in enumerate(GAINS[a]) if base.get(name, defaults[name]) > 0.0
    ]  # a gain of 0 is switched off: the fit leaves it off
    for a in fitted_axes:
        for name in GAINS[a]:
            if base.get(name, defaults[name]) <= 0.0:
                not_identified[name] = "0 in the start: switched off, kept"
    names = [name for _, _, name in chosen]
    axis_of = [AXES.index(a) for a, _, _ in chosen]
    kind_of = [k for _, k, _ in chosen]
    theta = np.log([base.get(name, defaults[name]) for name in names]) if names else np.zeros(0)
    t = record.positions[:, 0]
    measured = record.positions[:, 1:]
    every_axis = [0, 1, 2]
    fixed_delay = 0.0 if record.kind == "trace" else None
    replays = 0

    def params_of(th: np.ndarray) -> dict[str, float]:
        return {name: float(math.exp(v)) for name, v in zip(names, th)}

    against_truth = mocap_against_truth(record) if record.kind == "log" else None
    late = 0.0 if against_truth is None else against_truth[0]

    def run(th: np.ndarray | None) -> Track:
        nonlocal replays
        replays += 1
        return replay(record, {} if th is None else {**base, **params_of(th)}, late)

    def velocity(track: Track, d: float) -> np.ndarray:
        return (track.at(t - d + 0.0005) - track.at(t - d - 0.0005)) / 0.001

    default_track = run(None)
    delay0, model0 = _best_delay(default_track, t, measured, every_axis, fixed_delay)
    if record.kind == "log" and against_truth is None and delay0 > 0.0:  # no truth: the fitted delay bounds it
        late = delay0
        default_track = run(None)
        delay0, model0 = _best_delay(default_track, t, measured, every_axis, fixed_delay)
    default_rms = float(np.sqrt(np.mean(np.sum((measured - model0) ** 2, axis=1))))
    history: list[dict[str, float]] = []
    iterations = 0
    delay, model = delay0, model0
    if names:
        track = default_track if not base else run(theta)
        delay, model = _best_delay(track, t, measured, every_axis, fixed_delay)
        cost = float(np.sum((measured - model) ** 2))
        mu = 1e-3
        gains_jac = np.zeros((len(t), len(names)))  # d(model along the gain's axis)/d(log gain)
        fresh = True
        for iterations in range(1, MAX_ITERATIONS + 1):
            if fresh:  # forward differences (every axis's gain of one kind at once); else Broyden's update
                for kind in sorted(set(kind_of)):
                    columns = [j for j, k in enumerate(kind_of) if k == kind]
                    shifted = theta.copy()
                    shifted[columns] += FD_STEP
                    moved = run(shifted).at(t - delay)
                    for j in columns:
                        gains_jac[:, j] = (moved[:, axis_of[j]] - model[:, axis_of[j]]) / FD_STEP
            speed = velocity(track, delay)
            jac = np.zeros((3 * len(t), len(names) + (fixed_delay is None)))
            for j, i in enumerate(axis_of):
                jac[i * len(t) : (i + 1) * len(t), j] = gains_jac[:, j]
            if fixed_delay is None:
                jac[:, -1] = -speed.T.ravel()  # the model seen later by d is the model at t - d
            residual = (measured - model).T.ravel()
            normal = jac.T @ jac
            step = np.linalg.solve(
                normal + mu * np.diag(np.diag(normal)) + 1e-12 * np.eye(len(normal)), jac.T @ residual
            )
            gain_step = np.clip(step[: len(names)], -MAX_STEP, MAX_STEP)
            delay_step = float(np.clip(step[-1], -0.02, 0.02)) if fixed_delay is None else 0.0
            trial = theta + gain_step
            trial_delay = min(max(delay + delay_step, MIN_DELAY_S), MAX_DELAY_S)
            trial_track = run(trial)
            trial_model = trial_track.at(t - trial_delay)
            trial_cost = float(np.sum((measured - trial_model) ** 2))
            # Broyden: what the gains did (the delay's share taken out), column by column of each axis
            change = trial_model - model + speed * (trial_delay - delay)
            for a in fitted_axes:
                cols = [j for j in range(len(names)) if names[j] in GAINS[a]]
                i, g = AXES.index(a), gain_step[cols]
                block = gains_jac[:, cols]
                gains_jac[:, cols] = block + np.outer(change[:, i] - block @ g, g) / max(float(g @ g), 1e-18)
            if trial_cost < cost:
                gained = (cost - trial_cost) / cost
                theta, delay, track, model, cost = trial, trial_delay, trial_track, trial_model, trial_cost
                mu = max(mu / 3.0, 1e-6)
                fresh = False
                done = (float(np.max(np.abs(gain_step))) < TOLERANCE and abs(delay_step) < 5e-4) or gained < MIN_GAIN
            else:
                mu *= 4.0
                fresh = True
                done = mu > 1e4 or (float(np.max(np.abs(gain_step))) < TOLERANCE and abs(delay_step) < 5e-4)
            rms = float(np.sqrt(cost / len(t)))
            history.append({"iteration": iterations, "residual_rms_m": rms, "delay_s": delay, **params_of(theta)})
            progress(
                f"iteration {iterations}: residual {rms * 1000:.2f} mm, delay {delay * 1000:.1f} ms, "
                + ", ".join(f"{k} {v:.3f}" for k, v in params_of(theta).items())
            )
            if done:
                break
    residual = measured - model
    distance = np.sqrt(np.sum(residual**2, axis=1))
    if record.kind == "trace":
        latency, latency_from, noise = 0.0, "none", 0.0
    elif against_truth is not None:
        latency, noise = against_truth
        latency_from = "truth"
    else:
        latency, latency_from = delay, "fit"
        frames = record.mocap_frames if record.mocap_frames is not None else record.positions
        noise = noise_from_frames(frames[(frames[:, 0] >= 0.0) & (frames[:, 0] <= record.end_s)])
    warnings = list(record.warnings)
    rms = float(np.sqrt(np.mean(distance**2)))
    if rms > max(UNEXPLAINED_M, 5.0 * noise):
        warnings.append(
            f"the fitted model leaves {rms * 1000:.1f} mm RMS unexplained ({noise * 1000:.2f} mm of mocap "
            "noise): the flight holds what the model does not (a stall, a gust, a crash, the floor, "
            "another drone's wash), or gains it does not fit"
        )
    return FitResult(
        warnings=warnings,
        params={**base, **(params_of(theta) if names else {})},
        not_identified=not_identified,
        delay_s=delay,
        residual_rms_m=float(np.sqrt(np.mean(distance**2))),
        residual_max_m=float(np.max(distance)),
        residual_axis_rms_m={a: float(np.sqrt(np.mean(residual[:, i] ** 2))) for i, a in enumerate(AXES)},
        default_residual_rms_m=default_rms,
        latency_s=latency,
        latency_from=latency_from,
        noise_m=noise,
        iterations=iterations,
        replays=replays,
        samples=len(t),
        history=history,
    )
