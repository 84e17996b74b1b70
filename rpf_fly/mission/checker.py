"""Typed reads of a mission's YAML values (`YNode`), each raising a precise `MissionError` (``FILE:LINE: FIELD:
message``): mappings with their keys, numbers within bounds, strings, choices with a "did you mean", points and
ranges, host names and IP addresses. Why apart: every section of a mission, and the CLI's planner options, read
their values through these rules.
"""

from __future__ import annotations

import difflib
import ipaddress
import math
import re
from collections.abc import Callable, Iterable, Sequence
from typing import NamedTuple, TypeVar

from . import model as m
from .errors import MissionError
from .yaml_nodes import YNode, child_path, describe

_Choice = TypeVar("_Choice", bound=str)

_HOST_NAME = re.compile(r"(?!-)[A-Za-z0-9-]{1,63}(?<!-)(\.(?!-)[A-Za-z0-9-]{1,63}(?<!-))*\.?")
"""A host name: dot-separated labels of letters, digits and hyphens, no label starting or ending with a hyphen."""


class Bound(NamedTuple):
    text: str
    ok: Callable[[float], bool]


POSITIVE = Bound("positive", lambda x: x > 0)
NON_NEGATIVE = Bound("non-negative", lambda x: x >= 0)
FRACTION = Bound("in [0, 1)", lambda x: 0 <= x < 1)


def fmt(x: float) -> str:
    return f"{x:.6g}"


def fmt_point(p: Sequence[float]) -> str:
    return f"({fmt(p[0])}, {fmt(p[1])})"


def did_you_mean(word: str, choices: Iterable[str]) -> str:
    choices = list(choices)
    for c in choices:
        if c.lower() == word.lower():
            return f" (did you mean {c!r}?)"
    close = difflib.get_close_matches(word, choices, n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


def options_text(choices: Iterable[str]) -> str:
    return ", ".join(repr(c) for c in choices)


class Checker:
    """Typed reads of :class:`YNode` values that raise a precise :class:`MissionError`."""

    def __init__(self, file: str):
        self.file = file

    def error(self, where: YNode | int, field: str, message: str) -> MissionError:
        line = where if isinstance(where, int) else where.line
        return MissionError(self.file, line, field, message)

    def bad(self, node: YNode, expected: str) -> MissionError:
        return self.error(node, node.path, f"expected {expected}, got {describe(node)}")

    def mapping(
        self, node: YNode, keys: Sequence[str], required: Sequence[str] = (), what: str = "a mapping"
    ) -> dict[str, YNode]:
        """The entries of a mapping with only ``keys`` and all of ``required``."""
        if not node.is_map:
            raise self.bad(node, what)
        entries = node.mapping
        for key, value in entries.items():
            if key not in keys:
                hint = did_you_mean(key, keys) or f"; expected one of {options_text(keys)}"
                raise self.error(value.key_line, value.path, f"unknown key{hint}")
        for key in required:
            if key not in entries:
                raise self.error(node.key_line, child_path(node.path, key), "missing required key")
        return entries

    def number(self, node: YNode, bound: Bound | None = None) -> float:
        v = node.value
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.bad(node, "a number")
        if not math.isfinite(v):
            raise self.error(node, node.path, f"expected a finite number, got {node.raw or v}")
        if bound is not None and not bound.ok(v):
            raise self.error(node, node.path, f"must be {bound.text}, got {node.raw or fmt(v)}")
        return float(v)

    def integer(self, node: YNode, lo: int | None = None, hi: int | None = None) -> int:
        v = node.value
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.bad(node, "an integer")
        if lo is not None and v < lo:
            raise self.error(
                node, node.path, f"must be at least {lo}, got {v}" if lo != 1 else f"must be positive, got {v}"
            )
        if hi is not None and v > hi:
            raise self.error(node, node.path, f"must be at most {hi}, got {v}")
        return v

    def string(self, node: YNode) -> str:
        if not isinstance(node.value, str):
            error = self.bad(node, "a string")
            if node.raw and not (node.is_map or node.is_seq):  # e.g. `name: no` or `rigid_body: 7`
                error = self.error(node, node.path, f"{error.message} (quote it to make it text: '{node.raw}')")
            raise error
        if not node.value.strip():
            raise self.error(node, node.path, "must not be empty")
        if any(ord(ch) < 32 for ch in node.value):
            raise self.error(node, node.path, f"must be one line of text, got {node.value!r}")
        return node.value

    def boolean(self, node: YNode) -> bool:
        if not isinstance(node.value, bool):
            raise self.bad(node, "true or false")
        return node.value

    def choice(self, node: YNode, choices: Sequence[_Choice], what: str = "") -> _Choice:
        """The one of ``choices`` the node names (typed as they are: a tuple of literals gives a literal)."""
        if not isinstance(node.value, str):
            raise self.bad(node, f"one of {options_text(choices)}")
        if node.value not in choices:
            label = (
                f"unknown {what} {node.value!r}"
                if what
                else f"expected one of {options_text(choices)}, got {node.value!r}"
            )
            hint = did_you_mean(node.value, choices)
            known = f"; known: {', '.join(choices)}" if what else ""
            raise self.error(node, node.path, f"{label}{hint}{known}")
        return next(c for c in choices if c == node.value)

    def vec2(self, node: YNode, labels: str = "x, y") -> m.Vec2:
        if not node.is_seq or len(node.seq) != 2:
            raise self.bad(node, f"a list of 2 numbers [{labels}]")
        a, b = node.seq
        return self.number(a), self.number(b)

    def span(self, node: YNode) -> m.Vec2:
        lo, hi = self.vec2(node, "lo, hi")
        if not lo < hi:
            raise self.error(node, node.path, f"inverted range [{fmt(lo)}, {fmt(hi)}]: expected [lo, hi] with lo < hi")
        return lo, hi

    def host(self, node: YNode) -> str:
        """An IP address or a syntactically valid host name (RFC 1123). Dotted numbers must be a whole IPv4
        address: ``192.168.1.1000`` and ``192.168.1`` are typos, not host names. Whether a name resolves is
        checked when a command needs the server (``rpf-fly fly`` and ``check``), not here: ``sim`` needs none."""
        text = self.string(node)
        expected = f"expected a host name or IP address, got {text!r}"
        try:
            ipaddress.ip_address(text)
            return text
        except ValueError:
            pass
        if re.fullmatch(r"[0-9.]+", text):
            raise self.error(node, node.path, f"{expected}: not an IPv4 address (four numbers 0-255 joined by dots)")
        if len(text) > 253 or not _HOST_NAME.fullmatch(text):
            raise self.error(node, node.path, expected)
        return text

    def ip(self, node: YNode, multicast: bool = False) -> str:
        text = self.string(node)
        try:
            address = ipaddress.ip_address(text)
        except ValueError:
            raise self.error(node, node.path, f"expected an IP address, got {text!r}") from None
        if multicast and not address.is_multicast:
            raise self.error(node, node.path, f"expected a multicast address (224.0.0.0/4), got {text!r}")
        return text
