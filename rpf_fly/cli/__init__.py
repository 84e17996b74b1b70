"""The ``rpf-fly`` command line: one typer app, one module per command group.

Each command module registers itself on :data:`app`; heavy imports (cflib, onnxruntime, matplotlib) happen
inside the commands so that ``rpf-fly --help`` stays fast and a missing optional extra only affects its command.
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


def _register() -> None:
    """Import the command modules so they attach their commands to ``app``."""
    from rpf_fly.cli import sim_cmd  # noqa: F401

    try:
        from rpf_fly.cli import mocap_cmd  # noqa: F401
    except ImportError:  # the mocap command module lands with the hardware-edges issue
        pass


def main() -> None:
    """Console-script entry point."""
    _register()
    app()
