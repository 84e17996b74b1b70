"""The fault hooks and snapshots of a simulated world reached over a control connection, by the names of
``FakeWorld``'s and ``SimulatedBodies``'s methods: a dry run's private world (``WorldProcess``,
rpf_fly/emulator/world_process.py) and a running lab's (``rpf_fly.flight.lab.LabClient``).
"""

from __future__ import annotations

from typing import Any

from .fake_firmware import FirmwareSnapshot
from .fake_world import TruthSample
from .host_lag import HostLag
from .sim_drone import RadioCounters
from .simulated_bodies import Pose


class WorldCalls:
    """The fault hooks and snapshots of a simulated world reached over a control connection, by the names of
    `FakeWorld`'s and `SimulatedBodies`'s methods: `WorldProcess` (a dry run's private world) and
    `rpf_fly.flight.lab.LabClient` (a running lab's)."""

    def call(self, method: str, *args: Any) -> Any:
        raise NotImplementedError

    def drop_link(self, address: int) -> None:
        self.call("drop_link", address)

    def restore_link(self, address: int) -> None:
        self.call("restore_link", address)

    def disturb(self, address: int, offset_m: tuple[float, float, float]) -> None:
        self.call("disturb", address, offset_m)

    def set_battery(self, address: int, open_circuit_v: float) -> None:
        self.call("set_battery", address, open_circuit_v)

    def reboot(self, address: int) -> None:
        self.call("reboot", address)

    def packet_loss(self, address: int, rate: float, seconds: float) -> None:
        self.call("packet_loss", address, rate, seconds)

    def gust(self, address: int, accel_m_s2: tuple[float, float, float], seconds: float) -> None:
        self.call("gust", address, accel_m_s2, seconds)

    def estimator_divergence(self, address: int, rate_m_s: float) -> None:
        self.call("estimator_divergence", address, rate_m_s)

    def radio_counters(self, address: int) -> RadioCounters:
        return self.call("radio_counters", address)

    def radio_bursts(self, address: int, start_s: float, end_s: float) -> list[tuple[float, float]]:
        return self.call("radio_bursts", address, start_s, end_s)

    def host_lag(self) -> HostLag:
        """How far the host let the simulated world fall behind its own time (`rpf_fly.emulator.host_lag`)."""
        return self.call("host_lag")

    def time_s(self) -> float:
        """The child world's clock (seconds since it started)."""
        return self.call("time_s")

    def snapshot(self, address: int) -> FirmwareSnapshot:
        return self.call("snapshot", address)

    def true_poses(self) -> dict[int, tuple[tuple[float, float, float], tuple[float, float, float, float]]]:
        return self.call("true_poses")

    def truth_samples(self) -> list[TruthSample]:
        """The world's truth samples since the previous call (`FakeWorld.truth_samples`): one round trip."""
        return self.call("truth_samples")

    def poses(self) -> dict[str, Pose]:
        """The bodies as the mocap sees them (`SimulatedBodies.poses`)."""
        return self.call("poses")

    def hide(self, body: str, seconds: float) -> None:
        self.call("hide", body, seconds)

    def blackout(self, seconds: float) -> None:
        self.call("blackout", seconds)

    def pose_jump(self, body: str, offset_m: tuple[float, float, float], seconds: float) -> None:
        self.call("pose_jump", body, offset_m, seconds)

    def orientation_flip(self, body: str, deg: float, seconds: float) -> None:
        self.call("orientation_flip", body, deg, seconds)

    def mocap_delay(self, delay_s: float, seconds: float) -> None:
        self.call("mocap_delay", delay_s, seconds)
