"""Where the APF gains come from: the gains interface and the fixed-gains policy (the vanilla APF).

A gains policy maps each drone's observation to ``(eta, lambda)``. The fixed policy ignores it (the paper's vanilla
APF: eta 0.05, lambda 2); the learned ONNX policy (RPF) reads it. Policies declare whether they need the
observation so the planner skips building it when it is not used.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from rpf_fly.planning.observation import Observation


@runtime_checkable
class GainsPolicy(Protocol):
    """Maps observations to gains; ``gains`` returns arrays ``eta`` and ``lambda`` of the observation's leading shape
    (or scalars, which broadcast)."""

    @property
    def needs_observation(self) -> bool: ...

    @property
    def max_neighbours(self) -> int: ...

    def gains(self, observation: Observation | None) -> tuple[np.ndarray | float, np.ndarray | float]: ...


@dataclass(frozen=True)
class FixedGains:
    """Constant gains: the vanilla APF (paper Section V: eta 0.05, lambda 2)."""

    eta: float = 0.05
    lam: float = 2.0
    needs_observation: bool = False
    max_neighbours: int = 0

    def gains(self, observation: Observation | None) -> tuple[float, float]:
        return self.eta, self.lam
