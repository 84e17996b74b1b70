"""rpf_fly: fly a Crazyflie swarm with the Reinforced Potential Field (RPF) planner.

Layers (see docs/architecture.md): ``planning`` is pure numpy; ``sim`` and ``learn`` step the same planning
functions; ``mocap`` and ``radio`` are the protocol edges; ``flight`` ties them together; ``log`` writes and reads
MCAP; ``cli`` is the ``rpf-fly`` command.
"""

__version__ = "0.1.0"
