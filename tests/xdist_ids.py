"""``pytest --lf`` across pytest-xdist's loadgroup and a run without workers (tests/conftest.py installs it).

Under ``--dist loadgroup`` (pyproject addopts) an xdist worker renames every test marked ``xdist_group`` to
``<id>@<group>`` (xdist/remote.py, ``pytest_collection_modifyitems``), so that the controller can schedule a group on
one worker. The reports carry the renamed id, and pytest's cache provider records failures under it
(``.pytest_cache/v/cache/lastfailed``). A run without ``-n`` collects the tests under their own ids: none of the
recorded ids matches, and ``--lf`` then keeps every collected test ("N known failures not in selected tests"), the
whole suite, one test at a time. The other way round, failures recorded without ``-n`` would not match the renamed
tests of a ``-n`` run.

:class:`PlainIds` keeps the failures under each test's own id and compares ids without the group suffix, so
``--lf`` reruns the failures alone, with or without ``-n``.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from typing import Any

import pytest

GROUP_SUFFIX = re.compile(r"@[A-Za-z0-9_.-]+$")
"""The ``@<group>`` xdist appends to a test id. A parametrized id ends in ``]``, so an ``@`` inside its brackets
(``test_x[a@b]``) is never taken for a group."""


def plain_nodeid(nodeid: str) -> str:
    """``nodeid`` without the ``@<group>`` suffix of xdist's loadgroup."""
    return GROUP_SUFFIX.sub("", nodeid)


class PlainIds(dict):  # type: ignore[type-arg]
    """The cache provider's record of failed test ids, keyed and looked up by :func:`plain_nodeid`."""

    def __init__(self, ids: Mapping[str, Any] | Iterable[tuple[str, Any]] = ()):
        super().__init__()
        self.update(ids)

    def __contains__(self, key: object) -> bool:
        return isinstance(key, str) and super().__contains__(plain_nodeid(key))

    def __getitem__(self, key: str) -> Any:
        return super().__getitem__(plain_nodeid(key))

    def __setitem__(self, key: str, value: Any) -> None:
        super().__setitem__(plain_nodeid(key), value)

    def __delitem__(self, key: str) -> None:
        super().__delitem__(plain_nodeid(key))

    def get(self, key: str, default: Any = None) -> Any:
        return super().get(plain_nodeid(key), default)

    def pop(self, key: str, *default: Any) -> Any:
        return super().pop(plain_nodeid(key), *default)

    def setdefault(self, key: str, default: Any = None) -> Any:
        return super().setdefault(plain_nodeid(key), default)

    def update(self, other: Mapping[str, Any] | Iterable[tuple[str, Any]] = (), **kwargs: Any) -> None:
        items = other.items() if isinstance(other, Mapping) else other
        for key, value in [*items, *kwargs.items()]:
            self[key] = value


def keep_failures_by_plain_id(config: pytest.Config) -> None:
    """Give the cache provider's ``--lf`` plugin a :class:`PlainIds` record (from ``pytest_configure``: the plugin
    reads the cache when it is registered, before any conftest's ``pytest_configure``)."""
    plugin = config.pluginmanager.get_plugin("lfplugin")
    if plugin is not None and isinstance(getattr(plugin, "lastfailed", None), dict):
        plugin.lastfailed = PlainIds(plugin.lastfailed)
