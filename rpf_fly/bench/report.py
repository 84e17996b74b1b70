"""Bench results as a rich table, a JSON document and Markdown (claims included). Formatting only."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Mapping, Optional, Sequence

from rpf_fly.bench.claims import Claim, evaluate_claims
from rpf_fly.bench.runner import PLANNER_LABELS, BenchResult


def results_json(result: BenchResult) -> dict[str, Any]:
    """The results document: settings, policies, summary rows, per-run records and the judged claims."""
    doc = result.to_json_dict()
    doc["claims"] = [c.to_json_dict() for c in evaluate_claims(doc)]
    return doc


def dumps(results: Mapping[str, Any]) -> str:
    """The results as indented JSON with one line per run record (the runs are most of the document)."""
    runs = results.get("runs")
    if not isinstance(runs, list) or not runs:
        return json.dumps(results, indent=1)
    marker = "\u0000runs\u0000"
    text = json.dumps({**results, "runs": marker}, indent=1)
    lines = ",\n".join("  " + json.dumps(run, separators=(", ", ": ")) for run in runs)
    return text.replace(json.dumps(marker), "[\n" + lines + "\n ]")


def write_json(results: Mapping[str, Any], path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(dumps(results) + "\n")
    return path


def claims_of(results: Mapping[str, Any]) -> list[Claim]:
    """The claims of a results document (re-judged from its rows and runs)."""
    return evaluate_claims(results)


def fmt_stat(s: Optional[Mapping[str, float]], digits: int = 2, n: bool = False, sep: str = " ± ") -> str:
    """``mean ± std`` (and the count with ``n``), ``-`` when undefined."""
    if s is None:
        return "-"
    text = f"{s['mean']:.{digits}f}{sep}{s['std']:.{digits}f}"
    return f"{text} ({s['n']})" if n else text


def _rate(value: Optional[float]) -> str:
    return "-" if value is None else f"{value:.0%}"


def _label(planner: str) -> str:
    return PLANNER_LABELS.get(planner, planner)


METRIC_DIGITS = {"travel_distance_m": 2, "smoothness": 4, "makespan_s": 1}


def _cells(row: Mapping[str, Any]) -> dict[str, str]:
    """Formatted cells of an ok row."""
    c = row["collisions"]
    f = row["failed_runs"]
    o = row["outcomes"]
    cells = {
        "success": f"{_rate(row['success_rate'])} ({row['successes']}/{row['runs']})",
        "collisions": f"{c['total']} ({c['drone_drone']} dd, {c['drone_obstacle']} do)" if c["total"] else "0",
        "reached": _rate(row["reached_rate"]),
        "failed": f"{f['collision']}/{f['stalled']}/{f['timeout']}",
        "drones_not_reached": f"{o['stalled']}/{o['timeout']}",
    }
    for metric, digits in METRIC_DIGITS.items():
        cells[f"{metric}.successful"] = fmt_stat(row[metric]["successful"], digits)
        cells[f"{metric}.all"] = fmt_stat(row[metric]["all"], digits, n=True)
    return cells


def print_report(results: Mapping[str, Any], console: Any = None) -> None:
    """Print the table (successful-run figures on the first line of a cell, all-run ones below) and the claims."""
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    console = console or Console()
    table = Table(
        title=f"rpf-fly bench: {results['episodes']} seeds per scene",
        caption="travel, smoothness, makespan: mean±std over successful runs; dim second line: over all runs where "
        "defined (count). failed runs by cause: collision/stalled/timeout",
        show_lines=True,
    )
    for column in ("scene", "planner", "success", "collisions", "reached", "travel [m]", "smoothness",
                   "makespan [s]", "failed c/s/t"):
        left = column in ("scene", "planner")
        table.add_column(escape(column), justify="left" if left else "right", no_wrap=left or column == "success")
    reasons: dict[str, str] = {}
    for row in results["rows"]:
        if row["status"] != "ok":
            reasons.setdefault(str(row["reason"]), _label(row["planner"]))
            table.add_row(row["scene"], _label(row["planner"]), "[yellow]missing[/yellow]")
            continue
        c = _cells(row)
        table.add_row(
            row["scene"],
            _label(row["planner"]),
            c["success"],
            c["collisions"],
            c["reached"],
            *(
                f"{fmt_stat(row[m]['successful'], d, sep='±')}\n[dim]{fmt_stat(row[m]['all'], d, n=True, sep='±')}[/dim]"
                for m, d in METRIC_DIGITS.items()
            ),
            c["failed"],
        )
    console.print(table)
    for reason, planner in reasons.items():
        console.print(f"[yellow]{planner} missing: {reason}[/yellow]")
    print_claims(claims_of(results), console)


def print_claims(claims: Sequence[Claim], console: Any = None) -> None:
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    console = console or Console()
    table = Table(title="the paper's claims", show_lines=True)
    for column in ("", "claim", "verdict", "numbers"):
        table.add_column(escape(column))
    colour = {"held": "green", "not held": "red", "not evaluated": "yellow"}
    for claim in claims:
        table.add_row(
            f"({claim.id})",
            claim.statement,
            f"[{colour[claim.status]}]{claim.status}[/{colour[claim.status]}]",
            _numbers_text(claim),
        )
    console.print(table)


def _numbers_text(claim: Claim) -> str:
    parts = []
    for key, value in claim.numbers.items():
        if isinstance(value, dict) and key != "PPO failures":
            inner = ", ".join(f"{k} {_short(v)}" for k, v in value.items())
            parts.append(f"{key}: {inner}")
        else:
            parts.append(f"{key}: {_short(value)}")
    if claim.note:
        parts.append(claim.note)
    return "\n".join(parts)


def _short(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {_short(v)}" for k, v in value.items()) + "}"
    return "-" if value is None else str(value)


def to_markdown(results: Mapping[str, Any]) -> str:
    """The results as Markdown: settings, policies, one table per scene, the claims."""
    lines = [
        "# rpf-fly bench results",
        "",
        f"{results['episodes']} seeds per scene; paper missions use start-jitter seeds "
        f"0..{results['episodes'] - 1}, `arena-a-fresh` generator seeds from 1000000 (never used in training). "
        "Path metrics: mean ± std over successful runs, and over all runs where the metric is defined (count in "
        "brackets). Failed runs by cause: collision / stalled / timeout. Drones not reached: stalled / timeout. "
        "See docs/bench.md.",
        "",
        "## Policies",
        "",
    ]
    policies = results.get("policies", {})
    if not policies:
        lines.append("No learned planner in this run.")
    for kind, info in policies.items():
        if "missing" in info:
            lines.append(f"- `{kind}`: **missing**: {info['missing']}")
        else:
            lines.append(f"- `{kind}`: `{Path(info['path']).name}` sha256 `{info['sha256'][:16]}…`")
    lines += ["", "## Results", ""]
    header = ("planner", "success", "collisions", "reached", "travel [m]", "travel, all", "smoothness",
              "smoothness, all", "makespan [s]", "makespan, all", "failed runs c/s/t", "drones not reached s/t")
    for scene in results["scenes"]:
        lines += [f"### {scene}", "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        for row in results["rows"]:
            if row["scene"] != scene:
                continue
            if row["status"] != "ok":
                lines.append(f"| {_label(row['planner'])} | missing: {row['reason']} |" + " |" * (len(header) - 2))
                continue
            c = _cells(row)
            lines.append(
                "| " + " | ".join([
                    _label(row["planner"]), c["success"], c["collisions"], c["reached"],
                    c["travel_distance_m.successful"], c["travel_distance_m.all"],
                    c["smoothness.successful"], c["smoothness.all"],
                    c["makespan_s.successful"], c["makespan_s.all"],
                    c["failed"], c["drones_not_reached"],
                ]) + " |"
            )
        lines.append("")
    lines += ["## Claims", "", "| | claim | verdict | numbers |", "|---|---|---|---|"]
    for claim in claims_of(results):
        numbers = _numbers_text(claim).replace("\n", "<br>").replace("|", "/")
        lines.append(f"| ({claim.id}) | {claim.statement} | **{claim.status}** | {numbers} |")
    lines.append("")
    return "\n".join(lines)


def write_markdown(results: Mapping[str, Any], path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(to_markdown(results))
    return path
