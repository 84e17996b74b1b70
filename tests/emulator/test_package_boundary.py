"""The emulators stay out of a real flight: importing what a real flight runs loads nothing from `rpf_fly.emulator`."""

from __future__ import annotations

import subprocess
import sys

REAL_FLIGHT_MODULES = (
    "rpf_fly.flight.loop",
    "rpf_fly.flight.session",
    "rpf_fly.radio.cflib_backend",
    "rpf_fly.mocap.natnet_client",
    "rpf_fly.mocap.motioncapture_source",
    "rpf_fly.cli",
)


def test_a_real_flight_imports_no_emulator() -> None:
    code = (
        "import importlib, sys\n"
        f"for name in {REAL_FLIGHT_MODULES!r}: importlib.import_module(name)\n"
        "print(sorted(m for m in sys.modules if m.startswith('rpf_fly.emulator')))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_radio_and_mocap_hold_no_emulator_module() -> None:
    from pathlib import Path

    import rpf_fly.mocap
    import rpf_fly.radio

    for package in (rpf_fly.radio, rpf_fly.mocap):
        names = {p.stem for p in Path(package.__file__).parent.glob("*.py")}
        assert not {n for n in names if n.startswith("fake_") or n in {"world_process", "natnet_server", "simulated"}}
