"""The paper's comparison: planners x scenes x seeds, each run scored by :mod:`rpf_fly.sim.evaluate`.

Scenes are the five paper missions (``missions/<name>.yaml``, seeds ``0..N-1`` draw each mission's start jitter)
and ``arena-a-fresh``: training-arena-A scenes generated from seeds ``1_000_000 + i``, a range the trainer never
draws (its scenes come from its own generator seeded with the training seed). Planners: ``rpf`` (RPF-1,
attention), ``rpf-mean`` (RPF-2), ``apf`` (robust fixed gains), ``ppo`` (heading policy), ``orca`` and ``rpf3``
(RPF-3, the product's default planner, with its guidance, margin and tuning). The
learned kinds load ``<policies>/<kind>.onnx`` or a path given per kind; an absent or unusable policy makes that
planner's rows ``missing`` with the reason.

``dynamics``: ``kinematic`` (the default) flies the kinematic world (rpf_fly.sim.rollout); ``firmware`` flies the
firmware's PID cascade on the identified Crazyflie body in the flight's closed loop (rpf_fly.sim.closed_loop), all
seeds of a (planner, scene) in one simulated swarm.

Computation only: :mod:`rpf_fly.bench.report` prints and writes, :mod:`rpf_fly.bench.figure` draws,
:mod:`rpf_fly.bench.claims` judges the paper's claims. No torch.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rpf_fly.mission.model import Mission, Obstacle, PlannerSettings
from rpf_fly.sim.closed_loop import DYNAMICS, FirmwareParams
from rpf_fly.sim.evaluate import Run, planner_settings, run_scenario, sim_params
from rpf_fly.sim.rollout import DroneOutcome, SimParams
from rpf_fly.sim.scenario import Scenario, arena_a, scenario_from_mission

PLANNERS = ("rpf", "rpf-mean", "apf", "ppo", "orca", "rpf3")
"""Bench planner kinds, in table order: the paper's, then RPF-3 (the product's default, judged in no paper claim)."""
PLANNER_LABELS = {"rpf": "RPF-1", "rpf-mean": "RPF-2", "apf": "APF", "ppo": "PPO", "orca": "ORCA", "rpf3": "RPF-3"}
PAPER_MISSIONS = ("arena-a-6", "arena-b-6", "circle-8-r3", "circle-8-r8", "lab-3")
FRESH_SCENE = "arena-a-fresh"
SCENES = PAPER_MISSIONS + (FRESH_SCENE,)
FRESH_SEED_BASE = 1_000_000
"""Fresh arena-A scenes use seeds ``FRESH_SEED_BASE + i``: never used in training."""
TRAJECTORY_SCENES = ("circle-8-r3", "circle-8-r8", "lab-3")
"""Scenes whose seed-0 trajectories the figure draws."""
POLICY_ACTIONS = {"rpf": "gains", "rpf-mean": "gains", "ppo": "heading", "rpf3": "gains"}
"""Learned kinds and the action their ONNX policy must have."""


@dataclass(frozen=True)
class BenchConfig:
    """What to run. ``episodes``: seeds per scene; ``policy_paths``: per-kind ONNX files overriding
    ``<policies_dir>/<kind>.onnx``; ``missions_dir``: where the paper missions live; ``dynamics``: one of
    :data:`~rpf_fly.sim.closed_loop.DYNAMICS`."""

    planners: tuple[str, ...] = PLANNERS
    scenes: tuple[str, ...] = SCENES
    episodes: int = 20
    policies_dir: Path = Path("policies")
    policy_paths: Mapping[str, Path] = field(default_factory=dict)
    missions_dir: Path = Path("missions")
    trajectory_scenes: tuple[str, ...] = TRAJECTORY_SCENES
    dynamics: str = "kinematic"

    def seeds(self, scene: str) -> list[int]:
        """The seeds of ``scene``: start jitter seeds ``0..N-1`` for missions, generator seeds for fresh scenes."""
        base = FRESH_SEED_BASE if scene == FRESH_SCENE else 0
        return list(range(base, base + self.episodes))


@dataclass(frozen=True)
class RunRecord:
    """One run's figures (the metrics JSON's headline fields) and how its drones ended.

    ``failure``: None for a success, else the run's cause: ``collision`` (any collision), ``stalled`` (a drone
    stuck in a local minimum), or ``timeout`` (a drone still progressing at the time limit).
    """

    planner: str
    scene: str
    seed: int
    drones: int
    reached: int
    success: bool
    collisions_drone_drone: int
    collisions_drone_obstacle: int
    travel_distance_m: float | None
    smoothness: float | None
    makespan_s: float | None
    min_separation_m: float | None
    min_obstacle_clearance_m: float | None
    outcomes: dict[str, int]
    failure: str | None

    @property
    def collisions(self) -> int:
        return self.collisions_drone_drone + self.collisions_drone_obstacle

    def to_json_dict(self) -> dict[str, Any]:
        return {
            "planner": self.planner,
            "scene": self.scene,
            "seed": self.seed,
            "drones": self.drones,
            "reached": self.reached,
            "success": self.success,
            "collisions": {
                "drone_drone": self.collisions_drone_drone,
                "drone_obstacle": self.collisions_drone_obstacle,
            },
            "travel_distance_m": _round(self.travel_distance_m),
            "smoothness": _round(self.smoothness, 6),
            "makespan_s": _round(self.makespan_s, 2),
            "min_separation_m": _round(self.min_separation_m),
            "min_obstacle_clearance_m": _round(self.min_obstacle_clearance_m),
            "outcomes": dict(self.outcomes),
            "failure": self.failure,
        }


@dataclass(frozen=True)
class Trajectory:
    """A run's XY tracks for the figure: ``positions`` ``(T+1, N)`` complex, metres."""

    planner: str
    scene: str
    seed: int
    positions: np.ndarray
    goals: np.ndarray
    shapes: tuple[Obstacle, ...]
    arena_x: tuple[float, float]
    arena_y: tuple[float, float]
    success: bool
    reached: int
    collisions: int


@dataclass(frozen=True)
class PolicyInfo:
    """A learned kind's policy: its file and hash, or why it cannot be used (``missing``)."""

    kind: str
    path: Path
    sha256: str | None = None
    missing: str | None = None

    def to_json_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"path": str(self.path)}
        if self.missing:
            out["missing"] = self.missing
        else:
            out["sha256"] = self.sha256
        return out


@dataclass(frozen=True)
class BenchPlan:
    """A checked configuration: loaded missions, resolved policies, and the reason for every missing
    (planner, scene) pair. ``total_runs`` counts the runs that will actually happen."""

    config: BenchConfig
    missions: dict[str, Mission]
    policies: dict[str, PolicyInfo]
    missing: dict[tuple[str, str], str]

    @property
    def total_runs(self) -> int:
        pairs = [(p, s) for p in self.config.planners for s in self.config.scenes if (p, s) not in self.missing]
        return len(pairs) * self.config.episodes


@dataclass(frozen=True)
class BenchResult:
    """Every run, the per-(planner, scene) summary rows, the policies used and the figure's trajectories."""

    config: BenchConfig
    runs: list[RunRecord]
    rows: list[dict[str, Any]]
    policies: dict[str, PolicyInfo]
    trajectories: list[Trajectory]

    def to_json_dict(self) -> dict[str, Any]:
        """The results JSON (claims are added by :func:`rpf_fly.bench.report.results_json`)."""
        c = self.config
        return {
            "bench": "rpf-fly bench",
            "version": 1,
            "dynamics": c.dynamics,
            **closed_loop_json(c.dynamics),
            "episodes": c.episodes,
            "planners": list(c.planners),
            "scenes": list(c.scenes),
            "seeds": {
                scene: {"first": c.seeds(scene)[0], "count": c.episodes} if c.episodes else {"first": None, "count": 0}
                for scene in c.scenes
            },
            "policies": {kind: info.to_json_dict() for kind, info in self.policies.items()},
            "rows": self.rows,
            "runs": [r.to_json_dict() for r in self.runs],
        }


class BenchError(ValueError):
    """An unknown planner or scene, or a non-positive episode count."""


def prepare(config: BenchConfig) -> BenchPlan:
    """Check names, load the missions and the policies; record what is missing instead of failing."""
    from rpf_fly.mission import MissionError, load_mission

    unknown = [p for p in config.planners if p not in PLANNERS]
    if unknown:
        raise BenchError(f"unknown planner {unknown[0]!r} (expected some of {', '.join(PLANNERS)})")
    unknown = [s for s in config.scenes if s not in SCENES]
    if unknown:
        raise BenchError(f"unknown scene {unknown[0]!r} (expected some of {', '.join(SCENES)})")
    if config.episodes < 1:
        raise BenchError(f"episodes must be at least 1, got {config.episodes}")
    check_dynamics(config.dynamics)
    missing: dict[tuple[str, str], str] = {}
    missions: dict[str, Mission] = {}
    for scene in config.scenes:
        if scene == FRESH_SCENE:
            continue
        path = Path(config.missions_dir) / f"{scene}.yaml"
        try:
            missions[scene] = load_mission(path)
        except (MissionError, OSError) as err:
            for planner in config.planners:
                missing[(planner, scene)] = f"mission {path}: {err}"
    policies: dict[str, PolicyInfo] = {}
    for kind in config.planners:
        if kind not in POLICY_ACTIONS:
            continue
        info = load_policy_info(kind, config.policy_paths.get(kind) or Path(config.policies_dir) / f"{kind}.onnx")
        policies[kind] = info
        if info.missing:
            for scene in config.scenes:
                missing.setdefault((kind, scene), info.missing)
    return BenchPlan(config, missions, policies, missing)


def load_policy_info(kind: str, path: Path) -> PolicyInfo:
    """Whether ``path`` is a usable policy for ``kind`` (exists, loads in onnxruntime, has the right action)."""
    from rpf_fly.planning.onnx_policy import OnnxPolicy, PolicyError

    path = Path(path)
    if not path.is_file():
        return PolicyInfo(kind, path, missing=f"no policy file {path}")
    try:
        policy = OnnxPolicy(path)
    except PolicyError as err:
        return PolicyInfo(kind, path, missing=str(err))
    if policy.action != POLICY_ACTIONS[kind]:
        return PolicyInfo(kind, path, missing=f"{path}: a {policy.action!r} policy cannot drive planner {kind!r}")
    return PolicyInfo(kind, path.resolve(), sha256=hashlib.sha256(path.read_bytes()).hexdigest())


def run_bench(plan: BenchPlan, on_run: Callable[[RunRecord], None] | None = None) -> BenchResult:
    """Run every available (planner, scene, seed); ``on_run`` is called after each run (progress)."""
    config = plan.config
    runs: list[RunRecord] = []
    rows: list[dict[str, Any]] = []
    trajectories: list[Trajectory] = []
    for scene in config.scenes:
        for kind in config.planners:
            reason = plan.missing.get((kind, scene))
            if reason is not None:
                rows.append(missing_row(kind, scene, reason))
                continue
            info = plan.policies.get(kind)
            policy = info.path if info is not None else None
            scene_runs = []
            for seed, run, scenario in _runs(plan, kind, policy, scene):
                assert run.rollout is not None
                record = _record(run, kind, scene)
                scene_runs.append(record)
                if on_run is not None:
                    on_run(record)
                if scene in config.trajectory_scenes and seed == config.seeds(scene)[0]:
                    trajectories.append(_trajectory(record, scenario, run.rollout.positions))
            runs.extend(scene_runs)
            rows.append(summarise_runs(kind, scene, scene_runs))
    return BenchResult(config, runs, rows, dict(plan.policies), trajectories)


def _runs(plan: BenchPlan, kind: str, policy: Path | None, scene: str) -> Iterator[tuple[int, Run, Scenario]]:
    """The runs of one (planner, scene), seed by seed: one kinematic rollout at a time, or every seed flown
    together on the firmware model."""
    seeds = plan.config.seeds(scene)
    setups = [_setup(plan, kind, policy, scene, seed) for seed in seeds]
    if plan.config.dynamics == "kinematic":
        for seed, (scenario, settings, params, _) in zip(seeds, setups):
            yield seed, run_scenario(scenario, settings, params, seed, scene, keep=True), scenario
        return
    from rpf_fly.sim.closed_loop import run_firmware

    _, settings, params, firmware = setups[0]  # the same for every seed of a (planner, scene)
    scenarios = [s[0] for s in setups]
    batch = run_firmware(scenarios, settings, params, seeds, [scene] * len(seeds), firmware, keep=True)
    yield from zip(seeds, batch, scenarios)


def _setup(
    plan: BenchPlan, kind: str, policy: Path | None, scene: str, seed: int
) -> tuple[Scenario, PlannerSettings, SimParams, FirmwareParams]:
    """A run's scene, planner settings, kinematics and the closed loop's flight height (the mission's)."""
    from rpf_fly.mission import with_planner

    if scene == FRESH_SCENE:
        scenario = arena_a(np.random.default_rng(seed))
        return scenario, planner_settings(kind, policy), SimParams(), FirmwareParams()
    chosen = with_planner(plan.missions[scene], kind, policy)
    firmware = FirmwareParams(chosen.flight.height, tuple(chosen.arena.z))
    return scenario_from_mission(chosen, seed), chosen.planner, sim_params(chosen), firmware


def check_dynamics(dynamics: str) -> None:
    """Raise :class:`BenchError` unless ``dynamics`` is one of :data:`~rpf_fly.sim.closed_loop.DYNAMICS`."""
    if dynamics not in DYNAMICS:
        raise BenchError(f"unknown dynamics {dynamics!r} (expected {' or '.join(DYNAMICS)})")


def dynamics_line(results: Mapping[str, Any]) -> str:
    """One line (under 110 columns) saying which dynamics a results document's runs flew (``kinematic`` where it
    does not say: written before the closed loop)."""
    if results.get("dynamics", "kinematic") != "firmware":
        return "Dynamics: kinematic (every drone moves along its planned heading at the mission speed)."
    loop = results.get("closed_loop", {})
    views = "; planners on the true state" if loop.get("plan_from") == "truth" else ""
    return (
        f"Dynamics: firmware (the flight's closed loop on the Crazyflie firmware model; safety on "
        f"{loop.get('truth_hz', 100)} Hz truth{views})."
    )


def closed_loop_json(dynamics: str, f: FirmwareParams = FirmwareParams()) -> dict[str, Any]:
    """Beside ``"dynamics"`` in the results: for ``firmware``, ``closed_loop``, the closed loop's settings common to
    every run (the flight height is each mission's); nothing for ``kinematic``."""
    if dynamics != "firmware":
        return {}
    from rpf_fly.sim.closed_loop import STEP_S

    return {
        "closed_loop": {
            "truth_hz": round(1.0 / STEP_S),
            "settle_s": f.settle_s,
            "hold_tail_s": f.hold_tail_s,
            "plan_from": f.plan_from,
        }
    }


def _record(run: Run, kind: str, scene: str) -> RunRecord:
    m = run.metrics
    assert run.rollout is not None
    outcomes = {o.value: 0 for o in DroneOutcome}
    for outcome in run.rollout.outcomes:
        outcomes[outcome.value] += 1
    collisions = m.collisions_drone_drone + m.collisions_drone_obstacle
    if m.success:
        failure = None
    elif collisions:
        failure = "collision"
    elif outcomes[DroneOutcome.STALLED.value]:
        failure = "stalled"
    else:
        failure = "timeout"
    return RunRecord(
        planner=kind,
        scene=scene,
        seed=run.seed,
        drones=m.drones,
        reached=m.reached,
        success=m.success,
        collisions_drone_drone=m.collisions_drone_drone,
        collisions_drone_obstacle=m.collisions_drone_obstacle,
        travel_distance_m=m.travel_distance_m,
        smoothness=m.smoothness,
        makespan_s=m.makespan_s,
        min_separation_m=m.min_separation_m,
        min_obstacle_clearance_m=m.min_obstacle_clearance_m,
        outcomes=outcomes,
        failure=failure,
    )


def _trajectory(record: RunRecord, scenario: Scenario, positions: np.ndarray) -> Trajectory:
    return Trajectory(
        planner=record.planner,
        scene=record.scene,
        seed=record.seed,
        positions=np.asarray(positions).copy(),
        goals=scenario.goals.copy(),
        shapes=scenario.shapes,
        arena_x=scenario.arena_x,
        arena_y=scenario.arena_y,
        success=record.success,
        reached=record.reached,
        collisions=record.collisions,
    )


# -- summaries -----------------------------------------------------------------------------------------------------

METRICS = ("travel_distance_m", "smoothness", "makespan_s")
"""Path metrics summarised as mean +- std, over successful runs and over all runs where defined."""


def stat(values: Sequence[float | None]) -> dict[str, float] | None:
    """``{"mean", "std", "n"}`` over the defined values (population std), None when there are none."""
    defined = [float(v) for v in values if v is not None]
    if not defined:
        return None
    return {"mean": float(np.mean(defined)), "std": float(np.std(defined)), "n": len(defined)}


def summarise_runs(planner: str, scene: str, runs: Sequence[RunRecord]) -> dict[str, Any]:
    """The row of one (planner, scene): rates, collisions, path metrics, outcomes and failure causes."""
    successful = [r for r in runs if r.success]
    row: dict[str, Any] = {
        "planner": planner,
        "scene": scene,
        "status": "ok",
        "reason": None,
        "runs": len(runs),
        "successes": len(successful),
        "success_rate": len(successful) / len(runs) if runs else None,
        "collisions": {
            "drone_drone": sum(r.collisions_drone_drone for r in runs),
            "drone_obstacle": sum(r.collisions_drone_obstacle for r in runs),
            "total": sum(r.collisions for r in runs),
            "runs_with_collision": sum(1 for r in runs if r.collisions),
        },
        "reached_rate": (sum(r.reached for r in runs) / sum(r.drones for r in runs)) if runs else None,
    }
    for metric in METRICS:
        row[metric] = {
            "successful": stat([getattr(r, metric) for r in successful]),
            "all": stat([getattr(r, metric) for r in runs]),
        }
    row["outcomes"] = {o.value: sum(r.outcomes.get(o.value, 0) for r in runs) for o in DroneOutcome}
    row["failed_runs"] = {
        cause: sum(1 for r in runs if r.failure == cause) for cause in ("collision", "stalled", "timeout")
    }
    return row


def missing_row(planner: str, scene: str, reason: str) -> dict[str, Any]:
    """The row of a (planner, scene) that could not run."""
    return {"planner": planner, "scene": scene, "status": "missing", "reason": reason, "runs": 0}


def _round(value: float | None, digits: int = 4) -> float | None:
    return None if value is None else round(float(value), digits)
