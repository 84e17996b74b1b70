"""``rpf-fly mocap``: watch a NatNet stream (or a system of the ``motioncapture`` package: ``--system``), or emulate
Motive so ``watch`` can be tried without one.

``watch`` shows every rigid body as frames arrive, in the Z-up world frame: on a terminal one table redrawn in
place, piped a header and at most ``--rate`` lines a second, with ``--json`` one JSON object per frame per line;
then a summary (frames, the seconds from the first to the last and the rate over them, the watch's duration, frames
missed, each body's valid %) on exit, Ctrl-C or ``--duration`` (on stderr with ``--json``). It exits 0 after
``--frames`` frames, ``--duration`` seconds or Ctrl-C, and 1 with a one-line error when no server answers (or no
frames arrive) within ``--timeout`` seconds. ``emulate`` runs :class:`NatNetServer` with bodies ``cf1..cfN`` flying
circles.
"""

from __future__ import annotations

import json
import math
import time
from enum import Enum
from pathlib import Path

import typer

from rpf_fly.app.mocap_watch import UpAxisCheck, WatchStats
from rpf_fly.cli import app

mocap_app = typer.Typer(
    help="Motion capture: watch a NatNet (OptiTrack Motive) stream or, with watch --system, any system of the "
    "motioncapture package (Vicon, Qualisys, VRPN, ...); or emulate a Motive server.",
    no_args_is_help=True,
)
app.add_typer(mocap_app, name="mocap")


class UpAxis(str, Enum):
    """The up axis Motive streams (Motive: Streaming > Up Axis; its default is Y)."""

    y = "y"
    z = "z"


def _finite(value: float) -> float | None:
    """JSON has no NaN/inf: report them as null."""
    return value if math.isfinite(value) else None


def frame_json(frame) -> str:  # noqa: ANN001 - MocapFrame, imported lazily
    bodies = {
        name: {
            "position": [_finite(v) for v in pose.position],
            "quaternion": [_finite(v) for v in pose.quaternion],
            "valid": pose.valid,
        }
        for name, pose in sorted(frame.bodies.items())
    }
    return json.dumps({"frame": frame.frame_number, "timestamp": _finite(frame.capture_time_s), "bodies": bodies})


def frame_line(frame) -> str:  # noqa: ANN001 - MocapFrame, imported lazily
    latency = f"{frame.latency_s * 1000:.1f} ms" if frame.latency_s is not None else "n/a"
    parts = [f"frame {frame.frame_number:>8}  t={frame.capture_time_s:10.3f} s  latency {latency}"]
    for name, pose in sorted(frame.bodies.items()):
        x, y, z = pose.position
        state = "[green]ok[/]" if pose.valid else "[red]LOST[/]"
        parts.append(f"{name} ({x:+.3f}, {y:+.3f}, {z:+.3f}) {state}")
    if len(parts) == 1:
        parts.append("no rigid bodies")
    return "  |  ".join(parts)


def printing(rate: float) -> str:
    """What a piped watch prints at ``--rate``: ``at most 1 line a second (--rate)``, ``... 10 lines ...``."""
    if rate <= 0:
        return "every frame"
    return f"at most {rate:g} line{'' if rate == 1 else 's'} a second (--rate)"


def _watch_table(frame, stats: WatchStats):  # noqa: ANN001, ANN202 - MocapFrame, rich Table
    from rich.console import JustifyMethod
    from rich.table import Table

    rate = stats.rate_hz
    latency = f"{frame.latency_s * 1000:.1f} ms" if frame.latency_s is not None else "n/a"
    table = Table(
        caption=f"frame {frame.frame_number}, {stats.frames} frames, "
        f"{'-' if rate is None else f'{rate:.1f}'} Hz, latency {latency}, "
        f"{stats.missed} missed  (Ctrl-C: stop)"
    )
    columns: tuple[tuple[str, JustifyMethod], ...] = (
        ("body", "left"),
        ("x", "right"),
        ("y", "right"),
        ("z", "right"),
        ("tracked", "left"),
        ("valid %", "right"),
    )
    for column, justify in columns:
        table.add_column(column, justify=justify)
    for name, pose in sorted(frame.bodies.items()):
        x, y, z = pose.position
        table.add_row(
            name,
            f"{x:+.3f}",
            f"{y:+.3f}",
            f"{z:+.3f}",
            "[green]ok[/]" if pose.valid else "[red]LOST[/]",
            f"{stats.valid_pct(name):.1f}",
        )
    return table


@mocap_app.command("watch")
def watch(
    natnet: str = typer.Option("127.0.0.1", "--natnet", help="Motive (NatNet server) host name or IPv4 address."),
    multicast: bool = typer.Option(True, "--multicast/--unicast", help="Receive frames by multicast or unicast."),
    local_ip: str = typer.Option(
        "0.0.0.0", "--local-ip", help="Local interface facing Motive (choose it on hosts with several network cards)."
    ),
    command_port: int = typer.Option(1510, "--command-port", help="Server command port."),
    data_port: int | None = typer.Option(
        None, "--data-port", help="Multicast data port (default: as announced by the server, normally 1511)."
    ),
    up_axis: UpAxis = typer.Option(UpAxis.z, "--up-axis", help="Up axis Motive streams; output is always Z-up."),
    frames: int = typer.Option(0, "--frames", min=0, help="Exit after this many frames (0: until Ctrl-C)."),
    duration: float = typer.Option(0.0, "--duration", min=0.0, help="Exit after this many seconds (0: until Ctrl-C)."),
    rate: float = typer.Option(
        10.0,
        "--rate",
        min=0.0,
        help="Lines a second when piped, table redraws a second on a terminal (0: a line for "
        "every frame). --json prints every frame.",
    ),
    json_output: bool = typer.Option(False, "--json", help="One JSON object per line per frame (summary on stderr)."),
    timeout: float = typer.Option(5.0, "--timeout", min=0.1, help="Seconds to wait for the server and for frames."),
    system: str = typer.Option(
        "natnet",
        "--system",
        help="natnet (our NatNet client, the default for OptiTrack) or a type of the "
        "motioncapture package: optitrack, vicon, qualisys, vrpn, mock, ... (docs/mocap.md).",
    ),
    host: str | None = typer.Option(None, "--host", help="The system's host (--system natnet: the same as --natnet)."),
    option: list[str] = typer.Option(
        [],
        "--option",
        help="KEY=VALUE: an option of the motioncapture type (repeat for several), e.g. "
        "--option 'rigid_bodies=cf1(0,0,0,1,0,0,0)' for mock.",
    ),
) -> None:
    """Show rigid bodies as they arrive from a NatNet server, or from a system of the motioncapture package
    (Z-up world frame, metres).

    NatNet: on a terminal one table is redrawn in place; piped, a header, at most --rate lines a second; then the
    summary (frames, their span and rate, the watch's duration, frames missed, each body's valid %) on exit, Ctrl-C
    or --duration. A motioncapture
    system: a header, at most --rate lines a second, the same summary."""
    if system != "natnet":
        from rpf_fly.cli.mocap_library import watch_library

        return watch_library(
            system,
            host,
            option,
            local_ip=local_ip,
            command_port=command_port,
            up_axis=up_axis.value,
            frames=frames,
            json_output=json_output,
            timeout=timeout,
            rate=rate,
            duration=duration,
        )
    if host is not None:
        natnet = host
    if option:
        typer.echo("error: --option is for the motioncapture systems (--system TYPE), not natnet", err=True)
        raise typer.Exit(2)
    from rpf_fly.cli.output import console as make_console
    from rpf_fly.mocap.natnet_client import NatNetClient

    console = make_console(highlight=False)
    try:
        client = NatNetClient(
            natnet,
            multicast=multicast,
            local_ip=local_ip,
            command_port=command_port,
            data_port=data_port,
            up_axis=up_axis.value,
        )
    except (OSError, ValueError) as exc:
        typer.echo(f"error: cannot listen for NatNet from {natnet}: {exc}", err=True)
        raise typer.Exit(1) from None
    stats = WatchStats()
    up_check = UpAxisCheck(up_axis.value)
    started = time.monotonic()
    live = None
    with client:
        try:
            if not client.wait_for_server(timeout, with_models=False):
                info = client.server_info
                if info is not None:
                    typer.echo(
                        f"error: {info.app_name} at {natnet} streams NatNet {info.version[0]}.{info.version[1]},"
                        " which is not supported (3.x, 4.x)",
                        err=True,
                    )
                else:
                    typer.echo(
                        f"error: no NatNet server answered at {natnet}:{command_port} within {timeout:g} s",
                        err=True,
                    )
                raise typer.Exit(1)
            client.wait_for_server(min(timeout, 1.0), with_models=True)  # names for the first lines
            title = _watch_header(client, natnet, multicast, up_axis.value)
            if json_output:
                pass
            elif console.is_terminal:
                from rich.live import Live

                console.print(title)
                live = Live(console=console, auto_refresh=False, transient=False)
                live.__enter__()
            else:
                console.print(f"{title}; printing {printing(rate)}")
            started = time.monotonic()
            end = started + duration if duration > 0 else math.inf
            last_frame = time.monotonic()
            next_line = 0.0
            while (frames == 0 or stats.frames < frames) and time.monotonic() < end:
                frame = client.receive(min(0.2, max(0.0, end - time.monotonic())))
                if frame is None:
                    if time.monotonic() - last_frame > timeout:
                        mode = f"multicast (local ip {local_ip})" if multicast else "unicast"
                        typer.echo(
                            f"error: server at {natnet} answered but no frames arrived within {timeout:g} s "
                            f"({mode}; check Motive's streaming transport, interface and firewall)",
                            err=True,
                        )
                        raise typer.Exit(1)
                    continue
                last_frame = time.monotonic()
                stats.add(frame)
                hint = up_check.add(frame)
                if hint is not None:
                    if json_output or live is None:
                        typer.echo(hint, err=json_output)
                    else:
                        console.print(hint, markup=False)
                if json_output:
                    typer.echo(frame_json(frame))
                elif live is not None:
                    if last_frame >= next_line:  # one redraw per 1/rate s (at most 30 a second)
                        next_line = last_frame + 1.0 / min(rate or 30.0, 30.0)
                        live.update(_watch_table(frame, stats), refresh=True)
                elif rate <= 0 or last_frame >= next_line:
                    next_line = last_frame + (1.0 / rate if rate > 0 else 0.0)
                    console.print(frame_line(frame))
        except KeyboardInterrupt:
            pass
        finally:
            if live is not None:
                live.__exit__(None, None, None)
        lines = stats.summary(time.monotonic() - started, client.stats)
    hint = up_check.finish() or up_check.hint  # a watch shorter than the check judges what it saw
    for line in lines + ([hint] if hint else []):
        typer.echo(line, err=json_output)


def _watch_header(client, natnet: str, multicast: bool, up_axis: str) -> str:  # noqa: ANN001 - NatNetClient
    info = client.server_info
    server = (
        f"{info.app_name} {'.'.join(map(str, info.app_version[:3]))}, NatNet {info.version[0]}.{info.version[1]}"
        if info is not None
        else "NatNet"
    )
    names = sorted(client.rigid_body_names.values())
    bodies = f", {len(names)} rigid bodies ({', '.join(names)})" if names else ""
    transport = "multicast" if multicast else "unicast"
    return (
        f"{server} at {natnet}, {transport}, assuming {up_axis.upper()}-up (--up-axis {up_axis}; NatNet does not "
        f"say which Motive streams), shown Z-up{bodies}"
    )


def _circle_poses(n_bodies: int, radius: float, speed: float, t0: float):  # noqa: ANN202
    """Bodies cf1..cfN on concentric horizontal circles, facing along their motion (Z-up, metres)."""
    names = [f"cf{i + 1}" for i in range(n_bodies)]

    def poses() -> dict[str, tuple[tuple[float, float, float], tuple[float, float, float, float], bool]]:
        t = time.monotonic() - t0
        out = {}
        for i, name in enumerate(names):
            r = radius * (1.0 + 0.25 * i)
            angle = speed / r * t + 2.0 * math.pi * i / max(1, n_bodies)
            yaw = angle + 0.5 * math.pi
            position = (r * math.cos(angle), r * math.sin(angle), 0.5 + 0.1 * i)
            out[name] = (position, (0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw)), True)
        return out

    return poses


@mocap_app.command("emulate")
def emulate(
    version: str = typer.Option("4.1", "--version", help="NatNet bitstream: 3.0, 4.0, 4.1 or 4.2."),
    multicast: bool = typer.Option(True, "--multicast/--unicast", help="Stream frames by multicast or unicast."),
    bodies: int = typer.Option(3, "--bodies", min=0, max=200, help="Number of rigid bodies (cf1..cfN)."),
    rate: float = typer.Option(120.0, "--rate", min=1.0, max=1000.0, help="Frames per second."),
    local_ip: str = typer.Option("127.0.0.1", "--local-ip", help="Interface to serve and multicast on."),
    command_port: int = typer.Option(1510, "--command-port", help="Command port (0: any free port)."),
    data_port: int = typer.Option(1511, "--data-port", help="Data port (0: any free port)."),
    up_axis: UpAxis = typer.Option(UpAxis.z, "--up-axis", help="Up axis to stream (Motive's default is y)."),
    radius: float = typer.Option(1.0, "--radius", min=0.1, help="Radius of the innermost circle, metres."),
    speed: float = typer.Option(0.5, "--speed", min=0.0, help="Speed along the circles, m/s."),
    duration: float = typer.Option(0.0, "--duration", min=0.0, help="Stop after this many seconds (0: Ctrl-C)."),
    replay: Path | None = typer.Option(
        None,
        "--replay",
        help="Serve a flight log's /mocap poses at their logged times instead of circles "
        "(--bodies, --rate, --radius and --speed do not apply).",
    ),
    replay_speed: float = typer.Option(
        1.0, "--replay-speed", min=0.01, help="With --replay: playback speed (2: twice as fast)."
    ),
) -> None:
    """Run a NatNet server emulator streaming bodies on circles (or a flight log's mocap with --replay), so `mocap
    watch` and any NatNet client can be tried without Motive."""
    from rpf_fly.emulator.natnet_server import NatNetServer
    from rpf_fly.mocap.natnet_protocol import SUPPORTED_VERSIONS, parse_version

    try:
        parsed = parse_version(version)
    except ValueError:
        parsed = (-1, -1)
    if parsed not in SUPPORTED_VERSIONS:
        raise typer.BadParameter(f"{version} is not one of 3.0, 4.0, 4.1, 4.2", param_hint="--version")
    if replay is not None:
        _emulate_replay(replay, replay_speed, parsed, multicast, local_ip, command_port, data_port, up_axis, duration)
        return
    try:
        server = NatNetServer(
            _circle_poses(bodies, radius, speed, time.monotonic()),
            version=parsed,
            multicast=multicast,
            local_ip=local_ip,
            command_port=command_port,
            data_port=data_port,
            rate_hz=rate,
            up_axis=up_axis.value,
            bodies=[f"cf{i + 1}" for i in range(bodies)],
        )
    except OSError as exc:
        typer.echo(f"error: cannot start the emulator on {local_ip}: {exc}", err=True)
        raise typer.Exit(1) from None
    with server:
        transport = "multicast 239.255.42.99" if multicast else "unicast"
        typer.echo(
            f"NatNet emulator: bitstream {parsed[0]}.{parsed[1]}, {transport}, {up_axis.value}-up, {bodies} bodies at "
            f"{rate:g} Hz on {local_ip} (command port {server.command_port}, data port {server.data_port})"
        )
        flag = "" if multicast else " --unicast"
        typer.echo(
            f"try: rpf-fly mocap watch --natnet {local_ip} --command-port {server.command_port}{flag}"
            f" --up-axis {up_axis.value}   (Ctrl-C to stop)"
        )
        try:
            end = time.monotonic() + duration if duration > 0 else math.inf
            while time.monotonic() < end:
                time.sleep(min(0.2, max(0.0, end - time.monotonic())))
        except KeyboardInterrupt:
            pass


def _emulate_replay(
    log: Path,
    speed: float,
    version: tuple[int, int],
    multicast: bool,
    local_ip: str,  # noqa: PLR0913
    command_port: int,
    data_port: int,
    up_axis: UpAxis,
    duration: float,
) -> None:
    """``emulate --replay LOG``: the log's mocap frames over NatNet at their logged times (relative timing kept);
    exits when the last frame is sent (or after ``duration``, or on Ctrl-C)."""
    import threading

    from rpf_fly.cli.errors import fail
    from rpf_fly.emulator.log_playback import PosePlayback
    from rpf_fly.emulator.natnet_server import NatNetServer
    from rpf_fly.log.mocap_frames import mocap_frames
    from rpf_fly.log.reader import LogError, read_log

    try:
        data = read_log(log)
    except LogError as err:
        raise fail(f"{log}: {err}") from err
    except OSError as err:
        raise fail(f"{log}: {err.strerror or err}") from err
    frames = mocap_frames(data)
    if not frames:
        raise fail(f"{log}: no mocap poses (/mocap/<drone>) to serve")
    if data.truncated:
        typer.echo(
            f"{log}: warning: the log ends before its footer; serving the {len(frames)} frames of its complete chunks",
            err=True,
        )
    playback = PosePlayback([(f.t_ns / 1e9, f.poses) for f in frames], speed)
    bodies = playback.bodies
    try:
        server = NatNetServer(
            playback.poses,
            version=version,
            multicast=multicast,
            local_ip=local_ip,
            command_port=command_port,
            data_port=data_port,
            rate_hz=0,
            up_axis=up_axis.value,
            bodies=bodies,
        )
    except OSError as exc:
        typer.echo(f"error: cannot start the emulator on {local_ip}: {exc}", err=True)
        raise typer.Exit(1) from None
    with server:
        transport = "multicast 239.255.42.99" if multicast else "unicast"
        span = (frames[-1].t_ns - frames[0].t_ns) / 1e9
        typer.echo(
            f"NatNet emulator: replaying {log} ({len(frames)} frames of {', '.join(bodies)} over {span:.1f} s, "
            f"x{speed:g}): bitstream {version[0]}.{version[1]}, {transport}, {up_axis.value}-up on {local_ip} "
            f"(command port {server.command_port}, data port {server.data_port})"
        )
        flag = "" if multicast else " --unicast"
        typer.echo(
            f"try: rpf-fly mocap watch --natnet {local_ip} --command-port {server.command_port}{flag}"
            f" --up-axis {up_axis.value}   (Ctrl-C to stop)",
            nl=True,
        )
        import sys

        sys.stdout.flush()
        stop = threading.Event()
        if duration > 0:
            timer = threading.Timer(duration, stop.set)
            timer.daemon = True
            timer.start()
        try:
            if not multicast:  # unicast frames go to connected clients only: start when the first one connects
                typer.echo("waiting for a client to connect (unicast) ...")
                sys.stdout.flush()
                while not server.clients and not stop.wait(0.05):
                    pass
            sent = playback.play(server, stop)
        except KeyboardInterrupt:
            sent = len(playback.sent)
        typer.echo(
            f"replay done: {sent} of {len(frames)} frames sent (latest {playback.max_late_s * 1e3:.1f} ms "
            "behind its time)"
        )
