"""Cost of the simulated Crazyflie's dynamics (rpf_fly/emulator/cf_drone.py, cf_swarm.py): the CPU time one world
step of 10 ms takes, per drone, and how many drones one core keeps in real time.

Why: a world steps every drone every 10 ms on one thread; the firmware's cascade runs 1 kHz inside each step (10
body ticks, 5 attitude and rate loops, 1 position loop, the high-level commander). Two ways to run it are timed:
`CfDrone` objects stepped one after the other (pure Python), and one `CfSwarm` stepping every drone on numpy
arrays. Each drone hovers settled, then flies under the load of a dry run: "stream" drones get a position setpoint
every 10 ms from their ground station (a point on a circle of 0.5 m at 0.5 m/s); "hl" drones fly high-level go_to
commands (a new one every 2 s), their commanders evaluating the plan every 10 ms. The setpoint sending and the
commands are inside the timed step. CPU time (`time.process_time`, so another process's load on the machine does
not count) of the best of the repeats.

`--closed-loop` times the bench's closed loop instead (rpf_fly/sim/closed_loop.py, `rpf-fly bench --dynamics
firmware`): the runs of one scene family's bench seeds with one planner, all flown in one swarm as the bench flies
them (hover settle, planning at 10 Hz through the flight's setpoint code, truth recorded at 100 Hz, metrics), or
each alone (`--alone`). It prints closed-loop runs per CPU second and drone-steps (one drone advanced 10 ms) per
CPU second, the settle included; a run lasts until its drones arrived (or the time limit), so the figure depends on
the family and planner.

Usage:
    python tools/bench_cf_model.py [--drones 1,10,40,100] [--seconds 2] [--repeats 3] [--mode stream|hl]
    python tools/bench_cf_model.py --closed-loop [--family crossing] [--planner apf] [--seeds 20] [--alone]
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

from rpf_fly.emulator.cf_drone import CfDrone
from rpf_fly.emulator.cf_swarm import CfSwarm

STEP_S = 0.01
BUDGET_US = STEP_S * 1e6


def _targets(n: int, t: float) -> list[tuple[float, float, float]]:
    return [(0.6 * i + 0.5 * math.cos(t), 0.5 * math.sin(t), 1.0) for i in range(n)]


def _fly(drones: list, advance, seconds: float, mode: str) -> float:  # noqa: ANN001 - drones: CfDrone or views
    """CPU seconds per 10 ms world step over `seconds` of flight."""
    steps = round(seconds / STEP_S)
    start = time.process_time()
    for k in range(steps):
        t = k * STEP_S
        if mode == "stream":
            for d, (x, y, z) in zip(drones, _targets(len(drones), t)):
                d.send_position(x, y, z)
        elif k % 200 == 0:
            for i, d in enumerate(drones):
                d.go_to(0.6 * i + (0.3 if (k // 200) % 2 == 0 else 0.0), 0.2, 1.0, 1.5)
        advance()
    return (time.process_time() - start) / steps


def bench_single(n: int, seconds: float, repeats: int, mode: str) -> float:
    best = math.inf
    for _ in range(repeats):
        drones = [CfDrone.hovering((0.6 * i, 0.0, 1.0), settle_s=0.5) for i in range(n)]
        if mode == "hl":
            for d in drones:
                d.notify_setpoint_stop()

        def advance() -> None:
            for d in drones:
                d.step(STEP_S)

        best = min(best, _fly(drones, advance, seconds, mode))
    return best


def bench_swarm(n: int, seconds: float, repeats: int, mode: str) -> float:
    best = math.inf
    for _ in range(repeats):
        swarm = CfSwarm.hovering([(0.6 * i, 0.0, 1.0) for i in range(n)], settle_s=0.5)
        drones = [swarm.drone(i) for i in range(n)]
        if mode == "hl":
            for d in drones:
                d.notify_setpoint_stop()
        best = min(best, _fly(drones, lambda: swarm.step(STEP_S), seconds, mode))
    return best


def bench_closed_loop(family: str, planner: str, seeds: int, alone: bool) -> dict[str, float]:
    """CPU seconds, runs, drones and simulated 10 ms steps of the bench's closed loop on `seeds` bench seeds of
    `family` with `planner` (its kind's default guidance and margin), flown together or each alone."""
    from rpf_fly.bench.families import SIM, SPLIT
    from rpf_fly.bench.runner import POLICY_ACTIONS
    from rpf_fly.sim.closed_loop import STEP_S as LOOP_STEP_S
    from rpf_fly.sim.closed_loop import FirmwareParams, run_firmware
    from rpf_fly.sim.evaluate import planner_settings
    from rpf_fly.sim.generators import generate, split_seeds

    policy = Path(__file__).resolve().parents[1] / "policies" / f"{planner}.onnx" if planner in POLICY_ACTIONS else None
    settings = planner_settings(planner, policy)
    seed_list = split_seeds(SPLIT, seeds)
    scenes = [generate(family, seed, split=SPLIT) for seed in seed_list]
    batches = [[i] for i in range(len(scenes))] if alone else [list(range(len(scenes)))]
    settle_s = FirmwareParams().settle_s
    cpu = steps = 0.0
    for batch in batches:
        start = time.process_time()
        runs = run_firmware(
            [scenes[i] for i in batch], settings, SIM, [seed_list[i] for i in batch], [family] * len(batch), keep=True
        )
        cpu += time.process_time() - start
        drones = sum(scenes[i].n_drones for i in batch)
        longest = max(r.rollout.truth.shape[0] - 1 for r in runs) * LOOP_STEP_S  # the swarm flies the longest run
        steps += drones * round((settle_s + longest) / STEP_S)
    return {"cpu_s": cpu, "runs": len(scenes), "drones": sum(s.n_drones for s in scenes), "drone_steps": steps}


def main_closed_loop(args: argparse.Namespace) -> None:
    r = bench_closed_loop(args.family, args.planner, args.seeds, args.alone)
    how = "each alone" if args.alone else "together in one swarm"
    print(f"closed loop: {r['runs']} runs of {args.family} ({r['drones']:.0f} drones), {args.planner}, {how}")
    print(
        f"CPU {r['cpu_s']:.1f} s: {r['runs'] / r['cpu_s']:.2f} runs per CPU second, "
        f"{r['drone_steps'] / r['cpu_s']:.0f} drone-steps (10 ms) per CPU second"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drones", default="1,10,40,100")
    parser.add_argument("--seconds", type=float, default=2.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--mode", choices=("stream", "hl"), default="stream")
    parser.add_argument("--closed-loop", action="store_true", help="time the bench's closed loop instead")
    parser.add_argument("--family", default="crossing", help="closed loop: the scene family")
    parser.add_argument("--planner", default="apf", help="closed loop: the planner kind")
    parser.add_argument("--seeds", type=int, default=20, help="closed loop: bench seeds 0..N-1")
    parser.add_argument("--alone", action="store_true", help="closed loop: fly each run in a swarm of its own")
    args = parser.parse_args()
    if args.closed_loop:
        main_closed_loop(args)
        return
    print(f"mode {args.mode}: CPU time per 10 ms world step (best of {args.repeats} x {args.seconds:g} s)")
    print(
        "| drones | per-drone CfDrone: us/step | us per drone | swarm CfSwarm: us/step | us per drone "
        "| drones one core keeps in real time (CfDrone / CfSwarm) |"
    )
    print("|---|---|---|---|---|---|")
    for n in (int(v) for v in args.drones.split(",")):
        single = bench_single(n, args.seconds, args.repeats, args.mode) * 1e6
        swarm = bench_swarm(n, args.seconds, args.repeats, args.mode) * 1e6
        print(
            f"| {n} | {single:.0f} | {single / n:.0f} | {swarm:.0f} | {swarm / n:.1f} "
            f"| {BUDGET_US / (single / n):.0f} / {'yes' if swarm <= BUDGET_US else 'no'} at {n} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
