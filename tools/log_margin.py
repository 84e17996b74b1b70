"""Did a dry run keep the planner's margin? Read with the mcap library alone (not rpf_fly's reader): the simulated
world's truth (``/truth/<drone>``) of every airborne moment, against 2r + margin between drones and r + margin from
the mission's obstacles (RPF-3's dry-run line; docs/bench/rpf3.md).

    python tools/log_margin.py LOG MISSION [--margin 0.05]

Prints one JSON line: the smallest distance between two airborne drones (motors on, above 0.2 m) and from an
airborne drone to an obstacle's surface, the bars, crashes, and ``held``. Exit status 1 when the margin is broken.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import sys

import yaml
from mcap.reader import make_reader

AIRBORNE_Z_M = 0.2


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log")
    parser.add_argument("mission")
    parser.add_argument("--margin", type=float, default=0.05)
    args = parser.parse_args()
    mission = yaml.safe_load(open(args.mission))
    r = float((mission.get("planner") or {}).get("safety_radius", 0.1))
    truth: dict[str, list[dict]] = {}
    with open(args.log, "rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages():
            if channel.topic.startswith("/truth/"):
                truth.setdefault(channel.topic.split("/")[2], []).append(json.loads(message.data))
    if not truth:
        print(f"{args.log}: no /truth topic (not a dry-run log?)", file=sys.stderr)
        return 2
    names = sorted(truth)
    steps = min(len(samples) for samples in truth.values())

    def airborne(s: dict) -> bool:
        return bool(s["motors"]) and s["position"]["z"] > AIRBORNE_Z_M

    separation = clearance = math.inf
    for k in range(steps):
        up = [(s["position"]["x"], s["position"]["y"]) for s in (truth[n][k] for n in names) if airborne(s)]
        for p, q in itertools.combinations(up, 2):
            separation = min(separation, math.dist(p, q))
    for obstacle in mission.get("obstacles") or []:
        for samples in truth.values():
            for s in samples:
                if not airborne(s):
                    continue
                p = (s["position"]["x"], s["position"]["y"])
                if "radius" in obstacle:
                    d = math.dist(p, obstacle["center"]) - obstacle["radius"]
                else:
                    lo, hi = obstacle["min"], obstacle["max"]
                    d = math.hypot(max(lo[0] - p[0], 0.0, p[0] - hi[0]), max(lo[1] - p[1], 0.0, p[1] - hi[1]))
                clearance = min(clearance, d)
    crashed = [n for n in names if any(s["crashed"] for s in truth[n])]
    held = separation >= 2 * r + args.margin and clearance >= r + args.margin and not crashed
    print(
        json.dumps(
            {
                "log": args.log,
                "drones": len(names),
                "min_separation_m": None if separation == math.inf else round(separation, 3),
                "separation_bar_m": round(2 * r + args.margin, 3),
                "min_clearance_m": None if clearance == math.inf else round(clearance, 3),
                "clearance_bar_m": round(r + args.margin, 3),
                "crashed": crashed,
                "held": held,
            }
        )
    )
    return 0 if held else 1


if __name__ == "__main__":
    sys.exit(main())
