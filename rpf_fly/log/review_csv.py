"""``rpf-fly review --csv DIR``: one CSV file per topic of a flight log, the messages' fields flattened into
columns.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

from rpf_fly.log.reader import LogData


def _flatten(value: Any, prefix: str, row: dict[str, Any]) -> None:
    if isinstance(value, dict):
        for k, v in value.items():
            _flatten(v, f"{prefix}.{k}" if prefix else str(k), row)
    elif isinstance(value, list):
        row[prefix] = json.dumps(value, separators=(",", ":"))
    else:
        row[prefix] = "" if value is None else value


def csv_name(topic: str) -> str:
    """File name of a topic's CSV: ``/mocap/cf1`` -> ``mocap_cf1.csv``."""
    return topic.strip("/").replace("/", "_") + ".csv"


def export_csv(data: LogData, directory: str | Path) -> list[Path]:
    """One CSV per topic: ``log_time_ns, publish_time_ns, sequence`` and the message's fields flattened with dots
    (``pose.position.x``); arrays as JSON in one cell; null as an empty cell."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    written = []
    for topic in sorted(data.topics):
        rows = []
        columns: dict[str, None] = {"log_time_ns": None, "publish_time_ns": None, "sequence": None}
        for m in data.messages(topic):
            row: dict[str, Any] = {"log_time_ns": m.log_time, "publish_time_ns": m.publish_time, "sequence": m.sequence}
            if isinstance(m.data, dict):
                _flatten(m.data, "", row)
            else:
                row["data"] = m.data.hex() if isinstance(m.data, (bytes, bytearray)) else m.data
            columns.update(dict.fromkeys(row))
            rows.append(row)
        for name in [c for c in columns if any(d.startswith(c + ".") for d in columns)]:
            if all(row.get(name, "") == "" for row in rows):  # a nullable object, null in some rows: its fields are
                del columns[name]  # the columns
        path = directory / csv_name(topic)
        with open(path, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(columns), restval="")
            writer.writeheader()
            writer.writerows(rows)
        written.append(path)
    return written
