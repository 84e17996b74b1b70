"""Bench results as a rich table, a JSON document and Markdown (claims included). Formatting only."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from rpf_fly.bench.claims import Claim, evaluate_claims
from rpf_fly.bench.runner import PLANNER_LABELS, BenchResult, dynamics_line


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


def fmt_stat(s: Mapping[str, float] | None, digits: int = 2, n: bool = False, sep: str = " ± ") -> str:
    """``mean ± std`` (and the count with ``n``), ``-`` when undefined; the mean alone over one value (a standard
    deviation of one run is no spread)."""
    if s is None:
        return "-"
    text = f"{s['mean']:.{digits}f}" if s["n"] <= 1 else f"{s['mean']:.{digits}f}{sep}{s['std']:.{digits}f}"
    return f"{text} ({s['n']})" if n else text


REPORT_WIDTH = 100
"""Columns the bench's table and claims are laid out for (a narrower console wraps them further)."""


def _rate(value: float | None) -> str:
    return "-" if value is None else f"{value:.0%}"


def _label(planner: str) -> str:
    return PLANNER_LABELS.get(planner, planner)


METRIC_DIGITS = {"travel_distance_m": 2, "smoothness": 4, "makespan_s": 1}
TABLE_DIGITS = {"travel_distance_m": 2, "smoothness": 3, "makespan_s": 1}
"""The console table's digits (the Markdown and JSON keep :data:`METRIC_DIGITS` and full precision)."""


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


def _metric_cell(row: Mapping[str, Any], metric: str, digits: int) -> str:
    """Over the successful runs; below it, dim, over all runs where defined (count), unless that is the same."""
    ok, every = row[metric]["successful"], row[metric]["all"]
    first = fmt_stat(ok, digits, sep="±")
    if every is None or (ok is not None and ok["n"] == every["n"] and ok["mean"] == every["mean"]):
        return first
    return f"{first}\n[dim]{fmt_stat(every, digits, n=every['n'] != row['runs'], sep='±')}[/dim]"


def print_report(results: Mapping[str, Any], console: Any = None) -> None:
    """Print the table and the claims, laid out for :data:`REPORT_WIDTH` columns: one block of rows per scene,
    path metrics over the successful runs (and, dim below, over all runs where that differs), no spread where a
    figure comes from one run."""
    from rich import box
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    console = console or Console()
    one = results["episodes"] <= 1
    spread = "" if one else "mean±std "
    note = (
        f"success: successful runs / runs. travel, smoothness, makespan: {spread}over successful runs"
        + ("" if one else "; dim below: over all runs where defined (the count when not every run), where it differs")
        + ". coll.: drone-drone (dd), drone-obstacle (do). failed c/s/t: runs by cause collision/stalled/"
        "timeout"
    )
    table = Table(
        title=f"rpf-fly bench: {results['episodes']} seed{'' if one else 's'} per scene",
        box=box.SIMPLE_HEAD,
        pad_edge=False,
        collapse_padding=True,
    )
    for column in (
        "scene",
        "planner",
        "success",
        "coll.",
        "reached",
        "travel\n[m]",
        "smoothness",
        "makespan\n[s]",
        "failed\nc/s/t",
    ):
        left = column in ("scene", "planner")
        table.add_column(escape(column), justify="left" if left else "right", no_wrap=left)
    reasons: dict[str, str] = {}
    rows = list(results["rows"])
    for k, row in enumerate(rows):
        last_of_scene = k + 1 == len(rows) or rows[k + 1]["scene"] != row["scene"]
        if row["status"] != "ok":
            reasons.setdefault(str(row["reason"]), _label(row["planner"]))
            table.add_row(row["scene"], _label(row["planner"]), "[yellow]missing[/yellow]", end_section=last_of_scene)
            continue
        c = row["collisions"]
        f = row["failed_runs"]
        table.add_row(
            row["scene"],
            _label(row["planner"]),
            f"{row['successes']}/{row['runs']}",
            f"{c['total']} ({c['drone_drone']}dd {c['drone_obstacle']}do)" if c["total"] else "0",
            _rate(row["reached_rate"]),
            *(_metric_cell(row, m, d) for m, d in TABLE_DIGITS.items()),
            f"{f['collision']}/{f['stalled']}/{f['timeout']}",
            end_section=last_of_scene,
        )
    console.print(table)
    console.print(dynamics_line(results), width=min(REPORT_WIDTH, console.width))
    console.print(note, style="dim", width=min(REPORT_WIDTH, console.width))
    for reason, planner in reasons.items():
        console.print(f"[yellow]{escape(planner)} missing: {escape(reason)}[/yellow]")
    print_claims(claims_of(results), console)


def print_claims(claims: Sequence[Claim], console: Any = None) -> None:
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    console = console or Console()
    table = Table(title="the paper's claims", show_lines=True, width=min(REPORT_WIDTH, console.width))
    for column, ratio in (("", None), ("claim", 3), ("verdict", None), ("numbers", 4)):
        table.add_column(escape(column), ratio=ratio, no_wrap=ratio is None)
    colour = {"held": "green", "not held": "red", "not evaluated": "yellow"}
    for claim in claims:
        table.add_row(
            f"({claim.id})",
            escape(claim.statement),
            f"[{colour[claim.status]}]{claim.status}[/{colour[claim.status]}]",
            escape(_numbers_text(claim)),
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
        dynamics_line(results),
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
    header = (
        "planner",
        "success",
        "collisions",
        "reached",
        "travel [m]",
        "travel, all",
        "smoothness",
        "smoothness, all",
        "makespan [s]",
        "makespan, all",
        "failed runs c/s/t",
        "drones not reached s/t",
    )
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
                "| "
                + " | ".join(
                    [
                        _label(row["planner"]),
                        c["success"],
                        c["collisions"],
                        c["reached"],
                        c["travel_distance_m.successful"],
                        c["travel_distance_m.all"],
                        c["smoothness.successful"],
                        c["smoothness.all"],
                        c["makespan_s.successful"],
                        c["makespan_s.all"],
                        c["failed"],
                        c["drones_not_reached"],
                    ]
                )
                + " |"
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
