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


@app.callback()
def _root() -> None:
    """Fly a Crazyflie swarm with the Reinforced Potential Field planner."""
    # A callback keeps typer in group mode even when one command is registered, so `rpf-fly sim ...` always works.


def get_app() -> typer.Typer:
    """The app with every command module imported (idempotent)."""
    from rpf_fly.cli import bench_cmd, fly_cmd, mocap_cmd, review_cmd, sim_cmd, train_cmd  # noqa: F401

    return app


def main() -> None:
    """Console-script entry point."""
    get_app()()
