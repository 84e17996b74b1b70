"""The paper's comparison bench: planners x scenes x seeds (runner), the table, JSON and Markdown (report), the
figure (figure) and the paper's claims judged on the results (claims). See docs/bench.md."""

from rpf_fly.bench.claims import Claim, evaluate_claims
from rpf_fly.bench.runner import (
    FRESH_SCENE,
    FRESH_SEED_BASE,
    PAPER_MISSIONS,
    PLANNERS,
    SCENES,
    BenchConfig,
    BenchError,
    BenchPlan,
    BenchResult,
    RunRecord,
    prepare,
    run_bench,
)

__all__ = [
    "FRESH_SCENE",
    "FRESH_SEED_BASE",
    "PAPER_MISSIONS",
    "PLANNERS",
    "SCENES",
    "BenchConfig",
    "BenchError",
    "BenchPlan",
    "BenchResult",
    "Claim",
    "RunRecord",
    "evaluate_claims",
    "prepare",
    "run_bench",
]
