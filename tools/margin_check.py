"""Does the margin hold? Simulate missions with a planner, guidance and margin; print per mission the success,
collisions and the minimum separation and clearance against 2r + margin and r + margin.

    python tools/margin_check.py [--planner apf] [--guidance path] [--margin 0.05] [--seeds 20] [MISSION ...]

Missions default to the shipped ones (missions/*.yaml). Exit status 1 when a margin is broken on any run.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from rpf_fly.mission import load_mission  # noqa: E402
from rpf_fly.mission.load import with_planner  # noqa: E402
from rpf_fly.sim.evaluate import run_scenario, sim_params  # noqa: E402
from rpf_fly.sim.scenario import scenario_from_mission  # noqa: E402


def _held(value: float | None, need: float, held: bool) -> str:
    """A table cell: the measured value and whether it held its bound ("-": not measured)."""
    return "-" if value is None else f"{value:.3f} ({'ok' if held else 'BELOW ' + format(need, '.3f')})"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("missions", nargs="*", type=Path)
    ap.add_argument("--planner", default="apf")
    ap.add_argument("--guidance", choices=("none", "path"), default=None, help="default: the kind's")
    ap.add_argument("--margin", type=float, default=None, help="default: the kind's")
    ap.add_argument("--seeds", type=int, default=20)
    args = ap.parse_args()
    paths = args.missions or sorted((ROOT / "missions").glob("*.yaml"))
    overrides = {k: v for k, v in (("guidance", args.guidance), ("margin", args.margin)) if v is not None}
    broken = False
    print(
        "| mission | planner | guidance | margin | success | collisions | "
        "min sep [m] (>= 2r+m) | min clear [m] (>= r+m) | makespan [s] |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for path in paths:
        mission = with_planner(load_mission(path), args.planner, **overrides)
        s = mission.planner
        r, m = s.safety_radius, s.margin_m
        runs = [
            run_scenario(scenario_from_mission(mission, seed), s, sim_params(mission), seed, mission.name).metrics
            for seed in range(args.seeds)
        ]
        ok = sum(x.success for x in runs)
        coll = sum(x.collisions_drone_drone + x.collisions_drone_obstacle for x in runs)
        seps = [x.min_separation_m for x in runs if x.min_separation_m is not None]
        clears = [x.min_obstacle_clearance_m for x in runs if x.min_obstacle_clearance_m is not None]
        sep = min(seps) if seps else None
        clear = min(clears) if clears else None
        spans = [x.makespan_s for x in runs if x.makespan_s is not None]
        held_sep = sep is None or sep >= 2 * r + m
        held_clear = clear is None or clear >= r + m
        broken |= not (held_sep and held_clear)
        span = f"{sum(spans) / len(spans):.1f}" if spans else "-"
        print(
            f"| {mission.name} | {s.kind} | {s.guidance_mode} | {m:g} | {ok}/{len(runs)} | {coll} | "
            f"{_held(sep, 2 * r + m, held_sep)} | {_held(clear, r + m, held_clear)} | {span} |"
        )
    return 1 if broken else 0


if __name__ == "__main__":
    raise SystemExit(main())
