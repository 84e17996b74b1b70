"""The project's docs stand on their own: nothing cites a file a user's clone does not have (the first design's
DESIGN.md, the workspace's shared/ folder), and every docs/<page>.md the code, the docs and README cite exists."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def texts() -> dict[Path, str]:
    files = [
        ROOT / "README.md",
        *sorted((ROOT / "docs").glob("*.md")),
        *sorted((ROOT / "rpf_fly").rglob("*.py")),
        *sorted((ROOT / "tools").glob("*.py")),
        *sorted((ROOT / "missions").glob("*.yaml")),
    ]
    return {f: f.read_text(encoding="utf-8") for f in files}


def test_nothing_cites_a_file_outside_the_clone():
    found = [
        f"{path.relative_to(ROOT)}:{text[: m.start()].count(chr(10)) + 1}: {m.group(0)}"
        for path, text in texts().items()
        for m in re.finditer(r"DESIGN(\.md)?\b|\.\./shared\b|\bshared/(reference|paper|data|DESIGN)", text)
    ]
    assert found == []


def test_every_cited_docs_page_exists():
    missing = sorted(
        {
            f"{path.relative_to(ROOT)}: {m.group(0)}"
            for path, text in texts().items()
            for m in re.finditer(r"docs/[\w./-]+\.md", text)
            if not (ROOT / m.group(0)).is_file()
        }
    )
    assert missing == []
