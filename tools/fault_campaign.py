"""The maintainers' fault campaign over several shipped missions (rpf_fly/campaign; docs/fault-campaign.md).

    python tools/fault_campaign.py                       # every kind on lab-3 and circle-8-r3 (about 17 minutes)
    python tools/fault_campaign.py --kinds occlusion,gust --missions lab-3 --out -
    python tools/fault_campaign.py --planner rpf3        # the missions flown by another planner kind
    python tools/fault_campaign.py --extpose --kinds orientation_flip,pose_jump --out -   # poses sent as extpose
    python tools/fault_campaign.py --random 20 --seed 10 --faults-per-run 2   # two faults of different kinds a flight
    python tools/fault_campaign.py --random 16 --seed 16 --extpose --faults-per-run 2 --vary-world --only 14 \
        --keep run14 --out -                              # re-fly one run of that campaign, keeping its log
    python tools/fault_campaign.py --kinds ground_station_kill,dongle_unplug --out -   # the lab kinds' 10 runs
    python tools/fault_campaign.py --dynamics firmware   # every run's simulated drones on the firmware's PID cascade

A lab flies the same campaign on its own mission with ``rpf-fly campaign MISSION``. The report goes to ``--out``
(default docs/fault-campaign/<fixed|PLANNER|random|compound>[-extpose][-firmware][-seedS].md), the verdicts as JSON to
``--json``; exit 0 when every run passed, 1 otherwise, 2 for bad options.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from rpf_fly.campaign import CampaignError, maintainers_campaign  # noqa: E402
from rpf_fly.campaign.flights import read_log as _read_topics  # noqa: E402
from rpf_fly.campaign.report import progress_line, summary  # noqa: E402
from rpf_fly.campaign.runner import default_report  # noqa: E402
from rpf_fly.campaign.truth import CONTACT_M, GOAL_M, ON_FLOOR_M  # noqa: E402, F401 - tools/swarm_acceptance.py's

ROOT = Path(__file__).resolve().parents[1]


def read_log(path: Path) -> tuple[dict[str, list[tuple[int, dict]]], dict[str, Any]]:
    """A log's messages by topic, and an empty metadata map (tools/swarm_acceptance.py reads logs through this)."""
    return _read_topics(path), {}


def _list(text: str | None) -> list[str] | None:
    return text.split(",") if text else None


def parser() -> argparse.ArgumentParser:
    """The tool's options (each the same as before the campaign moved into rpf_fly/campaign)."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument(
        "--missions",
        default=None,
        help="comma-separated shipped mission names or mission file paths "
        "(default: lab-3,circle-8-r3; random: lab-3,circle-8-r3,arena-a-6,arena-b-6,u-trap)",
    )
    p.add_argument(
        "--kinds",
        default=None,
        help="comma-separated fault kinds (default: every kind; "
        "ground_station_kill and dongle_unplug fly their own missions against a lab unless --missions)",
    )
    p.add_argument(
        "--out", default=None, help="the report (markdown), - for stdout (default: docs/fault-campaign/<name>.md)"
    )
    p.add_argument("--json", default=None, help="verdicts as JSON to this file")
    p.add_argument("--planner", default=None, help="fly each mission with this planner kind and its default policy")
    p.add_argument(
        "--random",
        type=int,
        default=0,
        metavar="N",
        help="N flights with a random mission, planner, fault kind, drone, time and parameters",
    )
    p.add_argument("--seed", type=int, default=0, help="the random campaign's seed")
    p.add_argument("--planners", default="mission,rpf3", help="the random campaign's planners (mission: its own)")
    p.add_argument(
        "--faults-per-run",
        type=int,
        default=1,
        metavar="K",
        help="the random campaign's faults a flight: K of different kinds at once (compound)",
    )
    p.add_argument(
        "--vary-world",
        action="store_true",
        help="the random campaign's simulated world drawn from a "
        "seed of each run's own (dry_run.seed = seed * 1000 + run) instead of 0",
    )
    p.add_argument("--extpose", action="store_true", help="fly each mission with radio.extpos: extpose")
    p.add_argument(
        "--dynamics",
        default=None,
        choices=("first-order", "firmware"),
        help="how every run's simulated drones fly (dry_run.dynamics; default: each mission's own)",
    )
    p.add_argument(
        "--only",
        default=None,
        metavar="RUNS",
        help="the random campaign's runs to fly, comma-separated (the draws are the whole campaign's)",
    )
    p.add_argument(
        "--keep",
        default=None,
        metavar="DIR",
        help="fly in DIR and keep each run's mission copy, fault schedule and flight log",
    )
    return p


def main(argv: list[str] | None = None) -> int:
    """Parse the options, fly the campaign (`rpf_fly.campaign.maintainers_campaign`), write and print its report."""
    p = parser()
    args = p.parse_args(argv)
    if args.out not in (None, "-") and not Path(args.out).parent.is_dir():
        p.error(f"--out: {args.out}: its folder does not exist")
    try:
        only = {int(r) for r in args.only.split(",")} if args.only else None
    except ValueError:
        p.error(f"--only: expected run numbers separated by commas, got {args.only!r}")
    try:
        result = maintainers_campaign(
            _list(args.missions),
            _list(args.kinds),
            args.planner,
            args.random,
            args.seed,
            _list(args.planners),
            args.faults_per_run,
            args.vary_world,
            args.extpose,
            only,
            Path(args.keep) if args.keep else None,
            on_verdict=lambda v: print(progress_line(v), flush=True),
            dynamics=args.dynamics,
        )
    except CampaignError as err:
        p.error(str(err))
    if args.out == "-":
        print(result.markdown())
    else:
        out = (
            Path(args.out)
            if args.out
            else default_report(args.planner, args.random, args.seed, args.faults_per_run, args.extpose, args.dynamics)
        )
        out.write_text(result.markdown())
        print(f"report: {out}")
    if args.json:
        Path(args.json).write_text(json.dumps(result.json(), indent=1))
    print(summary(result.verdicts))
    return 0 if result.passed else 1


if __name__ == "__main__":
    raise SystemExit(main())
