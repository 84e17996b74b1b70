"""``rpf-fly lab``: a mission's simulated Crazyflies and Motive emulator, running until stopped (Ctrl-C, SIGTERM),
for ``rpf-fly check|fly MISSION --lab`` and cflib programs to fly one command after another, as real drones outlive
their ground station (rpf_fly/flight/lab.py, docs/flight.md "Lab")."""

from __future__ import annotations

import signal
from datetime import datetime
from pathlib import Path
from typing import Optional

import typer

from rpf_fly.cli import app
from rpf_fly.cli.errors import fail


@app.command()
def lab(
    mission: Path = typer.Argument(..., help="Mission YAML file: its drones, starts, obstacles and mocap."),
    faults: Optional[Path] = typer.Option(None, "--faults", help="Power-on faults of the drones (yaw_offset, "
                                          "start_offset, upside_down, motor_fault; docs/faults.md)."),
    log: Optional[Path] = typer.Option(None, "--log", help="The lab's MCAP log (default "
                                       "flights/lab-<mission>-<time>.mcap)."),
) -> None:
    """Run MISSION's simulated drones and mocap until stopped; `check --lab` and `fly --lab` fly them."""
    from rpf_fly.cli.fly_cmd import load_mission_or_fail, load_faults_or_fail
    from rpf_fly.flight.fault_injection import FaultInjection
    from rpf_fly.flight.lab import Lab, crazyradio_plug_call

    loaded = load_mission_or_fail(mission)
    start_faults = None
    if faults is not None:
        schedule = load_faults_or_fail(faults, loaded)
        timed = next((f for f in schedule if f.at_s is not None or f.drone is None), None)
        if timed is not None:
            raise fail(f"{faults}:{timed.line}: {timed.kind}: a lab takes the power-on faults only; give timed "
                       "faults to `rpf-fly fly MISSION --lab --faults FILE`")
        start_faults = FaultInjection(loaded, schedule).start_faults()
    log_path = log or Path("flights") / f"lab-{loaded.name}-{datetime.now():%Y%m%d-%H%M%S}.mcap"
    try:
        log_path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise fail(f"--log {log_path}: cannot make its folder: {err.strerror or err}")
    from rpf_fly.emulator.host_lag import ahead_of_the_ground_station

    ahead_of_the_ground_station()  # the lab's process is the drones' and Motive's, not a ground station's
    the_lab = Lab(loaded, mission, log_path, start_faults=start_faults)
    stop = {"signal": ""}

    def on_signal(signum: int, frame: object) -> None:
        stop["signal"] = signal.Signals(signum).name
        the_lab.close()

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        try:
            info = the_lab.start()
        except (RuntimeError, OSError) as err:
            raise fail(f"lab: {err}")
        typer.echo(f"lab: {len(info.addresses)} simulated Crazyflies of '{loaded.name}' on the floor at their "
                   f"mission starts, Motive emulated on 127.0.0.1:{info.natnet_command_port}")
        typer.echo(f"  fly them:   rpf-fly check {mission} --lab   then   rpf-fly fly {mission} --lab")
        typer.echo("  from cflib: from rpf_fly.emulator import fake_radio; from rpf_fly.flight.lab import lab_world; "
                   "fake_radio.register(lab_world()); then fake:// URIs (the mission's radio paths)")
        typer.echo("  or through cflib's radio driver: from rpf_fly.emulator import crazyradio; from rpf_fly.flight.lab "
                   f"import lab_world; {crazyradio_plug_call(loaded)}; then the mission's radio:// URIs")
        typer.echo(f"  lab file:   {the_lab.path}   log: {log_path}")
        typer.echo("  Ctrl-C stops the lab (its drones power off)")
        while not the_lab.wait(1.0):
            pass
    finally:
        the_lab.close()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    lag = the_lab.host_lag() if the_lab.server is not None else None
    typer.echo(f"lab stopped ({stop['signal'] or 'closed'}); log: {log_path}  (rpf-fly review {log_path})")
    if lag is not None and lag.sentence():
        typer.echo(lag.sentence())
