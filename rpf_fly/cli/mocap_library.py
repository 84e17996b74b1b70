"""``rpf-fly mocap watch --system TYPE``: rigid bodies from a system of the ``motioncapture`` package.

Apart from ``mocap_cmd.py`` so that the NatNet path of ``watch`` stays as it is: this one builds a
:class:`~rpf_fly.mocap.motioncapture_source.MotioncaptureSource` (the library in a child process) from the command
line and prints its frames with the same line and JSON formats. ``--local-ip`` sets the OptiTrack type's
``interface_ip`` and ``--command-port`` its ``port_command`` unless ``--option`` gives them; on a loopback host
``interface_ip`` defaults to 127.0.0.1, so ``--system optitrack --host 127.0.0.1`` reads ``rpf-fly mocap emulate``.
"""

from __future__ import annotations

import time

import typer


def _options(system: str, pairs: list[str], local_ip: str, command_port: int) -> dict[str, str]:
    """``--option KEY=VALUE`` pairs checked against the library's table, plus the NatNet flags that map onto it."""
    from rpf_fly.mocap.motioncapture_options import check_option

    options: dict[str, str] = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise ValueError(f"--option: expected KEY=VALUE, got {pair!r}")
        try:
            options[key] = check_option(system, key, value)
        except ValueError as err:
            raise ValueError(f"--option {key}: {err}") from None
    if system == "optitrack":
        if local_ip not in ("0.0.0.0", "") and "interface_ip" not in options:
            options["interface_ip"] = check_option(system, "interface_ip", local_ip)
        if command_port != 1510 and "port_command" not in options:
            options["port_command"] = str(command_port)
    return options


def watch_library(
    system: str,
    host: str | None,
    pairs: list[str],
    *,
    local_ip: str,
    command_port: int,
    up_axis: str,
    frames: int,
    json_output: bool,
    timeout: float,
    rate: float = 10.0,
    duration: float = 0.0,
) -> None:
    """The ``watch`` loop over a motioncapture system; exits 0 after ``frames`` frames, 1 with one line when the
    system does not answer, the library fails or crashes, or no frame comes for ``timeout`` seconds, 2 for bad
    options."""
    from rich.console import Console

    from rpf_fly.app.mocap_watch import UpAxisCheck, WatchStats
    from rpf_fly.cli.mocap_cmd import frame_json, frame_line, printing
    from rpf_fly.mocap.motioncapture_options import check_hostname, system_type
    from rpf_fly.mocap.motioncapture_source import MotioncaptureSource

    try:
        spec = system_type(system)
        if host is not None:
            check_hostname(system, host)
        options = _options(system, pairs, local_ip, command_port)
    except ValueError as err:
        message = str(err) if str(err).startswith("--option") else f"--system/--host: {err}"
        typer.echo(f"error: {message}", err=True)
        raise typer.Exit(2) from None
    if host is None and spec.hostname is not None and system != "mock":
        host = "127.0.0.1" if spec.hostname == "ip" else None  # optitrack: the library's `localhost` is no literal
    try:
        source = MotioncaptureSource(system, host, options, up_axis=up_axis, connect_timeout_s=timeout)
    except ConnectionError as err:
        typer.echo(f"error: {err}", err=True)
        raise typer.Exit(1) from None
    console = Console(highlight=False, soft_wrap=True)
    if system == "mock" and "rigid_bodies" not in options:
        typer.echo(
            "note: the mock has no rigid bodies unless given, e.g. --option 'rigid_bodies=cf1(0,0,0.5,1,0,0,0)'"
            " (name(x,y,z,qw,qx,qy,qz))",
            err=True,
        )
    stats = WatchStats()
    up_check = UpAxisCheck(up_axis)
    if not json_output:
        console.print(
            f"motioncapture {system} at {host or 'its default host'}, assuming {up_axis.upper()}-up "
            f"(--up-axis {up_axis}), shown Z-up; printing {printing(rate)}"
        )
    started = time.monotonic()
    end = started + duration if duration > 0 else float("inf")
    next_line = 0.0
    with source:
        try:
            count = 0
            last_frame = time.monotonic()
            while (frames == 0 or count < frames) and time.monotonic() < end:
                frame = source.receive(0.2)
                if frame is None:
                    if not source.alive:
                        typer.echo(
                            f"error: motioncapture {system}: the library's process ended ({source.failure})", err=True
                        )
                        raise typer.Exit(1)
                    if time.monotonic() - last_frame > timeout:
                        typer.echo(
                            f"error: motioncapture {system}: connected but no frames arrived within {timeout:g} s",
                            err=True,
                        )
                        raise typer.Exit(1)
                    continue
                last_frame = time.monotonic()
                count += 1
                stats.add(frame)
                hint = up_check.add(frame)
                if hint is not None:
                    typer.echo(hint, err=json_output)
                if json_output:
                    typer.echo(frame_json(frame))
                elif rate <= 0 or last_frame >= next_line:
                    next_line = last_frame + (1.0 / rate if rate > 0 else 0.0)
                    console.print(frame_line(frame))
        except KeyboardInterrupt:
            pass
    hint = up_check.finish() or up_check.hint  # a watch shorter than the check judges what it saw
    for line in stats.summary(time.monotonic() - started) + ([hint] if hint else []):
        typer.echo(line, err=json_output)
