"""What the flight sends each dongle, and when: the extpos schedule and the measured load per dongle (pure).

Why: a Crazyradio carries about 1000 transactions a second shared by every drone on it (budget.py), and what
matters is not only the mean but the bursts. Setpoints go out at every planning tick (``flight.rate_hz``), all
drones at once: their latency is what the drones feel. Extpos goes out at its own rate (``radio.extpos_rate_hz``,
30 Hz by default against 100 Hz of mocap), and without a schedule every drone's extpos fell on the same mocap
frame: with 10 drones a burst of 10 packets on the dongle every third or fourth frame (10 ms of air at 1 ms a
transaction), sometimes on a planning tick's frame, behind its setpoints. The rate also missed its figure: a drone
sent when ``now - last >= 1 / rate``, so with frames every 10 ms a 30 Hz extpos went out every 40 ms (25 Hz), and
jitter made it vary; the budget counted 30.

The schedule: drone ``k`` of the ``n`` drones on its dongle (in mission order) owns the extpos slots
``floor(t * rate + (k + 1/2) / n)``: its extpos goes out on the first frame of each new slot. So

- each drone sends exactly ``rate`` extpos a second over any whole number of seconds (one per slot; at most one a
  frame, so with mocap slower than ``rate`` it sends one on every frame, fewer than the budget counts);
- the drones of a dongle are spread evenly over the extpos period: the slot boundaries of its ``n`` drones are
  ``1 / (n * rate)`` apart, so a frame carries at most ``ceil(n * rate / frame_rate)`` of its extpos (3 of 10
  drones at 30 Hz on 100 Hz mocap; 10 at once before);
- drones on different dongles are phased by their own dongle's share, since they use other radios.

The measured side: cflib's radio link statistics (``uplink_rate``, ``uplink_congestion``, every 0.1 s per link)
give each link's transactions (packets and empty polls) and its packets with data; :func:`dongle_loads` adds them up
per dongle for the log (``/radio/<dongle>``, docs/log-format.md).

Pure: times are passed in, nothing here sleeps, reads a clock or touches a radio.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

from rpf_fly.radio.budget import dongle_of
from rpf_fly.radio.packed_extpos import packed_groups


def extpos_phases(uris: Mapping[str, str], packed: bool = False) -> dict[str, float]:
    """Drone name -> its phase in [0, 1) of the extpos period: ``(k + 1/2) / n`` for drone ``k`` (in the order
    given) of the ``n`` drones on its dongle (the URI's first number). The half keeps the slot boundaries off the
    frames for the usual rates (30 Hz extpos on 100 Hz mocap: a boundary on a frame would fall on either side of it
    by a rounding error and put one more extpos on that frame). ``packed`` (``radio.extpos: packed``): the same
    for the packed groups of a dongle (`packed_extpos.packed_groups`, up to four drones a packet), every drone of a
    group in its group's phase, so a group's positions come due on the same frame and go out in one packet."""
    per: dict[int, list[tuple[str, ...]]] = {}
    if packed:
        for group in packed_groups(uris):
            per.setdefault(group.dongle, []).append(group.names)
    else:
        for name, uri in uris.items():
            per.setdefault(dongle_of(uri), []).append((name,))
    return {name: (k + 0.5) / len(units) for units in per.values() for k, unit in enumerate(units) for name in unit}


def extpos_slot(t_s: float, rate_hz: float, phase: float) -> int:
    """The extpos slot a drone of ``phase`` is in at time ``t_s``: it sends one extpos per slot."""
    return math.floor(t_s * rate_hz + phase)


def frame_share(drones: int, rate_hz: float, frame_rate_hz: float) -> int:
    """The most extpos of one dongle's ``drones`` that one mocap frame carries under the schedule (frames evenly
    spaced): ``ceil(drones * rate / frame_rate)``, at most ``drones``."""
    return min(drones, math.ceil(drones * rate_hz / frame_rate_hz - 1e-9))


@dataclass
class ExtposSchedule:
    """The extpos schedule of one flight (module docstring). ``rate_hz``: ``radio.extpos_rate_hz``; ``phases``:
    :func:`extpos_phases` of the flight's drones."""

    rate_hz: float
    phases: Mapping[str, float]
    _last: dict[str, int] = field(default_factory=dict)

    @classmethod
    def for_uris(cls, rate_hz: float, uris: Mapping[str, str], packed: bool = False) -> ExtposSchedule:
        return cls(float(rate_hz), extpos_phases(uris, packed))

    def due(self, name: str, t_s: float) -> bool:
        """Whether ``name``'s extpos goes out with the frame at ``t_s`` (True at most once per slot; a drone's first
        frame is always due). Call it only for drones that get an extpos when due: a True is taken as sent."""
        slot = extpos_slot(t_s, self.rate_hz, self.phases.get(name, 0.0))
        last = self._last.get(name)
        if last is not None and slot <= last:
            return False
        self._last[name] = slot
        return True


# ------------------------------------------------------------------------------------------- measured load


@dataclass(frozen=True)
class LinkCount:
    """One link's radio traffic since it connected, from cflib's link statistics: ``transactions`` (every
    acknowledged transaction, empty polls included: the dongle's air it used), ``packets`` (those with an uplink
    packet: setpoints, extpos, commands, cflib's pings)."""

    uri: str
    transactions: float
    packets: float
    superseded: float = 0.0
    """Setpoints replaced by a newer one before the radio took them (the drone's outbox: the radio lagged)."""


@dataclass(frozen=True)
class MeasuredLoad:
    """One dongle's measured traffic over one window of the log (``/radio/<dongle>``)."""

    dongle: int
    drones: tuple[str, ...]
    window_s: float
    packets: float
    transactions: float
    superseded: float = 0.0
    """Setpoints of the dongle's drones superseded before the radio took them, in the window."""

    @property
    def packets_per_s(self) -> float:
        return self.packets / self.window_s if self.window_s > 0 else 0.0

    @property
    def transactions_per_s(self) -> float:
        return self.transactions / self.window_s if self.window_s > 0 else 0.0


def dongle_loads(
    before: Mapping[str, LinkCount], after: Mapping[str, LinkCount], window_s: float, dongles: Iterable[int] = ()
) -> list[MeasuredLoad]:
    """Each dongle's traffic between two samples of the links' counts (drone name -> :class:`LinkCount`), in dongle
    order; ``dongles``: dongles to report even with no link counted yet (zeros). A drone missing from ``before``
    counts from zero."""
    per: dict[int, list[tuple[str, float, float, float]]] = {d: [] for d in dongles}
    for name, now in after.items():
        then = before.get(name)
        packets = now.packets - (then.packets if then is not None else 0.0)
        transactions = now.transactions - (then.transactions if then is not None else 0.0)
        superseded = now.superseded - (then.superseded if then is not None else 0.0)
        per.setdefault(dongle_of(now.uri), []).append(
            (name, max(0.0, packets), max(0.0, transactions), max(0.0, superseded))
        )
    return [
        MeasuredLoad(
            dongle,
            tuple(row[0] for row in rows),
            window_s,
            sum(row[1] for row in rows),
            sum(row[2] for row in rows),
            sum(row[3] for row in rows),
        )
        for dongle, rows in sorted(per.items())
    ]
