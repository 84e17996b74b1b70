"""The hang guard for every test here: cflib waits forever on silence, so a stuck radio test dumps stacks and exits.
And still air: the tests here check the emulator's documented figures (tracking lag, trajectories, contact
distances, drift) to the millimetre, so the simulated drones they make fly without turbulence unless a test asks
for it (`VehicleConfig.turbulence_m_s2`); the turbulence has its own tests, and every dry run (tests/flight,
tests/cli) flies with it. The mocap is exact here too (`_exact_mocap`)."""

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


@pytest.fixture(autouse=True)
def _exact_mocap(monkeypatch: pytest.MonkeyPatch) -> None:
    """The same for the mocap: the tests here compare served poses with the truth to a tenth of a millimetre, so
    the rigs they build serve it without a real room's jitter and dropouts (rpf_fly/emulator/mocap_noise.py), which
    has its own tests; every dry run elsewhere flies with it."""
    from rpf_fly.emulator import mocap_noise

    monkeypatch.setattr(mocap_noise, "POSITION_NOISE_M", 0.0)
    monkeypatch.setattr(mocap_noise, "ORIENTATION_NOISE_DEG", 0.0)
    monkeypatch.setattr(mocap_noise, "DROPOUT", 0.0)
