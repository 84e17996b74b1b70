"""Did every shipped mission's dry run keep its planner's margin, on a given model of the simulated Crazyflie?

    python tools/mission_margins.py --dynamics firmware                       # every mission under missions/
    python tools/mission_margins.py --dynamics first-order lab-3 campaign/wall-gap-5 --runs 3

For each mission: a copy with ``dry_run.dynamics`` set (`rpf_fly.campaign.missions.with_dynamics`), then
``rpf-fly fly COPY --dry-run --no-console --log LOG`` as a user types it (flown again, up to 3 tries, when the host
could not keep up: such a run is not evidence), then ``tools/log_margin.py LOG COPY --margin M`` with the mission's
own ``planner.margin_m``: the smallest true distance between two airborne drones against 2r + margin and from an
airborne drone to an obstacle against r + margin, judged on the simulated world's truth. The 40-drone missions fly
``--distributed`` (one worker per dongle), as their users fly them. One JSON line a run; exit 1 when any run broke
its margin or did not fly.

    python tools/mission_margins.py --closed-loop cross-40-4dongles lanes-40-4dongles --runs 5

``--closed-loop`` flies the mission's own planner on the firmware model's batched closed loop instead
(`rpf_fly.sim.closed_loop`, as ``rpf-fly bench --dynamics firmware`` flies a scene): the same layout with the
``sim`` section's jitter (seeds 0..N-1), the setpoints flown by simulated firmware drones at the flight's rate, no
radio, mocap or ground station, judged on the closed loop's truth against the same bars. It is the planners' margins
on the firmware's dynamics for a mission whose dry run needs more cores than the host has (docs/dynamics.md).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from rpf_fly.campaign.flights import read_log  # noqa: E402
from rpf_fly.campaign.missions import mission_path, with_dynamics  # noqa: E402
from rpf_fly.mission import load_mission  # noqa: E402

NOT_EVIDENCE = "not evidence"
TRIES = 3


def shipped() -> list[str]:
    """Every mission under missions/, by its name there (``lab-3``, ``campaign/wall-gap-5``)."""
    folder = ROOT / "missions"
    return sorted(str(p.relative_to(folder).with_suffix("")) for p in folder.rglob("*.yaml"))


def behind(done: subprocess.CompletedProcess, log: Path) -> bool:
    if NOT_EVIDENCE in done.stdout + done.stderr:
        return True
    if not log.exists():
        return False
    return any(NOT_EVIDENCE in str(m.get("message", "")) for _, m in read_log(log).get("/events", []))


def fly(name: str, dynamics: str, out: Path, run: int) -> dict:
    copy = with_dynamics(mission_path(name), dynamics, out)
    mission = load_mission(copy)
    margin = mission.planner.margin_m
    distributed = len({d.uri.split("/")[2] for d in mission.drones}) > 1 and len(mission.drones) > 20
    log = out / f"{name.replace('/', '-')}.{dynamics}.{run}.mcap"
    command = [sys.executable, "-m", "rpf_fly", "fly", str(copy), "--dry-run", "--no-console", "--log", str(log)]
    if distributed:
        command.append("--distributed")
    tries = 0
    while True:
        tries += 1
        log.unlink(missing_ok=True)
        done = subprocess.run(command, capture_output=True, text=True, cwd=out, timeout=900)
        late = behind(done, log)
        if not late or tries == TRIES:
            break
    record: dict = {"mission": name, "dynamics": dynamics, "run": run, "margin_m": margin, "exit": done.returncode}
    record.update({"tries": tries, "host_behind": late, "distributed": distributed})
    if log.exists():
        judged = subprocess.run(
            [sys.executable, str(ROOT / "tools" / "log_margin.py"), str(log), str(copy), "--margin", str(margin)],
            capture_output=True,
            text=True,
        )
        record["judged"] = json.loads(judged.stdout) if judged.stdout.strip() else {"error": judged.stderr.strip()}
    else:
        record["judged"] = {"error": f"no log: {done.stderr.strip()[-300:]}"}
    return record


def closed_loop(name: str, runs: int) -> list[dict]:
    """The mission's planner flown ``runs`` times (jitter seeds 0..runs-1) on the firmware model's closed loop."""
    from rpf_fly.sim.closed_loop import FirmwareParams, run_firmware
    from rpf_fly.sim.evaluate import sim_params
    from rpf_fly.sim.scenario import scenario_from_mission

    mission = load_mission(mission_path(name))
    settings = mission.planner
    seeds = list(range(runs))
    scenarios = [scenario_from_mission(mission, seed) for seed in seeds]
    firmware = FirmwareParams(mission.flight.height, tuple(mission.arena.z))
    flown = run_firmware(scenarios, settings, sim_params(mission), seeds, [name] * runs, firmware)
    records = []
    for seed, run in zip(seeds, flown):
        m = run.metrics
        records.append(
            {
                "mission": name,
                "dynamics": "firmware closed loop",
                "seed": seed,
                "planner": settings.kind,
                "margin_m": settings.margin_m,
                "reached": f"{m.reached}/{m.drones}",
                "collisions": m.collisions_drone_drone + m.collisions_drone_obstacle,
                "min_separation_m": None if m.min_separation_m is None else round(m.min_separation_m, 4),
                "separation_bar_m": round(2 * settings.safety_radius + settings.margin_m, 4),
                "min_clearance_m": None if m.min_obstacle_clearance_m is None else round(m.min_obstacle_clearance_m, 4),
                "clearance_bar_m": round(settings.safety_radius + settings.margin_m, 4),
                "held": m.margin_held and m.reached == m.drones,
            }
        )
    return records


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("missions", nargs="*", help="mission names under missions/ (default: every one)")
    parser.add_argument("--dynamics", default="firmware", choices=("firmware", "first-order"))
    parser.add_argument("--runs", type=int, default=1, help="dry runs of each mission")
    parser.add_argument("--out", type=Path, default=None, help="the copies' and logs' folder (default: temporary)")
    parser.add_argument(
        "--closed-loop", action="store_true", help="the planner on the firmware model's batched closed loop, no dry run"
    )
    args = parser.parse_args()
    if args.closed_loop:
        held = True
        for name in args.missions or shipped():
            for record in closed_loop(name, args.runs):
                held = held and record["held"]
                print(json.dumps(record), flush=True)
        return 0 if held else 1
    out = args.out or Path(tempfile.mkdtemp(prefix="rpf-mission-margins-"))
    out.mkdir(parents=True, exist_ok=True)
    ok = True
    for name in args.missions or shipped():
        for run in range(1, args.runs + 1):
            record = fly(name, args.dynamics, out, run)
            judged = record["judged"]
            ok = ok and record["exit"] == 0 and not record["host_behind"] and bool(judged.get("held"))
            print(json.dumps(record), flush=True)
    print(f"logs: {out}", file=sys.stderr)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
