"""A mission file's YAML read into `Mission`: each section in document order (its keys before its values), the
drones or the formation, the files a mission names, then the layout checks, every error on the line of the value
at fault. Why apart: this is the file's grammar; rpf_fly/mission/load.py is the API around it.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Literal

from . import model as m
from .checker import POSITIVE, Checker, fmt, fmt_point
from .errors import MissionError
from .layout import LayoutError, check_layout
from .policy_paths import DEFAULT_POLICY, find_file, looked_in, search_dirs
from .radio_uri import RadioUri, parse_uri
from .sections import (
    DRY_RUN_SPEC,
    FLIGHT_SPEC,
    MOCAP_SPEC,
    MOTIONCAPTURE_KEYS,
    PLANNER_SPEC,
    RADIO_SPEC,
    SAFETY_SPEC,
    SIM_SPEC,
    Reader,
)
from .yaml_nodes import ROOT, YNode, child_path, describe

NAME_PATTERN = re.compile(r"[A-Za-z][A-Za-z0-9_-]*")
"""Drone names (and the formation's name prefix): usable as MCAP topic segments."""

TOP_KEYS = (
    "name",
    "arena",
    "flight",
    "planner",
    "mocap",
    "radio",
    "sim",
    "safety",
    "obstacles",
    "drones",
    "formation",
    "runtime",
    "dry_run",
)
DRONE_KEYS = ("name", "uri", "rigid_body", "start", "goal")
FORMATION_KEYS = ("kind", "count", "radius", "center", "uri_base", "name_prefix", "phase_deg")
FORMATION_KINDS = ("circle_swap",)
MAX_FORMATION_COUNT = 255
OBSTACLE_KEYS = {"circle": ("shape", "center", "radius"), "box": ("shape", "min", "max")}
ZENOH_MODES: tuple[Literal["client", "peer"], ...] = ("client", "peer")
MOCAP_RELAYS: tuple[Literal["auto", "on", "off"], ...] = ("auto", "on", "off")


class MissionParser(Checker):
    def __init__(self, file: str, base_dir: Path | None):
        super().__init__(file)
        self.base_dir = base_dir
        self.nodes: dict[str, YNode] = {}

    # -- sections -------------------------------------------------------------------------------------------

    def settings(self, node: YNode, cls: type, spec: dict[str, tuple[str, Reader]]) -> Any:
        entries = self.mapping(node, tuple(spec))
        return cls(**{spec[k][0]: spec[k][1](self, v) for k, v in entries.items()})

    def arena(self, node: YNode) -> m.Arena:
        e = self.mapping(node, ("x", "y", "z"), required=("x", "y"))
        return m.Arena(**{k: self.span(v) for k, v in e.items()})

    def planner(self, node: YNode) -> m.PlannerSettings:
        settings: m.PlannerSettings = self.settings(node, m.PlannerSettings, PLANNER_SPEC)
        entries = node.mapping
        dirs = search_dirs(self.base_dir)
        if "policy" in entries:
            raw = str(settings.policy)
            found, looked = find_file(raw, dirs)
            if found is None:
                raise self.error(
                    entries["policy"], "planner.policy", f"policy file {raw!r} not found ({looked_in(looked)})"
                )
        elif settings.kind in m.POLICY_KINDS:
            found = self.default_policy(settings.kind, entries.get("kind", node), "kind" not in entries)
        else:
            found = None
        return dataclasses.replace(settings, policy=found)

    def default_policy(self, kind: str, where: YNode | int, defaulted: bool) -> Path:
        """``policies/<kind>.onnx`` for a policy kind given no ``planner.policy``; the error names the kind's
        default, and says the kind itself was the default when the mission names none (``defaulted``)."""
        raw = DEFAULT_POLICY.format(kind=kind)
        found, looked = find_file(raw, search_dirs(self.base_dir))
        if found is None:
            whose = f"the default planner kind {kind!r}" if defaulted else f"planner kind {kind!r}"
            hint = " (or name another planner.kind, e.g. apf, which needs none)" if defaulted else ""
            raise self.error(
                where,
                "planner.policy",
                f"{whose} needs a policy and none is given; the default {raw!r} was not found "
                f"({looked_in(looked)}){hint}",
            )
        return found

    def mocap(self, node: YNode) -> m.MocapSettings:
        settings: m.MocapSettings = self.settings(node, m.MocapSettings, MOCAP_SPEC)
        entries = node.mapping
        if settings.command_port == settings.data_port:
            at = entries.get("data_port") or entries["command_port"]
            raise self.error(at, at.path, f"command_port and data_port must differ, both are {settings.data_port}")
        if settings.kind == "motioncapture":
            return self.motioncapture(node, entries, settings)
        for key in MOTIONCAPTURE_KEYS:
            if key in entries:
                raise self.error(
                    entries[key].key_line,
                    entries[key].path,
                    f"only for kind 'motioncapture' (this mocap is kind {settings.kind!r})",
                )
        return settings

    def motioncapture(self, node: YNode, entries: dict[str, YNode], settings: m.MocapSettings) -> m.MocapSettings:
        """`type`, `hostname` and `options` of kind `motioncapture`, checked against libmotioncapture's own table
        (rpf_fly/mocap/motioncapture_options.py): the library itself ignores unknown keys and misreads values."""
        from rpf_fly.mocap import motioncapture_options as mc

        if "type" not in entries:
            raise self.error(
                node.key_line,
                child_path(node.path, "type"),
                f"missing required key: kind 'motioncapture' needs the system's type, one of {', '.join(mc.TYPES)}",
            )
        system = self.choice(entries["type"], tuple(mc.TYPES), what="motioncapture type")
        hostname = None
        if "hostname" in entries:
            at = entries["hostname"]
            try:
                hostname = mc.check_hostname(system, at.value)
            except ValueError as err:
                raise self.error(at, at.path, str(err)) from None
        options: list[tuple[str, str]] = []
        if "options" in entries:
            at = entries["options"]
            if not at.is_map:
                raise self.bad(at, f"a mapping of {system} options")
            for key, value in at.mapping.items():
                if value.is_map or value.is_seq:
                    raise self.bad(value, "a scalar (text, number, true or false)")
                try:
                    options.append((key, mc.check_option(system, key, value.value)))
                except ValueError as err:
                    where = value.key_line if str(err).startswith(("unknown option", "give the host")) else value
                    raise self.error(where, value.path, str(err)) from None
        return dataclasses.replace(settings, system=system, hostname=hostname, options=tuple(options))

    def runtime(self, node: YNode) -> m.RuntimeSettings:
        entries = self.mapping(node, ("zenoh", "mocap_relay"))
        relay = self.mocap_relay(entries["mocap_relay"]) if "mocap_relay" in entries else "auto"
        if "zenoh" not in entries:
            return m.RuntimeSettings(mocap_relay=relay)
        z = self.mapping(entries["zenoh"], ("mode", "connect", "listen", "config"))
        mode = self.choice(z["mode"], ZENOH_MODES) if "mode" in z else "client"
        config = self.zenoh_config(z["config"]) if "config" in z else None
        lists: dict[str, tuple[str, ...]] = {}
        for key in ("connect", "listen"):
            if key not in z:
                continue
            value = z[key]
            items = value.seq if value.is_seq else [value]
            endpoints = tuple(self.endpoint(item) for item in items)
            lists[key] = endpoints
        zenoh = m.ZenohSettings(
            mode=mode, config=config, connect=lists.get("connect", ()), listen=lists.get("listen", ())
        )
        return m.RuntimeSettings(zenoh=zenoh, mocap_relay=relay)

    def mocap_relay(self, node: YNode) -> Literal["auto", "on", "off"]:
        """``runtime.mocap_relay``: ``auto``, ``on`` or ``off`` (YAML 1.1 reads a bare on/off as true/false: taken
        as written)."""
        if isinstance(node.value, bool):
            return "on" if node.value else "off"
        return self.choice(node, MOCAP_RELAYS)

    def zenoh_config(self, node: YNode) -> Path:
        """``runtime.zenoh.config``: an existing file that Zenoh reads as its configuration (relative to the
        mission's folder, then the current one); one line naming the file and Zenoh's complaint otherwise."""
        raw = self.string(node)
        found, looked = find_file(raw, search_dirs(self.base_dir))
        if found is None:
            raise self.error(node, "runtime.zenoh.config", f"Zenoh config file {raw!r} not found ({looked_in(looked)})")
        import zenoh

        try:
            zenoh.Config.from_file(str(found))
        except zenoh.ZError as err:
            first = " ".join(str(err).split())[:200]
            raise self.error(node, "runtime.zenoh.config", f"Zenoh cannot read {str(found)!r}: {first}") from None
        return found

    def dry_run(self, node: YNode) -> m.DryRunSettings:
        settings: m.DryRunSettings = self.settings(node, m.DryRunSettings, DRY_RUN_SPEC)
        if settings.vehicle is not None and settings.dynamics != "firmware":
            at = node.mapping["vehicle"]
            raise self.error(
                at,
                "dry_run.vehicle",
                "a vehicle profile sets the firmware model's gains: give "
                f"dry_run.dynamics: firmware with it (it is {settings.dynamics})",
            )
        return settings

    def vehicle_profile(self, node: YNode) -> Any:
        """``dry_run.vehicle``: a vehicle profile file (relative to the mission's folder, then the current one),
        read and checked now (rpf_fly/calibrate/profile.py); one line naming the file and the field at fault."""
        from rpf_fly.calibrate.profile import ProfileError, load_profile

        raw = self.string(node)
        found, looked = find_file(raw, search_dirs(self.base_dir))
        if found is None:
            raise self.error(node, "dry_run.vehicle", f"vehicle profile {raw!r} not found ({looked_in(looked)})")
        try:
            return load_profile(found)
        except ProfileError as err:
            raise self.error(node, "dry_run.vehicle", str(err)) from None

    def endpoint(self, node: YNode) -> str:
        text = self.string(node)
        proto, sep, rest = text.partition("/")
        if not sep or proto not in ("tcp", "udp", "tls", "quic") or ":" not in rest:
            raise self.error(node, node.path, f"expected a Zenoh endpoint such as tcp/127.0.0.1:7447, got {text!r}")
        return text

    def obstacles(self, node: YNode) -> tuple[m.Obstacle, ...]:
        if not node.is_seq:
            raise self.bad(node, "a list of obstacles (write [] for none)")
        out: list[m.Obstacle] = []
        for item in node.seq:
            e = self.mapping(
                item,
                ("shape", "center", "radius", "min", "max"),
                required=("shape",),
                what="an obstacle mapping {shape: circle|box, ...}",
            )
            shape = self.choice(e["shape"], tuple(OBSTACLE_KEYS), what="obstacle shape")
            keys = OBSTACLE_KEYS[shape]
            e = self.mapping(item, keys, required=keys)
            if shape == "circle":
                out.append(m.CircleObstacle(center=self.vec2(e["center"]), radius=self.number(e["radius"], POSITIVE)))
            else:
                lo, hi = self.vec2(e["min"]), self.vec2(e["max"])
                for axis in (0, 1):
                    if not lo[axis] < hi[axis]:
                        raise self.error(
                            e["max"],
                            e["max"].path,
                            f"inverted box: min {fmt_point(lo)} must be below max {fmt_point(hi)} in "
                            f"{'xy'[axis]} ({fmt(lo[axis])} >= {fmt(hi[axis])})",
                        )
                out.append(m.BoxObstacle(min=lo, max=hi))
        return tuple(out)

    def drone_name(self, node: YNode, what: str = "drone name") -> str:
        name = self.string(node)
        if not NAME_PATTERN.fullmatch(name):
            raise self.error(
                node,
                node.path,
                f"{what} {name!r} must start with a letter and contain only letters, "
                "digits, '_' and '-' (it names MCAP topics)",
            )
        return name

    def uri(self, node: YNode) -> tuple[str, RadioUri]:
        text = self.string(node)
        try:
            return text, parse_uri(text)
        except ValueError as exc:
            raise self.error(node, node.path, str(exc)) from None

    def drones(self, node: YNode) -> tuple[m.Drone, ...]:
        if not node.is_seq:
            raise self.bad(node, "a list of drones")
        if not node.seq:
            raise self.error(node, "drones", "empty list: a mission needs at least one drone")
        drones: list[m.Drone] = []
        names: dict[str, YNode] = {}
        links: dict[tuple[int, str], YNode] = {}
        bodies: dict[str, YNode] = {}
        for item in node.seq:
            e = self.mapping(
                item,
                DRONE_KEYS,
                required=("name", "uri", "start", "goal"),
                what="a drone mapping {name, uri, start, goal}",
            )
            name = self.drone_name(e["name"])
            if name in names:
                raise self.error(
                    e["name"],
                    e["name"].path,
                    f"duplicate drone name {name!r} (also {names[name].path}, line {names[name].line})",
                )
            names[name] = e["name"]
            uri, parsed = self.uri(e["uri"])
            if parsed.link in links:
                other = links[parsed.link]
                raise self.error(
                    e["uri"],
                    e["uri"].path,
                    f"duplicate URI {uri!r}: same channel {parsed.channel} and address "
                    f"{parsed.address} as {other.path} ({other.value!r}, line {other.line}), "
                    "so both would reach the same Crazyflie",
                )
            links[parsed.link] = e["uri"]
            body_node = e.get("rigid_body", e["name"])
            body = self.string(body_node) if "rigid_body" in e else name
            if body in bodies:
                other = bodies[body]
                how = "" if "rigid_body" in e else " (defaulted from the name)"
                raise self.error(
                    body_node,
                    child_path(item.path, "rigid_body"),
                    f"duplicate rigid_body {body!r}{how}: also the rigid body of "
                    f"{other.path.rsplit('.', 1)[0]} (line {other.line})",
                )
            bodies[body] = body_node
            drones.append(
                m.Drone(name=name, uri=uri, rigid_body=body, start=self.vec2(e["start"]), goal=self.vec2(e["goal"]))
            )
        return tuple(drones)

    def formation(self, node: YNode) -> tuple[m.Formation, tuple[m.Drone, ...]]:
        e = self.mapping(node, FORMATION_KEYS, required=("kind", "count", "radius"))
        kwargs: dict[str, Any] = {
            "kind": self.choice(e["kind"], FORMATION_KINDS, what="formation kind"),
            "count": self.integer(e["count"], 1, MAX_FORMATION_COUNT),
            "radius": self.number(e["radius"], POSITIVE),
        }
        if "center" in e:
            kwargs["center"] = self.vec2(e["center"])
        if "phase_deg" in e:
            kwargs["phase_deg"] = self.number(e["phase_deg"])
        if "name_prefix" in e:
            kwargs["name_prefix"] = self.drone_name(e["name_prefix"], "name_prefix")
        if "uri_base" in e:
            kwargs["uri_base"] = self.string(e["uri_base"])
        formation = m.Formation(**kwargs)
        try:
            parse_uri(formation.uri_base + "01")
        except ValueError as exc:
            at = e.get("uri_base", node)
            raise self.error(
                at,
                "formation.uri_base",
                f"{formation.uri_base!r} followed by the drone number as 2 hex digits must be a URI: {exc}",
            ) from None
        return formation, expand_formation(formation)

    # -- the whole file -------------------------------------------------------------------------------------

    def parse(self, root: YNode, text: str, source: Path | None) -> m.Mission:
        if not root.is_map:
            raise self.error(
                root,
                ROOT,
                f"expected a mapping of mission keys (name, arena, drones, ...) at the top level, got {describe(root)}",
            )
        entries = self.mapping(root, TOP_KEYS, required=("arena",))
        if "drones" in entries and "formation" in entries:
            second = max(entries["drones"], entries["formation"], key=lambda n: n.key_line)
            raise self.error(second.key_line, second.path, "give either `drones` or `formation`, not both")
        if "drones" not in entries and "formation" not in entries:
            raise self.error(root.key_line, "drones", "missing: give a `drones` list or a `formation`")
        self.index(root)

        parts: dict[str, Any] = {
            "flight": m.FlightSettings(),
            "planner": m.PlannerSettings(),
            "mocap": m.MocapSettings(),
            "radio": m.RadioSettings(),
            "sim": m.SimSettings(),
            "safety": m.SafetySettings(),
            "obstacles": (),
            "formation": None,
            "name": source.stem if source is not None else "mission",
        }
        readers: dict[str, Callable[[YNode], Any]] = {
            "name": self.string,
            "arena": self.arena,
            "planner": self.planner,
            "mocap": self.mocap,
            "obstacles": self.obstacles,
            "drones": self.drones,
            "formation": self.formation,
            "flight": lambda n: self.settings(n, m.FlightSettings, FLIGHT_SPEC),
            "radio": lambda n: self.settings(n, m.RadioSettings, RADIO_SPEC),
            "sim": lambda n: self.settings(n, m.SimSettings, SIM_SPEC),
            "safety": lambda n: self.settings(n, m.SafetySettings, SAFETY_SPEC),
            "runtime": self.runtime,
            "dry_run": self.dry_run,
        }
        for key, node in entries.items():  # document order
            parts[key] = readers[key](node)
        if "planner" not in entries and parts["planner"].kind in m.POLICY_KINDS:
            parts["planner"] = dataclasses.replace(
                parts["planner"], policy=self.default_policy(parts["planner"].kind, root.key_line, True)
            )
        if "formation" in entries:
            parts["formation"], parts["drones"] = parts["formation"]

        mission = m.Mission(source=source, text=text, **parts)
        check_layout(mission, self.layout_error(mission, entries))
        if mission.radio.extpos == "packed":
            self.packed_extpos(mission, entries.get("radio", root.key_line))
        return mission

    def packed_extpos(self, mission: m.Mission, at: YNode | int) -> None:
        """``radio.extpos: packed``: every drone's id (its address's last byte) its own on its channel, and the
        arena within the int16 millimetres a packed position carries (rpf_fly/radio/packed_extpos.py)."""
        from rpf_fly.radio.packed_extpos import MAX_MM, shared_ids

        for channel, ident, names in shared_ids({d.name: d.uri for d in mission.drones}):
            raise self.error(
                at,
                "radio.extpos",
                f"packed: drones {' and '.join(names)} both have id 0x{ident:02X} "
                f"(the last byte of their radio address) on channel {channel}; the firmware takes a "
                "packed position by that byte, so each would fly on the other's: give them addresses "
                "with different last bytes, or use extpos",
            )
        reach = max(abs(v) for v in (*mission.arena.x, *mission.arena.y, *mission.arena.z))
        if reach * 1000.0 > MAX_MM:
            raise self.error(
                at,
                "radio.extpos",
                f"packed: positions go as int16 millimetres (+-{MAX_MM / 1000} m) "
                f"and the arena reaches {reach:g} m: use extpos",
            )

    def index(self, node: YNode) -> None:
        self.nodes[node.path] = node
        if node.is_map:
            for child in node.mapping.values():
                self.index(child)
        elif node.is_seq:
            for child in node.seq:
                self.index(child)

    def layout_error(self, mission: m.Mission, entries: dict[str, YNode]) -> LayoutError:
        def make(path: str, message: str, at: Sequence[str] = ()) -> MissionError:
            if path.startswith("drones[") and mission.formation is not None:
                index = int(path[len("drones[") : path.index("]")])
                line = entries["formation"].key_line
                return MissionError(self.file, line, "formation", f"{path} ({mission.drones[index].name}): {message}")
            for candidate in (path, *at):
                if candidate in self.nodes:
                    return MissionError(self.file, self.nodes[candidate].line, path, message)
            return MissionError(self.file, 1, path, message)

        return make


def expand_formation(formation: m.Formation) -> tuple[m.Drone, ...]:
    """The explicit drones of a formation. ``circle_swap``: drone i (0-based) is ``f"{prefix}{i+1}"`` with URI
    ``uri_base + f"{i+1:02X}"``, starts at ``center + radius (cos t, sin t)`` with
    ``t = phase + 2 pi i / count`` and flies to the antipode ``center - radius (cos t, sin t)``."""
    cx, cy = formation.center
    drones = []
    for i in range(formation.count):
        t = math.radians(formation.phase_deg) + 2.0 * math.pi * i / formation.count
        dx, dy = formation.radius * math.cos(t), formation.radius * math.sin(t)
        name = f"{formation.name_prefix}{i + 1}"
        drones.append(
            m.Drone(
                name=name,
                uri=f"{formation.uri_base}{i + 1:02X}",
                rigid_body=name,
                start=(cx + dx, cy + dy),
                goal=(cx - dx, cy - dy),
            )
        )
    return tuple(drones)
