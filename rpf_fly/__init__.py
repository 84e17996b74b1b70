"""rpf_fly: fly a Crazyflie swarm with the Reinforced Potential Field (RPF) planner.

Layers (see docs/architecture.md): ``planning`` is pure numpy; ``sim`` and ``learn`` step the same planning
functions; ``mocap`` and ``radio`` are the protocol edges; ``flight`` ties them together; ``log`` writes and reads
MCAP; ``cli`` is the ``rpf-fly`` command.
"""

__version__ = "0.1.0"


def install_hint(extra: str) -> str:
    """How a message names an optional extra to install, one spelling everywhere: ``pip install 'rpf_fly[live]'``
    (the distribution's name as pyproject.toml spells it; pip adds the extra's packages to the installed rpf_fly,
    editable or not, from any directory)."""
    return f"pip install 'rpf_fly[{extra}]'"
