"""One spelling of the hint that names an optional extra (``pip install 'rpf_fly[EXTRA]'``: rpf_fly.install_hint) in
every message, doc page and the README; only the README's set-up installs the checkout itself (``-e ".[...]"``)."""

from __future__ import annotations

import re
from pathlib import Path

from rpf_fly import install_hint

ROOT = Path(__file__).resolve().parents[2]
EXTRA = re.compile(r"pip install (?:-e )?['\"]?[\w.-]*\[[\w,]+\]['\"]?")
SETUP = 'pip install -e ".[dev,train,live,motioncapture]"'


def test_every_hint_to_install_an_extra_is_spelt_alike():
    files = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), *sorted((ROOT / "rpf_fly").rglob("*.py"))]
    found = {m.group(0) for f in files for m in EXTRA.finditer(f.read_text(encoding="utf-8"))}
    assert found - {SETUP} == {install_hint("live"), install_hint("motioncapture")}
    assert install_hint("live") == "pip install 'rpf_fly[live]'"


def test_the_messages_name_the_extra_the_same_way(monkeypatch):
    import sys

    from typer.testing import CliRunner

    from rpf_fly.cli import get_app
    from rpf_fly.log.live import INSTALL_HINT
    from rpf_fly.mocap.motioncapture_options import MISSING_LIBRARY

    assert INSTALL_HINT == install_hint("live") and MISSING_LIBRARY.endswith(install_hint("motioncapture"))
    monkeypatch.setitem(sys.modules, "torch", None)  # as if the train extra were not installed
    result = CliRunner().invoke(get_app(), ["train", "--out", "runs/never.onnx"])
    assert result.exit_code == 2 and install_hint("train") in result.output
