"""Planner and simulator benchmark: per-drone plan step, one flight tick, batched simulation throughput.

    python tools/bench_planner.py [--repeats 15] [--json out.json]
    python tools/bench_planner.py --cadence      # the flight tick's cold start at the flight's cadence
    python tools/bench_planner.py --rpf3         # RPF-3 as shipped: per-drone step vs onnxruntime, batched ticks

1. Per-drone plan step (fixed gains, the apf kind's defaults: guidance path, margin 0.05): one drone planned from
   its own view, as the flight loop does, on views taken mid-flight from the paper missions. Median over repeats of
   the mean time per call. Then RPF's step with guidance beside the same step without and the onnxruntime call
   alone (docs/algorithm.md, *Global guidance*).
2. One tick for 10 and 100 drones: every drone planned from its own view, (a) one call per drone as the flight
   loop does, view building included, and (b) all drones in one batched call.
3. Batched simulation: many arenas stepped together (views, plan, advance), in robot-steps per second.

Runs on one core (numpy here uses no threads for these sizes; OMP/BLAS threads are pinned to 1 anyway). The
machines are shared and noisy: read medians and ratios, not single runs.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from rpf_fly.mission import load_mission  # noqa: E402
from rpf_fly.planning import FixedGains, ObstacleSet, Planner, PlannerConfig, view_of_drone  # noqa: E402
from rpf_fly.planning.factory import make_planner  # noqa: E402
from rpf_fly.sim import SimParams, World, arena_a, circle_swap, rollout, scenario_from_mission  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def timed(fn: Callable[[], object], inner: int, repeats: int) -> float:
    """Median over ``repeats`` of the mean seconds per call of ``fn`` over ``inner`` calls."""
    for _ in range(max(inner // 10, 1)):
        fn()
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(inner):
            fn()
        samples.append((time.perf_counter() - t0) / inner)
    return statistics.median(samples)


def midflight_views(mission_name: str):  # type: ignore[no-untyped-def]
    """Each drone's own view at the middle of a simulated run of the mission (fixed-gains APF), and the planner."""
    from dataclasses import replace

    mission = load_mission(ROOT / "missions" / f"{mission_name}.yaml")
    scenario = scenario_from_mission(mission, 0)
    planner = make_planner(replace(mission.planner, kind="apf", policy=None), scenario.obstacles)
    params = SimParams(mission.flight.speed, mission.flight.dt, mission.flight.goal_tolerance, mission.sim.time_limit_s)
    run = rollout(scenario, planner, params)
    k = run.steps // 2
    pos = run.positions[k]
    vel = (run.positions[k] - run.positions[k - 1]) / params.dt
    heading = np.where(abs(vel) > 0, vel / np.maximum(abs(vel), 1e-12), 1.0)
    views = []
    for i in range(len(pos)):
        others = np.delete(np.arange(len(pos)), i)
        views.append(view_of_drone(pos[i], scenario.goals[i], heading[i], pos[others], vel[others], 6.0))
    return planner, views


def bench_per_drone(repeats: int, kind: str = "apf") -> dict[str, float]:
    """Median per-drone step on each mission's mid-flight views, with the fixed-gains APF or the shipped RPF policy."""
    from dataclasses import replace

    out = {}
    for name in ("lab-3", "arena-a-6", "circle-8-r3"):
        planner, views = midflight_views(name)
        if kind != "apf":
            mission = load_mission(ROOT / "missions" / f"{name}.yaml")
            settings = replace(mission.planner, kind=kind, policy=ROOT / "policies" / f"{kind}.onnx")
            planner = make_planner(settings, planner.obstacles)
        per_view = [timed(lambda v=v: planner.step(v), 300, repeats) for v in views]
        out[name] = statistics.median(per_view)
    return out


def bench_guidance(repeats: int) -> dict[str, dict[str, float]]:
    """Per-drone plan step of RPF (policies/rpf.onnx) with guidance path and margin 0.05, beside the same step
    without guidance and the onnxruntime call alone (``OnnxPolicy.act`` on the step's observation), on each
    mission's mid-flight views (u-trap: the U-shaped trap, where the goal is hidden)."""
    from dataclasses import replace

    from rpf_fly.planning.observation import build_observation
    from rpf_fly.planning.planner import sense_obstacles

    out: dict[str, dict[str, float]] = {}
    for name in ("lab-3", "arena-a-6", "u-trap"):
        _, views = midflight_views(name)
        mission = load_mission(ROOT / "missions" / f"{name}.yaml")
        scenario = scenario_from_mission(mission, 0)
        base = replace(mission.planner, kind="rpf", policy=ROOT / "policies" / "rpf.onnx")
        bounds = (scenario.arena_x, scenario.arena_y)
        guided = make_planner(replace(base, guidance="path", margin=0.05), scenario.obstacles, bounds, scenario.goals)
        plain = make_planner(replace(base, guidance="none", margin=0.05), scenario.obstacles, bounds, scenario.goals)
        policy = guided.gains.policy
        observations = [
            build_observation(
                v, sense_obstacles(v, guided.obstacles, guided.config)[0], guided.config, policy.max_neighbours
            )
            for v in views
        ]
        hidden = sum(guided.step(v).waypoint != v.goal for v in views)
        out[name] = {
            "with_guidance": statistics.median(timed(lambda v=v: guided.step(v), 300, repeats) for v in views),
            "without_guidance": statistics.median(timed(lambda v=v: plain.step(v), 300, repeats) for v in views),
            "onnxruntime_alone": statistics.median(
                timed(lambda o=o: policy.act(o), 300, repeats) for o in observations
            ),
            "guided_views": float(hidden),
            "views": float(len(views)),
        }
    return out


def bench_rpf3(repeats: int) -> dict[str, dict[str, float]]:
    """RPF-3 as shipped (kind ``rpf3``: guidance, margin 0.05 and RPF-3's tuning, policies/rpf3.onnx): the
    per-drone step on each mission's mid-flight views beside the onnxruntime call alone on the same observations
    (the line: at most 1.5x), and one batched tick of 10 and 100 drones (the line: 100 under 2 ms)."""
    from dataclasses import replace

    from rpf_fly.mission.model import PlannerSettings
    from rpf_fly.planning import views_from_states
    from rpf_fly.planning.observation import build_observation
    from rpf_fly.planning.planner import guided_view, sense_obstacles

    out: dict[str, dict[str, float]] = {}
    for name in ("lab-3", "arena-a-6", "u-trap"):
        _, views = midflight_views(name)
        mission = load_mission(ROOT / "missions" / f"{name}.yaml")
        scenario = scenario_from_mission(mission, 0)
        settings = replace(
            mission.planner,
            kind="rpf3",
            policy=ROOT / "policies" / "rpf3.onnx",
            guidance=None,
            margin=None,
            capture_radius=None,
        )
        planner = make_planner(settings, scenario.obstacles, (scenario.arena_x, scenario.arena_y), scenario.goals)
        policy = planner.gains.policy
        observations = []
        for v in views:
            guided, _, remaining = guided_view(v, planner.guidance, planner.config.waypoint_reach)
            nearest = sense_obstacles(v, planner.obstacles, planner.config)[0]
            observations.append(build_observation(guided, nearest, planner.config, policy.max_neighbours, remaining))
        out[name] = {
            "step": statistics.median(timed(lambda v=v: planner.step(v), 300, repeats) for v in views),
            "onnxruntime_alone": statistics.median(
                timed(lambda o=o: policy.act(o), 300, repeats) for o in observations
            ),
        }
    for n in (10, 100):
        pos, goals, vel, obstacles = swarm_state(n, np.random.default_rng(n))
        planner = make_planner(
            PlannerSettings(kind="rpf3", policy=ROOT / "policies" / "rpf3.onnx"), obstacles, None, goals
        )
        view = views_from_states(pos, vel, goals, vel / abs(vel), planner.config.sensing_range)
        out[f"batched_tick_{n}"] = {"tick": timed(lambda: planner.step(view), max(2, 200 // n) * 5, repeats)}
    return out


def swarm_state(n: int, rng: np.random.Generator):  # type: ignore[no-untyped-def]
    """``n`` drones crossing a 20 m circle mid-swap, with a few obstacles: a realistic dense tick."""
    angles = 2 * np.pi * np.arange(n) / n
    pos = 10 * np.exp(1j * angles) * rng.uniform(0.3, 1.0, n)
    goals = -10 * np.exp(1j * angles)
    vel = 0.5 * (goals - pos) / abs(goals - pos)
    obstacles = ObstacleSet.from_shapes(circles=[((3.0, 0.0), 0.5), ((-2.0, 4.0), 0.5), ((0.0, -5.0), 0.3)])
    return pos, goals, vel, obstacles


def bench_tick(n: int, repeats: int) -> dict[str, float]:
    pos, goals, vel, obstacles = swarm_state(n, np.random.default_rng(n))
    planner = Planner(obstacles, PlannerConfig.robust(), FixedGains())
    heading = vel / abs(vel)
    idx = [np.delete(np.arange(n), i) for i in range(n)]

    def per_drone_tick() -> None:
        for i in range(n):
            planner.step(view_of_drone(pos[i], goals[i], heading[i], pos[idx[i]], vel[idx[i]], 6.0))

    from rpf_fly.planning import views_from_states

    def batched_tick() -> None:
        planner.step(views_from_states(pos, vel, goals, heading, 6.0))

    inner = max(2, 200 // n)
    return {
        "per_drone_calls": timed(per_drone_tick, inner, repeats),
        "batched": timed(batched_tick, inner * 5, repeats),
    }


def flight_tick(kind: str, drones: int = 10, batching: bool = True) -> Callable[[], None]:
    """The flight loop's planning tick (``SwarmPlanner``) for ``drones`` drones of the circle swap that
    tools/bench_flight.py flies, mid-flight, as a callable (fixed-gains APF: ``kind`` apf; RPF-1: rpf)."""
    from bench_flight import mission_text as flight_bench_mission  # tools/ is on sys.path when run as a script

    from rpf_fly.flight.agent import DroneAgent
    from rpf_fly.flight.swarm_plan import Neighbourhood, SwarmPlanner
    from rpf_fly.mission import parse_mission

    mission = parse_mission(flight_bench_mission(drones, 100.0, kind))
    scenario = scenario_from_mission(mission, 0)
    planner = make_planner(mission.planner, scenario.obstacles)
    params = SimParams(mission.flight.speed, mission.flight.dt, mission.flight.goal_tolerance, 60.0)
    run = rollout(scenario, planner, params)
    k = run.steps // 2
    xy = run.positions[k]
    world = Neighbourhood([d.name for d in mission.drones], xy, (xy - run.positions[k - 1]) / params.dt)
    agents = [
        DroneAgent(
            d,
            make_planner(mission.planner, scenario.obstacles),
            height=1.0,
            speed=0.5,
            dt=params.dt,
            arena=mission.arena,
            budget_s=1.0,
        )
        for d in mission.drones
    ]
    requests = [(a, complex(p)) for a, p in zip(agents, xy)]
    for agent, p in requests:
        agent.begin_planning(p, 0.0)
    swarm = SwarmPlanner(mission.planner.sensing_range, 1.0, batching=batching)

    def tick() -> None:
        for agent, p in requests:
            agent.reference = p
        swarm.plan(requests, world)

    return tick


def bench_flight_tick(repeats: int, drones: int = 10) -> dict[str, dict[str, float]]:
    """The flight's planning tick: one batched call against one call per drone, with the fixed-gains APF and the
    shipped RPF-1. Hot caches: in flight the tick starts cold (see :func:`bench_flight_tick_cadence`)."""
    return {
        kind: {
            label: timed(flight_tick(kind, drones, batching), 50, repeats)
            for label, batching in (("batched", True), ("one_call_per_drone", False))
        }
        for kind in ("apf", "rpf")
    }


def bench_flight_tick_cadence(ticks: int = 150, drones: int = 10) -> dict[str, dict[str, float]]:
    """The batched flight tick timed one call at a time (median wall time) at the flight's cadence: back to back;
    after 10 ms asleep (what the loop does between 100 Hz frames); after 10 ms polling a non-blocking UDP socket
    (busy, never asleep); after 9.5 ms asleep and one warm-up tick. Shows what the flight pays for a cold start
    (docs/performance.md)."""
    import socket

    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.setblocking(False)

    def poll(seconds: float) -> None:
        end = time.perf_counter() + seconds
        while time.perf_counter() < end:
            try:
                sock.recvfrom(65536)
            except BlockingIOError:
                pass

    out: dict[str, dict[str, float]] = {}
    try:
        for kind in ("apf", "rpf"):
            tick = flight_tick(kind, drones)
            for _ in range(50):
                tick()

            def median_after(prepare: Callable[[], object]) -> float:
                samples = []
                for _ in range(ticks):
                    prepare()
                    t0 = time.perf_counter()
                    tick()
                    samples.append(time.perf_counter() - t0)
                return statistics.median(samples)

            out[kind] = {
                "back_to_back": median_after(lambda: None),
                "after_10ms_asleep": median_after(lambda: time.sleep(0.010)),
                "after_10ms_polling": median_after(lambda: poll(0.010)),
                "after_9.5ms_asleep_and_a_warm_up_tick": median_after(lambda: (time.sleep(0.0095), tick())),
            }
    finally:
        sock.close()
    return out


def bench_batched_sim(repeats: int) -> dict[str, float]:
    out = {}
    cases = {
        "arena-b (6 drones x 512 arenas, open)": (circle_swap(6, 2.0), 512),
        "arena-a (6 drones x 256 arenas, 12 obstacles)": (arena_a(np.random.default_rng(0)), 256),
    }
    for label, (scenario, arenas) in cases.items():
        planner = Planner(scenario.obstacles, PlannerConfig.robust(), FixedGains())
        starts = np.broadcast_to(scenario.starts, (arenas, scenario.n_drones))
        goals = np.broadcast_to(scenario.goals, (arenas, scenario.n_drones))
        world = World(starts, goals, 0.5, 0.1, 0.1, scenario.arena_x, scenario.arena_y)

        def step() -> None:
            world.advance(planner.step(world.views(6.0)).direction)

        seconds = timed(step, 20, repeats)
        out[label] = arenas * scenario.n_drones / seconds
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--json", type=Path, default=None, help="also write the figures as JSON")
    parser.add_argument(
        "--cadence",
        action="store_true",
        help="only the flight tick at the flight's cadence (cold start after a sleep vs back to back)",
    )
    parser.add_argument(
        "--rpf3",
        action="store_true",
        help="only RPF-3 as shipped: per-drone step against the onnxruntime call, batched ticks",
    )
    args = parser.parse_args(argv)
    if args.rpf3:
        figures = bench_rpf3(args.repeats)
        print("RPF-3 (kind rpf3: guidance, margin 0.05, RPF-3's tuning), median; line: step <= 1.5x onnxruntime")
        for name, f in figures.items():
            if "step" in f:
                print(
                    f"  {name:14s} step {f['step'] * 1e6:7.1f} us, "
                    f"onnxruntime alone {f['onnxruntime_alone'] * 1e6:6.1f} us:"
                    f" {f['step'] / f['onnxruntime_alone']:.2f}x"
                )
            else:
                n = int(name.rsplit("_", 1)[1])
                print(
                    f"  {name:14s} {f['tick'] * 1e3:7.2f} ms, {f['tick'] / n * 1e6:5.1f} us a drone"
                    f" (line: 100 drones < 2 ms; the flight plans a worker's drones in one such call)"
                )
        if args.json:
            args.json.write_text(json.dumps({"rpf3_s": figures}, indent=2))
        return 0
    if args.cadence:
        cadence = bench_flight_tick_cadence()
        print("batched flight tick, 10 drones mid-flight, median wall time of single calls")
        for kind, figures in cadence.items():
            for label, seconds in figures.items():
                print(f"  {kind}: {label.replace('_', ' '):40s} {seconds * 1e6:7.0f} us")
        if args.json:
            args.json.write_text(json.dumps({"flight_tick_cadence_s": cadence}, indent=2))
        return 0

    per_drone = bench_per_drone(args.repeats)
    per_drone_rpf = bench_per_drone(args.repeats, "rpf")
    guidance = bench_guidance(args.repeats)
    ticks = {n: bench_tick(n, args.repeats) for n in (10, 100)}
    sim = bench_batched_sim(args.repeats)
    flight_tick = bench_flight_tick(args.repeats)

    print("per-drone plan step, fixed gains (median; goal <= 50 us)")
    for name, s in per_drone.items():
        print(f"  {name:14s} {s * 1e6:8.1f} us")
    print("per-drone plan step, ONNX policy policies/rpf.onnx (median; goal <= 100 us)")
    for name, s in per_drone_rpf.items():
        print(f"  {name:14s} {s * 1e6:8.1f} us")
    print("per-drone plan step of RPF with guidance path + margin 0.05, beside the onnxruntime call alone (median)")
    for name, g in guidance.items():
        print(
            f"  {name:14s} with guidance {g['with_guidance'] * 1e6:7.1f} us, "
            f"without {g['without_guidance'] * 1e6:7.1f} us,"
            f" onnxruntime alone {g['onnxruntime_alone'] * 1e6:6.1f} us"
            f": {g['with_guidance'] / g['onnxruntime_alone']:.2f}x"
            f" ({g['guided_views']:.0f} of {g['views']:.0f} drones with a hidden goal)"
        )
    print("one tick, every drone from its own view (goal: 100 drones <= 5 ms)")
    for n, t in ticks.items():
        print(
            f"  {n:3d} drones: one call per drone {t['per_drone_calls'] * 1e3:7.2f} ms"
            f" ({t['per_drone_calls'] / n * 1e6:.1f} us/drone), batched {t['batched'] * 1e3:6.2f} ms"
        )
    print("flight planning tick, 10 drones mid-flight (rpf_fly.flight.swarm_plan, hot caches)")
    for kind, t in flight_tick.items():
        print(
            f"  {kind}: batched {t['batched'] * 1e6:7.1f} us ({t['batched'] / 10 * 1e6:.1f} us/drone), "
            f"one call per drone {t['one_call_per_drone'] * 1e6:7.1f} us"
        )
    print("batched simulation throughput (goal >= 1M robot-steps/s)")
    for label, rate in sim.items():
        print(f"  {label:48s} {rate / 1e6:6.2f} M robot-steps/s")
    if args.json:
        args.json.write_text(
            json.dumps(
                {
                    "per_drone_step_s": per_drone,
                    "per_drone_step_rpf_onnx_s": per_drone_rpf,
                    "per_drone_step_rpf_guidance_s": guidance,
                    "tick_s": {str(n): t for n, t in ticks.items()},
                    "flight_tick_10_drones_s": flight_tick,
                    "batched_sim_robot_steps_per_s": sim,
                    "python": sys.version.split()[0],
                    "numpy": np.__version__,
                },
                indent=2,
            )
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
