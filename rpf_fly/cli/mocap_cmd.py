"""``rpf-fly mocap``: watch a NatNet stream (or a system of the ``motioncapture`` package: ``--system``), or emulate
Motive so ``watch`` can be tried without one.

``watch`` prints every rigid body as frames arrive, in the Z-up world frame (one line per frame, or one JSON
object per line with ``--json``); it exits 0 after ``--frames`` frames and 1 with a one-line error when no server
answers (or no frames arrive) within ``--timeout`` seconds. ``emulate`` runs :class:`NatNetServer` with bodies
``cf1..cfN`` flying circles.
"""

from __future__ import annotations

import json
import math
import time
from enum import Enum
from typing import Optional

import typer

from rpf_fly.cli import app

mocap_app = typer.Typer(
    help="Motion capture: watch a NatNet (OptiTrack Motive) stream, or emulate a Motive server.",
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


def _frame_json(frame) -> str:  # noqa: ANN001 - MocapFrame, imported lazily
    bodies = {
        name: {
            "position": [_finite(v) for v in pose.position],
            "quaternion": [_finite(v) for v in pose.quaternion],
            "valid": pose.valid,
        }
        for name, pose in sorted(frame.bodies.items())
    }
    return json.dumps({"frame": frame.frame_number, "timestamp": _finite(frame.capture_time_s), "bodies": bodies})


def _frame_line(frame) -> str:  # noqa: ANN001 - MocapFrame, imported lazily
    latency = f"{frame.latency_s * 1000:.1f} ms" if frame.latency_s is not None else "n/a"
    parts = [f"frame {frame.frame_number:>8}  t={frame.capture_time_s:10.3f} s  latency {latency}"]
    for name, pose in sorted(frame.bodies.items()):
        x, y, z = pose.position
        state = "[green]ok[/]" if pose.valid else "[red]LOST[/]"
        parts.append(f"{name} ({x:+.3f}, {y:+.3f}, {z:+.3f}) {state}")
    if len(parts) == 1:
        parts.append("no rigid bodies")
    return "  |  ".join(parts)


@mocap_app.command("watch")
def watch(
    natnet: str = typer.Option("127.0.0.1", "--natnet", help="Motive (NatNet server) host name or IPv4 address."),
    multicast: bool = typer.Option(True, "--multicast/--unicast", help="Receive frames by multicast or unicast."),
    local_ip: str = typer.Option(
        "0.0.0.0", "--local-ip", help="Local interface facing Motive (choose it on hosts with several network cards)."
    ),
    command_port: int = typer.Option(1510, "--command-port", help="Server command port."),
    data_port: Optional[int] = typer.Option(
        None, "--data-port", help="Multicast data port (default: as announced by the server, normally 1511)."
    ),
    up_axis: UpAxis = typer.Option(UpAxis.z, "--up-axis", help="Up axis Motive streams; output is always Z-up."),
    frames: int = typer.Option(0, "--frames", min=0, help="Exit after this many frames (0: until Ctrl-C)."),
    json_output: bool = typer.Option(False, "--json", help="One JSON object per line per frame."),
    timeout: float = typer.Option(5.0, "--timeout", min=0.1, help="Seconds to wait for the server and for frames."),
    system: str = typer.Option(
        "natnet", "--system", help="natnet (our NatNet client, the default for OptiTrack) or a type of the "
        "motioncapture package: optitrack, vicon, qualisys, vrpn, mock, ... (docs/mocap.md)."),
    host: Optional[str] = typer.Option(
        None, "--host", help="The system's host (--system natnet: the same as --natnet)."),
    option: list[str] = typer.Option(
        [], "--option", help="KEY=VALUE: an option of the motioncapture type (repeat for several), e.g. "
        "--option 'rigid_bodies=cf1(0,0,0,1,0,0,0)' for mock."),
) -> None:
    """Print rigid bodies as they arrive from a NatNet server, or from a system of the motioncapture package
    (Z-up world frame, metres)."""
    if system != "natnet":
        from rpf_fly.cli.mocap_library import watch_library

        return watch_library(system, host, option, local_ip=local_ip, command_port=command_port,
                             up_axis=up_axis.value, frames=frames, json_output=json_output, timeout=timeout)
    if host is not None:
        natnet = host
    if option:
        typer.echo("error: --option is for the motioncapture systems (--system TYPE), not natnet", err=True)
        raise typer.Exit(2)
    from rich.console import Console

    from rpf_fly.mocap.natnet_client import NatNetClient

    console = Console(highlight=False, soft_wrap=True)
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
            count = 0
            last_frame = time.monotonic()
            while frames == 0 or count < frames:
                frame = client.receive(0.2)
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
                count += 1
                if json_output:
                    typer.echo(_frame_json(frame))
                else:
                    console.print(_frame_line(frame))
        except KeyboardInterrupt:
            pass


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
) -> None:
    """Run a NatNet server emulator streaming bodies on circles, so `mocap watch` can be tried without Motive."""
    from rpf_fly.mocap.natnet_protocol import SUPPORTED_VERSIONS, parse_version
    from rpf_fly.emulator.natnet_server import NatNetServer

    try:
        parsed = parse_version(version)
    except ValueError:
        parsed = (-1, -1)
    if parsed not in SUPPORTED_VERSIONS:
        raise typer.BadParameter(f"{version} is not one of 3.0, 4.0, 4.1, 4.2", param_hint="--version")
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
