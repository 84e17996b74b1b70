"""The hang guard for every test here: cflib waits forever on silence, so a stuck radio test dumps stacks and exits.
And still air: the tests here check the emulator's documented figures (tracking lag, trajectories, contact
distances, drift) to the millimetre, so the simulated drones they make fly without turbulence unless a test asks
for it (`VehicleConfig.turbulence_m_s2`); the turbulence has its own tests, and every dry run (tests/flight,
tests/cli) flies with it."""

from __future__ import annotations

from collections.abc import Iterator

import pytest


@pytest.fixture(autouse=True)
def _hang_guard(hang_guard: None) -> Iterator[None]:
    yield


@pytest.fixture(autouse=True)
def _still_air(monkeypatch: pytest.MonkeyPatch) -> None:
    from rpf_fly.emulator import fake_vehicle

    monkeypatch.setattr(fake_vehicle, "TURBULENCE_M_S2", 0.0)
