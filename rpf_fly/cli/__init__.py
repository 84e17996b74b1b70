"""The ``rpf-fly`` command line: one typer app, one module per command group.

Each command module registers itself on :data:`app` when imported; :func:`get_app` imports them all. Heavy
imports (cflib, onnxruntime, matplotlib) happen inside the commands so that ``rpf-fly --help`` stays fast and a
missing optional extra only affects its own command.
"""

from __future__ import annotations

import typer

app = typer.Typer(
    name="rpf-fly",
    help="Fly a Crazyflie swarm with the Reinforced Potential Field planner.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def package_version() -> str:
    """The installed distribution's version (``importlib.metadata``); the package's own ``__version__`` when it is
    not installed (a source tree on ``PYTHONPATH``)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("rpf_fly")
    except PackageNotFoundError:
        from rpf_fly import __version__

        return __version__


def _print_version(value: bool) -> None:
    if value:
        typer.echo(f"rpf-fly {package_version()}")
        raise typer.Exit(0)


@app.callback()
def _root(
    version: bool = typer.Option(
        False, "--version", callback=_print_version, is_eager=True, help="Print the rpf_fly version and exit."
    ),
) -> None:
    """Fly a Crazyflie swarm with the Reinforced Potential Field planner."""
    # A callback keeps typer in group mode even when one command is registered, so `rpf-fly sim ...` always works.


def _flags_show_no_type() -> None:
    """typer (0.29) prints a type after every option in the help, ``<bool>`` after a flag too, which reads as if the
    flag took a value (``--dry-run true`` then fails: a flag takes none). Flags show no type; every other option
    keeps its own (``<path>``, ``<int>``)."""
    from typer.core import TyperOption

    original = TyperOption.display_type_rich
    if getattr(original, "_rpf_fly_flags", False):
        return

    def display_type_rich(self, ctx):
        if getattr(self, "is_flag", False) and getattr(self, "is_bool_flag", False):
            return None
        return original(self, ctx)

    # patching typer's own class (typer 0.29 has no hook for it): its stubs rightly say neither assignment exists
    display_type_rich._rpf_fly_flags = True  # type: ignore[attr-defined]
    TyperOption.display_type_rich = display_type_rich  # type: ignore[method-assign]


def get_app() -> typer.Typer:
    """The app with every command module imported (idempotent)."""
    from rpf_fly.cli import (  # noqa: F401
        bench_cmd,
        calibrate_cmd,  # noqa: F401
        campaign_cmd,  # noqa: F401
        fly_cmd,
        lab_cmd,
        mocap_cmd,
        radio_cmd,  # noqa: F401
        replay_cmd,
        review_cmd,
        scenario_cmd,
        sim_cmd,
        train_cmd,
        worker_cmd,
    )

    _flags_show_no_type()
    return app


def main() -> None:
    """Console-script entry point (``fly --foxglove PORT`` read as ``--foxglove-port PORT``: cli/live_opts.py)."""
    import sys

    from rpf_fly.cli.live_opts import foxglove_port_argv

    get_app()(args=foxglove_port_argv(sys.argv[1:]), prog_name="rpf-fly")
