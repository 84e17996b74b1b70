"""Learned policies at run time: an exported ONNX graph run with onnxruntime (never torch, never pickle).

:class:`OnnxPolicy` wraps one session (one thread: a drone's planner must not fight the flight loop for cores) and
reads the graph's metadata (action kind, neighbour slots, gain ranges). :class:`OnnxGains` is the RPF gains policy
for :class:`~rpf_fly.planning.Planner`: observation in, ``(eta, lambda)`` out.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rpf_fly.planning.observation import Observation


class PolicyError(ValueError):
    """A policy file that cannot be used: unreadable, not one of ours, or of the wrong kind."""


class OnnxPolicy:
    """An exported rpf_fly policy: ``act(observation)`` returns actions of shape ``S + (action_size,)``."""

    def __init__(self, path: str | Path):
        import onnxruntime as ort

        self.path = Path(path)
        options = ort.SessionOptions()
        options.intra_op_num_threads = 1
        options.inter_op_num_threads = 1
        try:
            self.session = ort.InferenceSession(str(self.path), options, providers=["CPUExecutionProvider"])
        except Exception as err:  # onnxruntime raises several types for unreadable files
            raise PolicyError(f"{self.path}: cannot load ONNX policy: {err}") from None
        meta = self.session.get_modelmeta().custom_metadata_map
        if "rpf_fly.action" not in meta:
            raise PolicyError(f"{self.path}: not an rpf_fly policy (no rpf_fly.* metadata)")
        self.metadata = dict(meta)
        self.action = meta["rpf_fly.action"]
        self.max_neighbours = int(meta["rpf_fly.max_neighbours"])
        inputs = {i.name for i in self.session.get_inputs()}
        if inputs != {"local", "neighbours", "mask"}:
            raise PolicyError(f"{self.path}: expected inputs local, neighbours, mask; got {sorted(inputs)}")
        self._bind_one_drone()

    def _bind_one_drone(self) -> None:
        """Preallocated input and output buffers for the one-drone call (the flight loop's case): binding them
        once saves ~20 us a call over ``session.run`` (measured: 30 vs 51 us). Not thread-safe: one policy
        instance per drone, as the flight loop gives every drone its own planner."""
        import onnxruntime as ort

        k = self.max_neighbours
        size = int(self.session.get_outputs()[0].shape[-1])
        self._local = np.zeros((1, 4), np.float32)
        self._neighbours = np.zeros((1, k, 3), np.float32)
        self._mask = np.zeros((1, k), np.float32)
        self._action = np.zeros((1, size), np.float32)
        self._binding = self.session.io_binding()
        for name, array in (("local", self._local), ("neighbours", self._neighbours), ("mask", self._mask)):
            self._binding.bind_ortvalue_input(name, ort.OrtValue.ortvalue_from_numpy(array))
        self._binding.bind_ortvalue_output("action", ort.OrtValue.ortvalue_from_numpy(self._action))

    def act(self, observation: Observation) -> np.ndarray:
        """Deterministic actions for every drone of the observation's leading shape."""
        if observation.local.ndim == 1:  # one drone: write into the bound buffers (they share memory with ORT)
            self._local[0] = observation.local
            self._neighbours[0] = observation.neighbours
            self._mask[0] = observation.mask
            self.session.run_with_iobinding(self._binding)
            return self._action[0].copy()
        lead = observation.local.shape[:-1]
        k = self.max_neighbours
        feeds = {
            "local": np.ascontiguousarray(observation.local.reshape(-1, observation.local.shape[-1]), np.float32),
            "neighbours": np.ascontiguousarray(observation.neighbours.reshape(-1, k, 3), np.float32),
            "mask": np.ascontiguousarray(observation.mask.reshape(-1, k), np.float32),
        }
        out = self.session.run(["action"], feeds)[0]
        return out.reshape(*lead, out.shape[-1])


class OnnxGains:
    """RPF: gains ``(eta, lambda)`` from an ONNX policy, per drone, every step."""

    needs_observation = True

    def __init__(self, policy: OnnxPolicy):
        if policy.action != "gains":
            raise PolicyError(f"{policy.path}: a {policy.action!r} policy cannot set APF gains")
        self.policy = policy
        self.max_neighbours = policy.max_neighbours

    def gains(self, observation: Observation | None):
        assert observation is not None
        action = self.policy.act(observation)
        if action.ndim == 1:  # one drone: Python numbers keep the planner on its fast scalar path
            eta, lam = action.tolist()
            return eta, lam
        action = action.astype(float)
        return action[..., 0], action[..., 1]
