"""Safe YAML loading that keeps the line of every value.

PyYAML's ``yaml.compose`` (with ``SafeLoader``, plus one resolver so that ``1e-3`` reads as a number) parses a
document into a node graph without constructing anything; this module turns that graph into :class:`YNode` trees
of plain Python values (``None``, ``bool``, ``int``, ``float``, ``str``, lists and string-keyed dicts), each value
with the line it starts on and the line of the key that holds it. Any tag other than the plain scalar, sequence
and mapping tags is refused at its line, so a mission file can never construct an object. Duplicate mapping keys
are refused at the second occurrence; ``<<`` merge keys and anchors/aliases work as in YAML 1.1.

Every problem raises :class:`~rpf_fly.mission.errors.MissionError` with the file, the 1-based line and the dotted
path of the offending value (``(file)`` for the document as a whole).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any, TypeAlias

import yaml
from yaml.constructor import SafeConstructor
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

from .errors import MissionError

ROOT = "(file)"
"""The field name of the document as a whole."""

MAX_NODES = 500_000
"""Refuse documents that expand (through aliases) to more values than this (a "billion laughs" guard)."""

_STD = "tag:yaml.org,2002:"
_SCALAR_TAGS = {_STD + t for t in ("str", "int", "float", "bool", "null", "timestamp")}
_SEQ_TAG = _STD + "seq"
_MAP_TAG = _STD + "map"
_MERGE_TAG = _STD + "merge"
TAG_MESSAGE = "YAML tags that construct objects are not allowed (safe loading only)"

YValue: TypeAlias = None | bool | int | float | str | list["YNode"] | dict[str, "YNode"]


@dataclass(frozen=True)
class YNode:
    """One value of the document.

    ``value``: a plain scalar, a ``list[YNode]`` (YAML sequence) or a ``dict[str, YNode]`` (YAML mapping, in
    document order). ``line``: 1-based line where the value starts. ``key_line``: line of the key holding it
    (``line`` for list items and the root). ``path``: dotted path such as ``drones[2].start`` (``(file)`` for the
    root). ``raw``: a scalar's text as written (``""`` for lists and mappings).
    """

    value: YValue
    line: int
    key_line: int
    path: str
    raw: str = ""

    @property
    def is_map(self) -> bool:
        return isinstance(self.value, dict)

    @property
    def is_seq(self) -> bool:
        return isinstance(self.value, list)

    @property
    def mapping(self) -> dict[str, YNode]:
        """A mapping's entries, for a node known to be one (:attr:`is_map`); a TypeError otherwise (a bug)."""
        if not isinstance(self.value, dict):
            raise TypeError(f"{self.path}: not a mapping")
        return self.value

    @property
    def seq(self) -> list[YNode]:
        """A sequence's items, for a node known to be one (:attr:`is_seq`); a TypeError otherwise (a bug)."""
        if not isinstance(self.value, list):
            raise TypeError(f"{self.path}: not a sequence")
        return self.value

    def plain(self) -> Any:
        """The value as plain Python (nested lists and dicts), lines dropped."""
        if isinstance(self.value, dict):
            return {k: v.plain() for k, v in self.value.items()}
        if isinstance(self.value, list):
            return [v.plain() for v in self.value]
        return self.value


class _Loader(yaml.SafeLoader):
    """``SafeLoader`` that also reads ``1e-3`` as a number (YAML 1.2 does; PyYAML's YAML 1.1 wants ``1.0e-3``)."""


_Loader.add_implicit_resolver(_STD + "float", re.compile(r"^[-+]?[0-9][0-9_]*[eE][-+]?[0-9]+$"), list("-+0123456789"))


def describe(node: YNode) -> str:
    """How a found value reads in an error message: ``string 'fast'``, ``boolean true``, ``a list of 3 items``."""
    v = node.value
    if isinstance(v, dict):
        return "a mapping" if v else "an empty mapping"
    if isinstance(v, list):
        return f"a list of {len(v)} item{'' if len(v) == 1 else 's'}" if v else "an empty list"
    if v is None:
        return "null" if node.raw in ("", "~", "null", "Null", "NULL") else f"null ({node.raw})"
    if isinstance(v, bool):
        return f"boolean {node.raw or str(v).lower()}"
    if isinstance(v, (int, float)):
        return f"number {node.raw or v}"
    return f"string {v!r}"


def child_path(path: str, key: str | int) -> str:
    """``drones`` + 2 -> ``drones[2]``; ``planner`` + ``kind`` -> ``planner.kind``; the root's children are bare."""
    if isinstance(key, int):
        return f"{path}[{key}]"
    return key if path in ("", ROOT) else f"{path}.{key}"


def compose(text: str, file: str) -> YNode | None:
    """Parse ``text`` safely; ``None`` for an empty document (nothing, or only comments / ``---``)."""
    try:
        root = yaml.compose(text, Loader=_Loader)
    except yaml.MarkedYAMLError as exc:
        raise _yaml_error(exc, file) from None
    except yaml.YAMLError as exc:  # unmarked (e.g. reader errors without a mark)
        raise MissionError(file, 1, ROOT, f"invalid YAML: {exc}") from None
    except RecursionError:
        raise MissionError(file, 1, ROOT, "invalid YAML: nested too deeply") from None
    if root is None:
        return None
    if isinstance(root, ScalarNode) and root.tag == _STD + "null" and root.value == "" and not root.style:
        return None
    try:
        return _Converter(file).convert(root, ROOT, root.start_mark.line + 1)
    except RecursionError:
        raise MissionError(file, root.start_mark.line + 1, ROOT, "invalid YAML: nested too deeply") from None


def _yaml_error(exc: yaml.MarkedYAMLError, file: str) -> MissionError:
    mark = exc.problem_mark or exc.context_mark
    line = mark.line + 1 if mark is not None else 1
    problem = exc.problem or exc.context or "cannot parse"
    text = f"invalid YAML: {problem}"
    if exc.problem and exc.context:
        where = ""
        if exc.context_mark is not None and exc.context_mark.line + 1 != line:
            where = f" at line {exc.context_mark.line + 1}"
        text += f" ({exc.context}{where})"
    return MissionError(file, line, ROOT, text)


def _short_tag(tag: str) -> str:
    return "!!" + tag[len(_STD) :] if tag.startswith(_STD) else tag


class _Converter:
    """Walks the composed node graph once per occurrence (aliases are expanded), keeping lines and paths."""

    def __init__(self, file: str):
        self.file = file
        self.scalars = SafeConstructor()
        self.active: set[int] = set()
        self.count = 0

    def fail(self, node: Node, path: str, message: str) -> MissionError:
        return MissionError(self.file, node.start_mark.line + 1, path, message)

    def convert(self, node: Node, path: str, key_line: int) -> YNode:
        self.count += 1
        if self.count > MAX_NODES:
            raise self.fail(node, path, f"document expands to more than {MAX_NODES} values (alias expansion?)")
        line = node.start_mark.line + 1
        if isinstance(node, ScalarNode):
            return YNode(self.scalar(node, path), line, key_line, path, node.value)
        if id(node) in self.active:
            raise self.fail(node, path, "recursive YAML alias (a value that contains itself)")
        self.active.add(id(node))
        try:
            if isinstance(node, SequenceNode):
                if node.tag != _SEQ_TAG:
                    raise self.fail(node, path, f"{TAG_MESSAGE}, found {_short_tag(node.tag)}")
                items = [
                    self.convert(item, child_path(path, i), item.start_mark.line + 1)
                    for i, item in enumerate(node.value)
                ]
                return YNode(items, line, key_line, path)
            if isinstance(node, MappingNode):
                return YNode(self.mapping(node, path), line, key_line, path)
        finally:
            self.active.discard(id(node))
        raise self.fail(node, path, f"unsupported YAML node {type(node).__name__}")  # pragma: no cover

    def scalar(self, node: ScalarNode, path: str) -> Any:
        if node.tag not in _SCALAR_TAGS:
            raise self.fail(node, path, f"{TAG_MESSAGE}, found {_short_tag(node.tag)}")
        kind = node.tag[len(_STD) :]
        if kind in ("str", "timestamp"):  # a date stays the text it was written as
            return str(node.value)
        try:
            if kind == "int":
                return self.scalars.construct_yaml_int(node)
            if kind == "float":
                return self.scalars.construct_yaml_float(node)
            if kind == "bool":
                return self.scalars.construct_yaml_bool(node)
            return None
        except Exception:  # an explicit tag on text that is not of that type, e.g. `!!int abc`
            raise self.fail(node, path, f"invalid !!{kind} value {node.value!r}") from None

    def key(self, node: Node, path: str) -> str:
        if not isinstance(node, ScalarNode):
            raise self.fail(
                node,
                path,
                "mapping keys must be strings, got a " + ("list" if isinstance(node, SequenceNode) else "mapping"),
            )
        value = self.scalar(node, path)
        if not isinstance(value, str):
            kind = "null" if value is None else "boolean" if isinstance(value, bool) else "number"
            raise self.fail(
                node, path, f"mapping key {node.value!r} reads as a {kind}; keys must be strings (quote it)"
            )
        return value

    def mapping(self, node: MappingNode, path: str) -> dict[str, YNode]:
        if node.tag != _MAP_TAG:
            raise self.fail(node, path, f"{TAG_MESSAGE}, found {_short_tag(node.tag)}")
        out: dict[str, YNode] = {}
        merges: list[tuple[Node, Node]] = []
        for key_node, value_node in node.value:
            if isinstance(key_node, ScalarNode) and key_node.tag == _MERGE_TAG:
                merges.append((key_node, value_node))
                continue
            key = self.key(key_node, path)
            sub = child_path(path, key)
            if key in out:
                raise self.fail(key_node, sub, f"duplicate key {key!r} (first at line {out[key].key_line})")
            out[key] = self.convert(value_node, sub, key_node.start_mark.line + 1)
        for _key_node, value_node in merges:  # explicit keys win; earlier merge sources win over later ones
            sources = value_node.value if isinstance(value_node, SequenceNode) else [value_node]
            for source in sources:
                if not isinstance(source, MappingNode):
                    raise self.fail(source, path, "a '<<' merge key needs a mapping or a list of mappings")
                if id(source) in self.active:
                    raise self.fail(source, path, "recursive YAML alias (a value that contains itself)")
                self.active.add(id(source))
                try:
                    merged = self.mapping(source, path)
                finally:
                    self.active.discard(id(source))
                for key, value in merged.items():
                    out.setdefault(key, value)
        return out
