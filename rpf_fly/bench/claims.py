"""The paper's claims, judged on bench results (the results JSON: ``rows`` and ``runs``).

Each claim comes back ``held``, ``not held`` or ``not evaluated`` (a planner or scene it needs was not run or its
policy is missing), with the numbers it was judged on. Rules (docs/bench.md):

- path metrics are means over *successful* runs (lower is better for travel distance and smoothness);
- (a) circle-8-r3: RPF-1's travel distance and smoothness are both below RPF-2's and APF's. A competitor without
  any successful run counts as beaten (it never completed the swap);
- (b) circle-8-r8: PPO fails (collision, stall or timeout) on a seed where RPF-1 succeeds, for at least half of
  the seeds both ran;
- (c) lab-3: among the paper's planners (RPF-1, RPF-2, PPO, APF; ORCA is reported beside it) that succeed on at
  least half of the seeds, RPF-1 (which must be one of them)
  has the lowest travel distance and the lowest smoothness (ties count as best);
- (d) RPF-1 succeeds on at least 98 % of all seeded runs of the five paper missions together, with zero collisions;
- (e) the same on the fresh arena-A scenes.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from rpf_fly.bench.runner import FRESH_SCENE, PAPER_MISSIONS, PLANNER_LABELS

SUCCESS_TARGET = 0.98
"""(d), (e): the fraction of runs RPF-1 must succeed on."""
MAJORITY = 0.5
"""(b): fraction of seeds on which PPO must fail where RPF-1 succeeds; (c): success rate that makes a planner
'successful' on lab-3."""

HELD = "held"
NOT_HELD = "not held"
NOT_EVALUATED = "not evaluated"


@dataclass(frozen=True)
class Claim:
    """One judged claim: ``status`` is held, not held or not evaluated; ``numbers`` what it was judged on."""

    id: str
    statement: str
    status: str
    numbers: dict[str, Any] = field(default_factory=dict)
    note: str = ""

    @property
    def held(self) -> bool | None:
        return None if self.status == NOT_EVALUATED else self.status == HELD

    def to_json_dict(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "statement": self.statement,
            "status": self.status,
            "held": self.held,
            "numbers": self.numbers,
            "note": self.note,
        }


STATEMENTS = {
    "a": "circle-8-r3: RPF-1 beats RPF-2 and APF on travel distance and smoothness",
    "b": "circle-8-r8: PPO fails (collision or timeout) where RPF-1 succeeds",
    "c": "lab-3: RPF-1 has the best travel distance and smoothness among the successful planners",
    "d": f"RPF-1 succeeds on >= {SUCCESS_TARGET:.0%} of the seeded runs of the five paper missions, zero collisions",
    "e": f"RPF-1 succeeds on >= {SUCCESS_TARGET:.0%} of the fresh arena-A scenes, zero collisions",
}


@dataclass(frozen=True)
class ClaimScenes:
    """Where each claim is judged. (a), (b), (c) on each scene of their tuple (held when held on every one that
    ran, judged per scene); (d) pooled over its scenes; (e) pooled over its scenes. ``statements`` as printed.
    ``only_run``: judge on the listed scenes that ran (the families suite may run a subset); else every listed
    scene is needed (the paper suite)."""

    a: tuple[str, ...]
    b: tuple[str, ...]
    c: tuple[str, ...]
    d: tuple[str, ...]
    e: tuple[str, ...]
    statements: Mapping[str, str]
    only_run: bool = False


PAPER_CLAIMS = ClaimScenes(("circle-8-r3",), ("circle-8-r8",), ("lab-3",), PAPER_MISSIONS, (FRESH_SCENE,), STATEMENTS)
"""The paper suite: each claim on the scene the paper states it for."""

SWAP_FAMILIES = ("circle", "arena-b")
OBSTACLE_FAMILIES = ("corridor", "doorway", "u-trap", "pillars", "passage", "arena-a")
ALL_FAMILIES = ("corridor", "doorway", "u-trap", "pillars", "crossing", "circle", "arena-a", "arena-b", "passage")
FAMILY_CLAIMS = ClaimScenes(
    a=SWAP_FAMILIES,
    b=("circle",),
    c=OBSTACLE_FAMILIES,
    d=ALL_FAMILIES,
    e=("arena-a",),
    statements={
        "a": "circle swaps (circle, arena-b): RPF-1 beats RPF-2 and APF on travel distance and smoothness",
        "b": "circle swaps of 8-24 drones: PPO fails (collision or timeout) where RPF-1 succeeds",
        "c": "obstacle families (corridor, doorway, u-trap, pillars, passage, arena-a): RPF-1 has the best travel "
        "distance and smoothness among the successful planners",
        "d": f"RPF-1 succeeds on >= {SUCCESS_TARGET:.0%} of the runs of all families pooled, zero collisions",
        "e": f"RPF-1 succeeds on >= {SUCCESS_TARGET:.0%} of the fresh arena-A family scenes, zero collisions",
    },
    only_run=True,
)
"""The families suite (docs/bench.md, *Scene families*): (a) on the swap families, (b) on the large circle swaps
(the paper's circle-8-r8), (c) on every obstacle family (the paper's lab-3 is one cluttered scene), (d) on all
families pooled, (e) on the arena-A family."""


def evaluate_claims(results: Mapping[str, Any], scenes: ClaimScenes = PAPER_CLAIMS) -> list[Claim]:
    """Judge claims (a)-(e) on a results dict (``rows``: summary rows; ``runs``: per-run records)."""
    table = _Rows(results)
    if scenes == PAPER_CLAIMS:
        return [_claim_a(table), _claim_b(table), _claim_c(table), _claim_d(table), _claim_e(table)]
    out = []
    for claim, judge in (("a", _claim_a), ("b", _claim_b), ("c", _claim_c)):
        out.append(_per_scene(table, claim, getattr(scenes, claim), scenes, judge))
    for claim in ("d", "e"):
        wanted = getattr(scenes, claim)
        ran = [s for s in wanted if table.row("rpf", s) is not None] if scenes.only_run else list(wanted)
        if not ran:
            out.append(
                Claim(claim, scenes.statements[claim], NOT_EVALUATED, note="RPF-1 ran on none of " + ", ".join(wanted))
            )
            continue
        judged = _success_claim(table, claim, tuple(ran))
        note = judged.note + ("" if len(ran) == len(wanted) else f"; judged on {', '.join(ran)} only")
        out.append(replace(judged, statement=scenes.statements[claim], note=note))
    return out


def _per_scene(t: _Rows, claim: str, wanted: tuple[str, ...], scenes: ClaimScenes, judge) -> Claim:
    """A scene claim judged on every wanted scene: held when held on each that was evaluated."""
    parts = {scene: judge(t, scene) for scene in wanted}
    if scenes.only_run:
        parts = {s: c for s, c in parts.items() if c.status != NOT_EVALUATED} or parts
    statement = scenes.statements[claim]
    statuses = {c.status for c in parts.values()}
    if NOT_EVALUATED in statuses:
        return Claim(
            claim,
            statement,
            NOT_EVALUATED,
            note="; ".join(f"{s}: {c.note}" for s, c in parts.items() if c.status == NOT_EVALUATED),
        )
    status = HELD if statuses == {HELD} else NOT_HELD
    numbers = {s: c.numbers for s, c in parts.items()}
    note = "; ".join(f"{s}: {c.status}" + (f" ({c.note})" if c.note else "") for s, c in parts.items())
    missing = [s for s in wanted if s not in parts]
    if missing:
        note += f"; not run: {', '.join(missing)}"
    return Claim(claim, statement, status, numbers, note)


class _Rows:
    def __init__(self, results: Mapping[str, Any]):
        self.rows = {(r["planner"], r["scene"]): r for r in results.get("rows", [])}
        self.runs = list(results.get("runs", []))

    def row(self, planner: str, scene: str) -> Mapping[str, Any] | None:
        """The row if it ran (status ok with at least one run), else None."""
        r = self.rows.get((planner, scene))
        return r if r is not None and r.get("status") == "ok" and r.get("runs", 0) > 0 else None

    def ran(self, planner: str, scene: str) -> Mapping[str, Any]:
        """The row of a planner the caller knows ran (checked with :meth:`row`, or one of :meth:`planners`)."""
        r = self.row(planner, scene)
        if r is None:
            raise KeyError(f"{planner} on {scene}: no run")
        return r

    def why_missing(self, planner: str, scene: str) -> str:
        r = self.rows.get((planner, scene))
        name = f"{PLANNER_LABELS.get(planner, planner)} on {scene}"
        if r is None:
            return f"{name} was not run"
        return f"{name} is missing: {r.get('reason')}" if r.get("status") == "missing" else f"{name} has no runs"

    def planners(self, scene: str) -> list[str]:
        return [p for (p, s) in self.rows if s == scene and self.row(p, s) is not None]


def _mean(row: Mapping[str, Any], metric: str) -> float | None:
    s = row.get(metric, {}).get("successful")
    return None if s is None else float(s["mean"])


def _not_evaluated(claim: str, reasons: list[str]) -> Claim:
    return Claim(claim, STATEMENTS[claim], NOT_EVALUATED, note="; ".join(reasons))


def _claim_a(t: _Rows, scene: str = "circle-8-r3") -> Claim:
    needed = ("rpf", "rpf-mean", "apf")
    absent = [t.why_missing(p, scene) for p in needed if t.row(p, scene) is None]
    if absent:
        return _not_evaluated("a", absent)
    numbers = {
        PLANNER_LABELS[p]: {
            "travel_distance_m": _mean(t.ran(p, scene), "travel_distance_m"),
            "smoothness": _mean(t.ran(p, scene), "smoothness"),
            "success_rate": t.ran(p, scene)["success_rate"],
        }
        for p in needed
    }
    mine = numbers["RPF-1"]
    if mine["travel_distance_m"] is None:
        return Claim("a", STATEMENTS["a"], NOT_HELD, numbers, "RPF-1 has no successful run")
    notes, held = [], True
    for other in ("RPF-2", "APF"):
        theirs = numbers[other]
        if theirs["travel_distance_m"] is None:
            notes.append(f"{other} has no successful run (counts as beaten)")
            continue
        for metric in ("travel_distance_m", "smoothness"):
            if not mine[metric] < theirs[metric]:
                held = False
                notes.append(f"{metric}: RPF-1 {mine[metric]:.4g} >= {other} {theirs[metric]:.4g}")
    return Claim("a", STATEMENTS["a"], HELD if held else NOT_HELD, numbers, "; ".join(notes))


def _claim_b(t: _Rows, scene: str = "circle-8-r8") -> Claim:
    absent = [t.why_missing(p, scene) for p in ("rpf", "ppo") if t.row(p, scene) is None]
    if absent:
        return _not_evaluated("b", absent)
    runs = {(r["planner"], r["seed"]): r for r in t.runs if r["scene"] == scene}
    seeds = sorted({s for (p, s) in runs if p == "rpf"} & {s for (p, s) in runs if p == "ppo"})
    if not seeds:
        return _not_evaluated("b", ["no seed was run by both RPF-1 and PPO (per-run records missing)"])
    paired = [s for s in seeds if runs[("rpf", s)]["success"] and not runs[("ppo", s)]["success"]]
    causes: dict[str, int] = {}
    for s in seeds:
        failure = runs[("ppo", s)].get("failure")
        if failure:
            causes[failure] = causes.get(failure, 0) + 1
    numbers = {
        "seeds": len(seeds),
        "rpf1_succeeds_ppo_fails": len(paired),
        "RPF-1 success_rate": t.ran("rpf", scene)["success_rate"],
        "PPO success_rate": t.ran("ppo", scene)["success_rate"],
        "PPO failures": causes,
    }
    held = len(paired) > 0 and len(paired) >= MAJORITY * len(seeds)
    note = f"PPO failed where RPF-1 succeeded on {len(paired)} of {len(seeds)} seeds (needs >= {MAJORITY:.0%})"
    return Claim("b", STATEMENTS["b"], HELD if held else NOT_HELD, numbers, note)


PAPER_PLANNERS = ("rpf", "rpf-mean", "ppo", "apf")
"""The planners of the paper's comparison; others (ORCA) are reported beside claim (c), not judged in it."""


def _claim_c(t: _Rows, scene: str = "lab-3") -> Claim:
    if t.row("rpf", scene) is None:
        return _not_evaluated("c", [t.why_missing("rpf", scene)])
    everyone = t.planners(scene)
    planners = [p for p in everyone if p in PAPER_PLANNERS]  # the paper compares RPF-1, RPF-2, PPO and APF
    numbers = {
        PLANNER_LABELS.get(p, p): {
            "success_rate": t.ran(p, scene)["success_rate"],
            "travel_distance_m": _mean(t.ran(p, scene), "travel_distance_m"),
            "smoothness": _mean(t.ran(p, scene), "smoothness"),
        }
        for p in planners
    }
    successful = [name for name, n in numbers.items() if n["success_rate"] >= MAJORITY]
    if "RPF-1" not in successful:
        return Claim(
            "c", STATEMENTS["c"], NOT_HELD, numbers, f"RPF-1 succeeds on fewer than {MAJORITY:.0%} of {scene} runs"
        )
    notes, held = [f"successful planners: {', '.join(successful)}"], True
    for metric in ("travel_distance_m", "smoothness"):
        best = min(successful, key=lambda name: numbers[name][metric])
        if numbers[best][metric] < numbers["RPF-1"][metric]:
            held = False
            notes.append(f"{metric}: {best} {numbers[best][metric]:.4g} < RPF-1 {numbers['RPF-1'][metric]:.4g}")
    for extra in (p for p in everyone if p not in PAPER_PLANNERS):  # beyond the paper: reported, not judged
        row = t.ran(extra, scene)
        label = PLANNER_LABELS.get(extra, extra)
        travel, smooth = _mean(row, "travel_distance_m"), _mean(row, "smoothness")
        notes.append(
            f"beyond the paper, {label}: success {row['success_rate']:.0%}, travel "
            f"{travel if travel is None else round(travel, 3)}, smoothness "
            f"{smooth if smooth is None else round(smooth, 4)}"
        )
    return Claim("c", STATEMENTS["c"], HELD if held else NOT_HELD, numbers, "; ".join(notes))


def _success_claim(t: _Rows, claim: str, scenes: tuple[str, ...]) -> Claim:
    absent = [t.why_missing("rpf", s) for s in scenes if t.row("rpf", s) is None]
    if absent:
        return _not_evaluated(claim, absent)
    per_scene = {}
    runs = successes = collisions = 0
    for scene in scenes:
        row = t.row("rpf", scene)
        assert row is not None
        per_scene[scene] = {
            "success_rate": row["success_rate"],
            "runs": row["runs"],
            "collisions": row["collisions"]["total"],
        }
        runs += row["runs"]
        successes += row["successes"]
        collisions += row["collisions"]["total"]
    rate = successes / runs
    numbers = {
        "runs": runs,
        "successes": successes,
        "success_rate": rate,
        "collisions": collisions,
        "per_scene": per_scene,
    }
    held = rate >= SUCCESS_TARGET and collisions == 0
    note = f"{successes}/{runs} = {rate:.1%} (needs >= {SUCCESS_TARGET:.0%}), {collisions} collisions (needs 0)"
    return Claim(claim, STATEMENTS[claim], HELD if held else NOT_HELD, numbers, note)


def _claim_d(t: _Rows) -> Claim:
    return _success_claim(t, "d", PAPER_MISSIONS)


def _claim_e(t: _Rows) -> Claim:
    return _success_claim(t, "e", (FRESH_SCENE,))
