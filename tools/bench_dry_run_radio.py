"""A dry run through the fake radio against one through cflib's own radio driver and emulated Crazyradios
(``dry_run.radio``, docs/radio.md "Dry runs through cflib's radio driver"): what each costs a flight.

Usage::

    python tools/bench_dry_run_radio.py [--runs N] [--radios fake,crazyradio_pa,crazyradio_2]

flies a 3-drone mission (one dongle, setpoints at 10 Hz, extpos at 30 Hz, the dry run's bursty loss) ``--runs``
times through each radio, in this process as ``rpf-fly fly --dry-run`` does, and prints for each run the connection
time (the swarm's ``connecting`` to ``preflight`` phases: TOC download and parameters through a fresh TOC cache), the
whole flight's time and the drones that reached their goals.

As a pytest plugin it flies every `DryRun` of a test run through one radio instead of the mission's (the default
decision's measurements)::

    RPF_FLY_DRY_RUN_RADIO=crazyradio_pa PYTHONPATH=tools python -m pytest -p bench_dry_run_radio TESTS --durations=0
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path
from typing import Any

MISSION = """\
name: short-3
arena: {x: [-2.0, 2.0], y: [-2.0, 2.0], z: [0.0, 1.5]}
flight: {height: 0.5, speed: 0.5, rate_hz: 10, goal_tolerance: 0.1, takeoff_s: 1.0, land_s: 1.0, timeout_s: 30}
planner: {kind: apf, margin: 0}
mocap: {kind: natnet, rate_hz: 100}
obstacles:
  - {shape: circle, center: [0.0, 0.9], radius: 0.1}
drones:
  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [-1.0, -0.6], goal: [1.0, -0.6]}
  - {name: cf2, uri: radio://0/80/2M/E7E7E7E702, start: [-1.0, 0.0], goal: [1.0, 0.0]}
  - {name: cf3, uri: radio://0/80/2M/E7E7E7E703, start: [-1.0, 0.6], goal: [1.0, 0.6]}
"""


def fly_once(radio: str) -> dict[str, Any]:
    """One dry-run flight of `MISSION` through ``radio`` (``fake`` or a dongle type): its figures."""
    from rpf_fly.flight.dry_run import DryRun
    from rpf_fly.flight.phases import FlightOutcome
    from rpf_fly.flight.session import run_flight
    from rpf_fly.mission import parse_mission
    from rpf_fly.planning.factory import make_planner
    from rpf_fly.sim.scenario import obstacle_set

    mission = parse_mission(MISSION)
    obstacles = obstacle_set(mission.obstacles)
    kind, dongle = ("fake", None) if radio == "fake" else ("crazyradio", radio)
    start = time.monotonic()
    with tempfile.TemporaryDirectory() as tmp, DryRun(mission, radio=kind, crazyradio=dongle, cache_dir=None) as rig:
        report = run_flight(
            mission, lambda drone: make_planner(mission.planner, obstacles), Path(tmp) / "f.mcap", rig=rig
        )
    phases = {e.message: e.time_s for e in report.events if e.kind == "phase" and e.drone is None}
    reached = sum(o == FlightOutcome.REACHED for o in report.outcomes.values())
    connected = phases.get("swarm: preflight")
    return {
        "radio": radio,
        "connect_s": None if connected is None else connected - phases["swarm: connecting"],
        "flight_s": time.monotonic() - start,
        "reached": reached,
        "drones": len(report.outcomes),
        "host_behind_s": report.host_behind_s or 0.0,
    }


def main() -> None:
    """Fly the mission through each radio ``--runs`` times and print a line a run."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=2)
    parser.add_argument("--radios", default="fake,crazyradio_pa,crazyradio_2")
    args = parser.parse_args()
    for radio in args.radios.split(","):
        for _ in range(args.runs):
            r = fly_once(radio)
            connect = "did not connect" if r["connect_s"] is None else f"connect {r['connect_s']:.2f} s"
            print(
                f"{r['radio']:14} {connect}  flight {r['flight_s']:.1f} s  reached {r['reached']}/{r['drones']}"
                f"  world behind {r['host_behind_s']:.1f} s",
                flush=True,
            )


_FORCED = os.environ.get("RPF_FLY_DRY_RUN_RADIO")
if _FORCED and __name__ != "__main__":  # loaded as a pytest plugin: every DryRun through that radio
    from rpf_fly.flight import dry_run as _dry_run

    _init = _dry_run.DryRun.__init__

    def _forced_init(self: Any, mission: Any, **kwargs: Any) -> None:
        if _FORCED == "fake":
            kwargs["radio"] = "fake"
        else:
            kwargs["radio"], kwargs["crazyradio"] = "crazyradio", _FORCED
        _init(self, mission, **kwargs)

    _dry_run.DryRun.__init__ = _forced_init  # type: ignore[method-assign]

if __name__ == "__main__":
    main()
