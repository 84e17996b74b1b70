"""Helpers for the mission tests: write YAML into a temporary directory and load it as ``m.yaml``."""

from __future__ import annotations

import textwrap
from collections.abc import Callable
from pathlib import Path

import pytest

from rpf_fly.mission import Mission, MissionError, load_mission


@pytest.fixture
def workdir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A fresh current directory, so that errors name the file plainly as ``m.yaml``."""
    monkeypatch.chdir(tmp_path)
    return tmp_path


@pytest.fixture
def no_shipped_policies(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """As if rpf_fly were installed without the project's ``policies/`` folder (a wheel): no fallback."""
    import rpf_fly.mission.policy_paths

    monkeypatch.setattr(rpf_fly.mission.policy_paths, "PROJECT_POLICIES", tmp_path / "no-shipped-policies")


@pytest.fixture
def load(workdir: Path) -> Callable[[str], Mission]:
    """Load YAML text (dedented) written to ``m.yaml`` in the working directory."""

    def _load(text: str, name: str = "m.yaml") -> Mission:
        path = workdir / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text))
        return load_mission(name)

    return _load


@pytest.fixture
def fail(load: Callable[[str], Mission]) -> Callable[..., MissionError]:
    """Load YAML text that must be rejected; check ``str(err)`` starts with ``prefix`` and contains ``part``."""

    def _fail(text: str, prefix: str, part: str = "", name: str = "m.yaml") -> MissionError:
        with pytest.raises(MissionError) as info:
            load(text, name)
        err = info.value
        message = str(err)
        assert message.startswith(prefix), message
        assert part in message, message
        assert "\n" not in message
        return err

    return _fail
