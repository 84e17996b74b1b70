"""``rpf-fly calibrate LOG``: fit each drone's closed-loop response in a flight log (or a trace JSON) and write a
vehicle profile a dry run flies (rpf_fly/calibrate, docs/dynamics.md "Calibrating a vehicle profile")."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import typer

from rpf_fly.cli import app
from rpf_fly.cli.errors import fail


def _summary(record: Any, result: Any, defaults: dict[str, float]) -> list[str]:
    """The fit in words: where it came from, how well it explains the flight, each gain against the firmware's."""
    lines = [
        f"{record.drone} ({record.kind} {record.path}, {record.origin}, {record.end_s:.1f} s, "
        f"{result.samples} positions): residual {result.residual_rms_m * 1000:.2f} mm RMS, "
        f"{result.residual_max_m * 1000:.1f} mm max ({result.default_residual_rms_m * 1000:.2f} mm RMS with the "
        f"firmware's defaults); delay {result.delay_s * 1000:.1f} ms; {result.iterations} iterations, "
        f"{result.replays} replays"
    ]
    for name, value in result.params.items():
        lines.append(
            f"  {name} {value:.4g} (firmware default {defaults[name]:g}, x{value / defaults[name]:.3f})"
            if defaults.get(name)
            else f"  {name} {value:.4g}"
        )
    for name, why in result.not_identified.items():
        lines.append(f"  {name}: not identified, kept ({why})")
    how = {
        "truth": "against the dry run's truth",
        "fit": "the fitted delay: the radio's latency included",
        "none": "a trace: true positions",
    }[result.latency_from]
    lines.append(f"  mocap: latency {result.latency_s * 1000:.1f} ms ({how}), noise {result.noise_m * 1000:.2f} mm")
    return lines


def _profile(record: Any, result: Any) -> str:
    """The profile file's text: what a dry run uses (params, mocap) and what says where it came from (source, fit)."""
    from rpf_fly.calibrate.fit import NOT_FITTED
    from rpf_fly.calibrate.profile import profile_text

    source = {
        "file": str(record.path),
        "kind": record.kind,
        "origin": record.origin,
        "window_s": record.end_s,
        "samples": result.samples,
    }
    mocap = {"latency_s": max(0.0, result.latency_s), "latency_from": result.latency_from, "noise_m": result.noise_m}
    fit = {
        "residual_rms_m": result.residual_rms_m,
        "residual_max_m": result.residual_max_m,
        "residual_axis_rms_m": result.residual_axis_rms_m,
        "default_residual_rms_m": result.default_residual_rms_m,
        "delay_s": result.delay_s,
        "iterations": result.iterations,
        "not_identified": result.not_identified,
        "warnings": result.warnings,
        "not_fitted": "kept as the firmware's (or --start's): " + ", ".join(NOT_FITTED),
    }
    return profile_text(record.drone, result.params, source=source, mocap=mocap, fit=fit)


@app.command()
def calibrate(
    log: Path = typer.Argument(..., help="Flight log (MCAP of rpf-fly fly or scenario) or a trace JSON."),
    out: Path | None = typer.Option(
        None, "--out", help="Write the vehicle profile here ({drone} in the path: one per drone)."
    ),
    drone: str | None = typer.Option(
        None, "--drone", help="Only this drone of the log (default: every drone with setpoints)."
    ),
    start: Path | None = typer.Option(
        None,
        "--start",
        help="Start the fit from this profile's gains (default: the firmware's); its other parameters are kept.",
    ),
    json_out: bool = typer.Option(False, "--json", help="Print the fits as one JSON document."),
    verbose: bool = typer.Option(False, "--verbose", help="Print each iteration on stderr."),
) -> None:
    """Fit each drone's closed-loop response (position and velocity gains, mocap latency and noise) by replaying
    the firmware model on its setpoints, and write a vehicle profile for dry_run.vehicle."""
    from rpf_fly.calibrate.fit import fit
    from rpf_fly.calibrate.profile import ProfileError, load_profile
    from rpf_fly.calibrate.record import RecordError, read_records
    from rpf_fly.emulator.cf_controller import CfGains

    begin: dict[str, float] = {}
    if start is not None:
        try:
            begin = dict(load_profile(start).params)
        except ProfileError as err:
            raise fail(f"--start {err}") from err
    try:
        records = read_records(log, drone)
    except RecordError as err:
        raise fail(str(err)) from err
    if out is not None and len(records) > 1 and "{drone}" not in str(out):
        raise fail(
            f"--out {out}: {log} has {len(records)} drones with setpoints ({', '.join(r.drone for r in records)}"
            "): give --drone NAME, or put {drone} in the path for one profile each"
        )
    defaults = CfGains().params()
    fits = []
    for record in records:

        def say(message: str, name: str = record.drone) -> None:
            if verbose:
                typer.echo(f"{name}: {message}", err=True)

        fits.append((record, fit(record, start=begin or None, progress=say)))
    written = []
    if out is not None:
        for record, result in fits:
            path = Path(str(out).replace("{drone}", record.drone))
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(_profile(record, result), encoding="utf-8")
            written.append(str(path))
    for record, result in fits:  # on stderr, whatever the output
        for warning in result.warnings:
            typer.echo(f"{log}: {record.drone}: warning: {warning}", err=True)
    if json_out:
        typer.echo(
            json.dumps(
                {
                    "log": str(log),
                    "profiles": written,
                    "drones": {
                        record.drone: {
                            "kind": record.kind,
                            "origin": record.origin,
                            "window_s": record.end_s,
                            "params": result.params,
                            "not_identified": result.not_identified,
                            "delay_s": result.delay_s,
                            "residual_rms_m": result.residual_rms_m,
                            "residual_max_m": result.residual_max_m,
                            "residual_axis_rms_m": result.residual_axis_rms_m,
                            "default_residual_rms_m": result.default_residual_rms_m,
                            "latency_s": result.latency_s,
                            "latency_from": result.latency_from,
                            "noise_m": result.noise_m,
                            "iterations": result.iterations,
                            "replays": result.replays,
                            "warnings": result.warnings,
                        }
                        for record, result in fits
                    },
                }
            )
        )
        return
    for record, result in fits:
        for line in _summary(record, result, defaults):
            typer.echo(line)
    typer.echo(f"profile: {', '.join(written)}" if written else "no --out: no profile written")
