"""The radio budget per dongle: what a mission asks of each Crazyradio against what it carries under cflib 0.1.34,
from the dongle's figures (docs/radio.md, "Radio budget").

What a dongle's time goes to (cflib 0.1.34, ``cflib/crtp/radiodriver.py``; the figures of
rpf_fly/emulator/crazyradio_timing.py, each with its source):
- every packet is one transaction of the dongle's shared radio thread, and the links of a dongle take turns, so
  almost every transaction first switches the dongle's address: a USB control transfer (about 1 ms on a PA, 2.5 ms
  on a 2.0) before the bulk write, the radio's attempts and the bulk read;
- per drone: streamed setpoints (``flight.rate_hz``), extpos (``radio.extpos_rate_hz``; none under packed extpos),
  cflib's latency ping (`LINK_PING_HZ`), the emergency-stop keep-alive (`KEEPALIVE_HZ`); telemetry and the pings'
  echoes ride on the acknowledgements (their bytes count as air time);
- packed extpos (``radio.extpos: packed``): one broadcast per group of up to four drones per extpos slot, each an
  address switch and four unanswered attempts (rpf_fly/radio/broadcast.py);
- lost attempts, at `EXPECTED_ATTEMPT_LOSS`, cost the radio's retries;
- polls: an idle link polls back to back (a Crazyflie's ack is never empty), so the backend opens every
  ``radio://`` link with cflib's ``?rate_limit=N`` (`link_uri`): each link then makes at most N transactions a
  second, polls included, and the queue stays short enough for the setpoints and the broadcasts.

``needed`` counts the transactions a second the mission's traffic needs; ``budget`` is what the dongle carries of
that mix (one second over the mix's mean transaction time). A lab that measured its own dongle (``rpf-fly radio
probe``: transactions a second with its links taking turns) gives it as ``radio.budget_packets_s``, and every
figure's time is scaled by the figures' own ceiling for that (a smallest transaction behind an address switch) over
the lab's. Each dongle's rate limits and its setpoint
latency come from the model of its shared radio thread (rpf_fly/radio/dongle_model.py), over a few seconds of the
mission's traffic. A dongle is over budget when its traffic takes more than `USE_LIMIT` of its time, or when the
model's setpoints wait longer than a planning period, its extpos longer than an extpos period, or newer ones
replace them before they go out.

Pure: mission in, numbers out. The CLI prints the table (``rpf-fly check``) and refuses (``fly``, ``check``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from functools import lru_cache
from urllib.parse import parse_qs

from rpf_fly.mission.model import Mission
from rpf_fly.radio.dongle_model import LinkTraffic, Run, Timing, Traffic, simulate, timing_of
from rpf_fly.radio.packed_extpos import BROADCAST_COPIES, ITEM, packed_groups, parse_link

DEFAULT_DONGLE_TYPE = "crazyradio_pa"
"""``radio.dongle_type`` when a mission says none."""

LINK_PING_HZ = 10.0
"""cflib's latency ping (port 15 echo), sent on every link every 0.1 s while connected (cflib 0.1.34,
``link_statistics.Latency``)."""

KEEPALIVE_HZ = 5.0
"""The emergency-stop keep-alive of each armed drone (`cflib_backend.KEEPALIVE_PERIOD_S`, 0.2 s)."""

STATUS_TELEMETRY_HZ = 10.0
"""The status log block each drone sends (battery, supervisor, estimate): `CflibBackend`'s default period."""

EXPECTED_ATTEMPT_LOSS = 0.046
"""Share of radio attempts lost, retries included, on a lab's link: docs/radio.md "Bursty loss" (4.6 %, the dry
run's loss model, `BurstLoss.retried_loss(3)`)."""

USE_LIMIT = 0.9
"""The share of a dongle's time a mission may plan for: the rest is for what the expectation leaves out (a loss
burst of 60 % for 30 ms about once a second, docs/radio.md "Bursty loss"; the flight's commands: take-off,
hand-over, landing)."""

RATE_LIMIT_FACTORS = (1.25, 1.5, 2.0, 3.0, 4.0, 6.0)
"""A link's ``rate_limit`` is its packets a second times one of these: the one whose modelled setpoint latency is
lowest (a low limit leaves a queued packet waiting out the link's sleep, a high one lets polls crowd the queue)."""

SETPOINT_BYTES, EXTPOS_BYTES, EXTPOSE_BYTES, PING_BYTES, KEEPALIVE_BYTES = 18, 13, 30, 10, 2
"""CRTP packets (header included): a position setpoint ``<Bffff``, extpos ``<fff``, extpose ``<Bfffffff``, cflib's
ping ``<Bd``, the keep-alive ``[0x04]``."""

STATUS_BYTES = 28
"""The status log packet on the acknowledgement: block id, 3-byte timestamp, 23 bytes of values."""

SUPERSEDED_LIMIT = 0.01
"""The share of setpoints the model may see replaced before the radio took them: one in a hundred is a queue that
keeps up (the drone flies on the newer one)."""

EXTPOS_DELIVERED_LIMIT = 0.9
"""The share of the planned extpos that must go out in the model (a replaced one is a position the estimator did not
get; with nine in ten out, no two in a row are missed unless the queue is behind)."""

MODEL_SECONDS = 4.0
"""Seconds of traffic the model runs per dongle (after half a second of warm-up)."""


@dataclass(frozen=True)
class DongleLoad:
    """One dongle's share of a mission, per second."""

    dongle: int
    drones: tuple[str, ...]
    radio_type: str
    setpoints: float
    extpos: float
    """Unicast extpos / extpose packets (none under packed extpos)."""
    broadcasts: float
    """Packed extpos packets (one per group of up to four drones per extpos slot)."""
    pings: float
    keepalives: float
    busy_s: float
    """Seconds of the dongle's time that traffic takes, address switches and expected retries included."""
    budget: float
    """Transactions a second the dongle carries of this mix."""
    measured: bool
    """``budget`` is scaled to the lab's ``radio.budget_packets_s``."""
    rate_limits: Mapping[str, int] = field(default_factory=dict)
    """Drone name -> the ``rate_limit`` its ``radio://`` link is opened with."""
    setpoint_p50_s: float = math.nan
    setpoint_p99_s: float = math.nan
    extpos_p99_s: float = math.nan
    """Modelled: a tick's setpoint from the tick to the drone, an extpos from the mocap frame to the drone."""
    setpoint_period_s: float = math.inf
    extpos_period_s: float = math.inf
    setpoints_superseded: float = 0.0
    """Share of the model's setpoints replaced by newer ones before the radio took them."""
    extpos_delivered: float = 1.0
    """Share of the model's extpos that went out (the others were replaced by newer ones on the way)."""

    @property
    def needed(self) -> float:
        """Transactions a second this dongle must carry."""
        return self.setpoints + self.extpos + self.broadcasts + self.pings + self.keepalives

    @property
    def use(self) -> float:
        """Needed over budget (1.0 = full)."""
        return self.needed / self.budget

    @property
    def late(self) -> bool:
        """The model's setpoints or extpos miss their period, or newer ones replace them."""
        return (
            self.setpoint_p99_s > self.setpoint_period_s
            or self.setpoints_superseded > SUPERSEDED_LIMIT
            or self.extpos_p99_s > self.extpos_period_s
            or self.extpos_delivered < EXTPOS_DELIVERED_LIMIT
        )

    @property
    def over(self) -> bool:
        return self.use > USE_LIMIT or self.late


def dongle_of(uri: str) -> int:
    """The dongle number of a ``radio://N/...`` or ``fake://N/...`` URI (the mission loader has checked it)."""
    return int(uri.partition("://")[2].split("/", 1)[0])


def uri_rate_limit(uri: str) -> int | None:
    """The ``rate_limit`` a URI's query sets (cflib's ``RadioDriver.parse_uri`` reads it as an integer)."""
    values = parse_qs(uri.partition("?")[2]).get("rate_limit")
    return int(values[0]) if values else None


def link_uri(uri: str, rate_limit: int | None) -> str:
    """The URI a ``radio://`` link is opened with: ``?rate_limit=N`` added (``&`` when it has a query) unless it has
    one already; other schemes and None unchanged."""
    if rate_limit is None or not uri.startswith("radio://") or uri_rate_limit(uri) is not None:
        return uri
    return f"{uri}{'&' if '?' in uri else '?'}rate_limit={int(rate_limit)}"


def _timing(radio_type: str, rate: str) -> Timing:
    from rpf_fly.emulator.crazyradio_timing import RADIO_TYPES  # the figures' one table (pure data)

    return timing_of(RADIO_TYPES[radio_type], rate)


def _expected_s(timing: Timing, up: int, switching: bool, arc: int = 3) -> float:
    """One acknowledged transaction of ``up`` bytes with a one-byte ack, at `EXPECTED_ATTEMPT_LOSS`."""
    p = EXPECTED_ATTEMPT_LOSS
    lost = sum(p**k for k in range(1, arc + 1))
    retry = (timing.ramp_s + timing.on_air_s(up) + timing.wait_s) * timing.scale
    return timing.transaction_s(up, 1, 1, True) + lost * retry + (timing.switch_s(1) if switching else 0.0)


def radio_loads(mission: Mission) -> list[DongleLoad]:
    """Every dongle the mission uses, in dongle order."""
    uris = {d.name: d.uri for d in mission.drones}
    per: dict[int, list[str]] = {}
    for name, uri in uris.items():
        per.setdefault(dongle_of(uri), []).append(name)
    radio = mission.radio
    return [
        _dongle_load(
            dongle,
            tuple((n, uris[n]) for n in names),
            radio.dongle_type,
            radio.extpos,
            radio.extpos_rate_hz,
            mission.flight.rate_hz,
            mission.mocap.rate_hz,
            radio.budget_packets_s,
        )
        for dongle, names in sorted(per.items())
    ]


CONNECT_TRANSACTIONS = 1000
"""What one drone's connection takes of its dongle's transactions: cflib reads the log and parameter TOCs (an
entry a request and its answer, unless the TOC cache has them) and every parameter's value (about 300 parameters on
a current firmware, two transactions each), then the flight's configuration. Drones connect in parallel, so a
dongle's drones all wait for the sum: 8 drones on one emulated Crazyradio PA (100 parameters each) connected after
15.7 s cold and 6.3 s with their TOCs cached."""

CONNECT_MARGIN = 2.0
"""A connection is given this many times its share of the dongle before it is called timed out."""


def connect_timeouts(mission: Mission, floor_s: float) -> dict[str, float]:
    """Drone name -> how long its connection may take: ``floor_s``, or, where its dongle is shared, `CONNECT_MARGIN`
    times the dongle's time for every drone on it to connect (`CONNECT_TRANSACTIONS` each at the budget's rate):
    a flat 10 s timed out all 8 drones of circle-8-r3 on one Crazyradio PA while they were still connecting."""
    return {
        name: max(floor_s, CONNECT_MARGIN * len(load.drones) * CONNECT_TRANSACTIONS / load.budget)
        for load in radio_loads(mission)
        for name in load.drones
    }


def link_rate_limits(mission: Mission) -> dict[str, int]:
    """Drone name -> the ``rate_limit`` of its ``radio://`` link (the budget's choice or the URI's own)."""
    return {name: limit for load in radio_loads(mission) for name, limit in load.rate_limits.items()}


@lru_cache(maxsize=64)
def _dongle_load(
    dongle: int,
    drones: tuple[tuple[str, str], ...],
    radio_type: str,
    mode: str,
    extpos_hz: float,
    setpoint_hz: float,
    frame_hz: float,
    measured_budget: float | None,
) -> DongleLoad:
    names = tuple(n for n, _ in drones)
    uris = dict(drones)
    n = len(names)
    rate = min(extpos_hz, frame_hz)  # at most one extpos a frame
    packed = mode == "packed"
    groups = [g for g in packed_groups(uris) if g.dongle == dongle] if packed else []
    air_rate = parse_link(drones[0][1]).rate
    timing = _timing(radio_type, air_rate)
    switching = n > 1 or packed
    unicast_bytes = EXTPOSE_BYTES if mode == "extpose" else EXTPOS_BYTES
    per_drone = {
        "setpoints": setpoint_hz,
        "extpos": 0.0 if packed else rate,
        "pings": LINK_PING_HZ,
        "keepalives": KEEPALIVE_HZ,
    }
    sizes = {"setpoints": SETPOINT_BYTES, "extpos": unicast_bytes, "pings": PING_BYTES, "keepalives": KEEPALIVE_BYTES}
    busy = n * sum(hz * _expected_s(timing, sizes[kind], switching) for kind, hz in per_drone.items())
    downlink_bits = n * (STATUS_TELEMETRY_HZ * (STATUS_BYTES - 1) + LINK_PING_HZ * (PING_BYTES - 1)) * 8
    busy += downlink_bits / timing.rate_bps * timing.scale
    broadcasts = len(groups) * rate
    for group in groups:
        up = 1 + ITEM.size * len(group.names)
        busy += rate * (timing.transaction_s(up, 0, BROADCAST_COPIES, False) + timing.switch_s(1))
    needed = n * sum(per_drone.values()) + broadcasts
    if measured_budget is not None:  # the lab's probe against the figures' own ceiling: every time scaled by that
        ceiling = 1.0 / (timing.switch_s(1) + timing.transaction_s(1, 1, 1, True))
        timing = replace(timing, scale=ceiling / measured_budget)
        busy *= ceiling / measured_budget
    budget = needed / busy if busy > 0 else math.inf
    load = DongleLoad(
        dongle,
        names,
        radio_type,
        n * setpoint_hz,
        n * per_drone["extpos"],
        broadcasts,
        n * LINK_PING_HZ,
        n * KEEPALIVE_HZ,
        busy,
        budget,
        measured_budget is not None,
        setpoint_period_s=1.0 / setpoint_hz,
        extpos_period_s=1.0 / rate,
    )
    return _with_model(load, uris, groups, timing, mode, rate, setpoint_hz, frame_hz, sum(per_drone.values()))


def _with_model(
    load: DongleLoad,
    uris: Mapping[str, str],
    groups: list,
    timing: Timing,
    mode: str,
    rate: float,
    setpoint_hz: float,
    frame_hz: float,
    packets_hz: float,
) -> DongleLoad:
    """The load with its rate limits and modelled latencies: each candidate limit (`RATE_LIMIT_FACTORS`, or the
    URIs' own) run through the dongle model, the lowest setpoint latency taken among those on time (`DongleLoad.late`
    false), else among all."""
    from rpf_fly.radio.schedule import extpos_phases  # (schedule imports this module)

    names = load.drones
    phases = extpos_phases({n: uris[n] for n in names}, packed=mode == "packed")
    own = {n: uri_rate_limit(uris[n]) for n in names}
    unicast_bytes = EXTPOSE_BYTES if mode == "extpose" else EXTPOS_BYTES
    group_phase = {g.names[0]: phases[g.names[0]] for g in groups}
    broadcasts = tuple((group_phase[g.names[0]], 1 + ITEM.size * len(g.names), g.channel, g.rate) for g in groups)
    best: tuple[tuple[bool, float], dict[str, int], Run] | None = None
    for factor in RATE_LIMIT_FACTORS:
        limits = {n: own[n] or max(1, math.ceil(packets_hz * factor)) for n in names}
        links = []
        for name in names:
            link = parse_link(uris[name])
            links.append(
                LinkTraffic(
                    (link.channel, link.rate, link.address),
                    limits[name],
                    setpoint_bytes=SETPOINT_BYTES,
                    extpos_hz=0.0 if mode == "packed" else rate,
                    extpos_phase=phases[name],
                    extpos_bytes=unicast_bytes,
                    ping_hz=LINK_PING_HZ,
                    ping_bytes=PING_BYTES,
                    keepalive_hz=KEEPALIVE_HZ,
                    keepalive_bytes=KEEPALIVE_BYTES,
                    status_hz=STATUS_TELEMETRY_HZ,
                    status_bytes=STATUS_BYTES,
                )
            )
        traffic = Traffic(
            tuple(links), setpoint_hz, frame_hz, rate, broadcasts, loss=EXPECTED_ATTEMPT_LOSS, copies=BROADCAST_COPIES
        )
        run = simulate(traffic, timing, seconds=MODEL_SECONDS)
        on_time = (
            run.setpoints_superseded <= SUPERSEDED_LIMIT
            and run.extpos_delivered >= EXTPOS_DELIVERED_LIMIT
            and run.setpoint_p(0.99) <= load.setpoint_period_s
            and run.extpos_p(0.99) <= load.extpos_period_s
        )
        score = (not on_time, run.setpoint_p(0.99))
        if best is None or score < best[0]:
            best = (score, limits, run)
        if all(own.values()):
            break  # the URIs set their own: nothing to choose
    assert best is not None
    _, limits, run = best
    return replace(
        load,
        rate_limits=limits,
        setpoint_p50_s=run.setpoint_p(0.5),
        setpoint_p99_s=run.setpoint_p(0.99),
        extpos_p99_s=run.extpos_p(0.99),
        setpoints_superseded=run.setpoints_superseded,
        extpos_delivered=run.extpos_delivered,
    )


def over_budget_message(load: DongleLoad, mission_name: str = "") -> str:
    """One line naming the dongle, what it needs and what it has, and the ways out."""
    n = len(load.drones)
    extpos = "packed extpos at radio.extpos_rate_hz" if load.broadcasts else "extpos at radio.extpos_rate_hz"
    why = (
        f"needs {load.needed:.0f} transactions/s ({load.needed / n:.0f} a drone: setpoints at flight.rate_hz, "
        f"{extpos}, cflib's {LINK_PING_HZ:.0f} pings, {KEEPALIVE_HZ:.0f} keep-alives) and a {load.radio_type} "
        f"carries about {load.budget:.0f} of them ({load.use:.0%}, at most {USE_LIMIT:.0%} planned)"
    )
    if load.use <= USE_LIMIT:
        why = (
            f"would hold its setpoints {load.setpoint_p99_s * 1e3:.0f} ms (p99; a planning period is "
            f"{load.setpoint_period_s * 1e3:.0f} ms) and its extpos {load.extpos_p99_s * 1e3:.0f} ms (an extpos "
            f"period is {load.extpos_period_s * 1e3:.0f} ms) with {load.needed:.0f} transactions/s of "
            f"{load.budget:.0f}"
        )
    names = ", ".join(load.drones) if n <= 4 else f"{load.drones[0]}, ..., {load.drones[-1]}"
    return (
        f"radio dongle {load.dongle} ({n} drones: {names}) {why}: lower the rates, set radio.extpos: packed, "
        f"spread the drones over more dongles (the URI's first number), or set radio.allow_over_budget: true"
    )


def budget_table(loads: list[DongleLoad]) -> list[str]:
    """Plain lines for ``rpf-fly check``: a header, then one per dongle."""
    rows = [
        [
            "dongle",
            "radio",
            "drones",
            "setpoints/s",
            "extpos/s",
            "packed/s",
            "pings+keep-alives/s",
            "needed/s",
            "carries/s",
            "use",
            "rate_limit",
            "setpoint ms p50/p99",
            "extpos ms p99",
        ]
    ]
    for load in loads:
        limits = sorted(set(load.rate_limits.values()))
        limit = f"{limits[0]}" if len(limits) == 1 else f"{limits[0]}-{limits[-1]}"
        rows.append(
            [
                str(load.dongle),
                load.radio_type,
                str(len(load.drones)),
                f"{load.setpoints:.0f}",
                f"{load.extpos:.0f}",
                f"{load.broadcasts:.0f}",
                f"{load.pings + load.keepalives:.0f}",
                f"{load.needed:.0f}",
                f"{load.budget:.0f}{'*' if load.measured else ''}",
                f"{load.use:.0%}",
                limit,
                f"{_ms(load.setpoint_p50_s)}/{_ms(load.setpoint_p99_s)}",
                _ms(load.extpos_p99_s),
            ]
        )
    widths = [max(len(row[k]) for row in rows) for k in range(len(rows[0]))]
    lines = [
        "  ".join(cell.ljust(w) if k == 1 else cell.rjust(w) for k, (cell, w) in enumerate(zip(row, widths)))
        for row in rows
    ]
    lines = [lines[0]] + [line + ("  OVER BUDGET" if load.over else "") for line, load in zip(lines[1:], loads)]
    if any(load.measured for load in loads):
        lines.append("* scaled to radio.budget_packets_s, the lab's own figure")
    return lines


def _ms(seconds: float) -> str:
    return "-" if math.isnan(seconds) else f"{seconds * 1e3:.0f}"
