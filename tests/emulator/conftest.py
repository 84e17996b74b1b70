"""The hang guard for every test here: cflib waits forever on silence, so a stuck radio test dumps stacks and exits."""

from __future__ import annotations

from collections.abc import Iterator

import pytest


@pytest.fixture(autouse=True)
def _hang_guard(hang_guard: None) -> Iterator[None]:
    yield
