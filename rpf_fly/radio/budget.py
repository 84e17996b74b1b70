"""The radio budget: what a mission asks of each Crazyradio, against what one carries.

Why: every packet to a Crazyflie is one radio transaction with an acknowledgement, all links on one dongle take
turns, and cflib has no broadcast, so a dongle's capacity is shared by every drone on it. Bitcraze's figures
(github.com/bitcraze/crazyradio2-firmware/issues/9, /16, /22 and /pull/25): about 1000 transactions a second per
radio in total. A mission over that does not fail loudly: setpoints and extpos queue up, latency grows, and the
estimators starve of mocap until the drones drift (the dry run's radio, with its 1 ms air time, shows it). So the
load is computed before anything connects and a mission over budget is refused unless it says
``radio.allow_over_budget: true``.

What counts, per drone, every second:
- the streamed setpoints: ``flight.rate_hz`` (one packet each);
- extpos / extpose: ``radio.extpos_rate_hz`` (one localization packet each), sent on the schedule of
  ``rpf_fly.radio.schedule`` (exactly that many a second, spread over the period across a dongle's drones);
- cflib's latency ping: 10 a second per link (``cflib.crazyflie.link_statistics.Latency``, started on every
  connection: an echo packet every 0.1 s);
- the status telemetry (log blocks, 10 Hz): downlink, carried on the acknowledgements of the packets above; it
  costs a transaction of its own only where a drone sends less than it receives, which this stack never does at
  7.5 Hz or more of setpoints (shown in the table, counted only then);
- cflib's empty polls fill the gaps between packets (every 10 ms when a link is idle): they yield to real packets
  and are not counted.

Pure: mission in, numbers out. The CLI prints the table (``rpf-fly check``) and refuses (``fly``, ``check``).
"""

from __future__ import annotations

from dataclasses import dataclass

from rpf_fly.mission.model import Mission

DONGLE_BUDGETS: dict[str, float] = {
    "crazyradio_pa": 1000.0,
    "crazyradio_2": 1000.0,
}
"""Transactions a second one dongle carries, shared by all its links (both radios: about 1000 with cflib; the
Crazyradio 2.0's inline mode raises a single link's rate, not the dongle's total). ``radio.budget_packets_s``
overrides it with a figure measured in your lab."""

LINK_PING_HZ = 10.0
"""cflib's latency ping (port 15 echo), sent on every link every 0.1 s while connected (cflib 0.1.34)."""

STATUS_TELEMETRY_HZ = 10.0
"""The status log block each drone sends (battery, supervisor, estimate): `CflibBackend`'s default period."""


@dataclass(frozen=True)
class DongleLoad:
    """One dongle's share of a mission, in packets a second."""

    dongle: int
    drones: tuple[str, ...]
    setpoints: float
    extpos: float
    pings: float
    """cflib's latency pings (`LINK_PING_HZ` per link)."""
    telemetry: float
    """Downlink packets; they ride on the uplink's acknowledgements (see :attr:`telemetry_transactions`)."""
    telemetry_transactions: float
    """Downlink packets that need a transaction of their own (a drone receiving more than it sends)."""
    budget: float
    radio_type: str

    @property
    def needed(self) -> float:
        """Transactions a second this dongle must carry."""
        return self.setpoints + self.extpos + self.pings + self.telemetry_transactions

    @property
    def use(self) -> float:
        """Needed over budget (1.0 = full)."""
        return self.needed / self.budget

    @property
    def over(self) -> bool:
        return self.needed > self.budget


def dongle_of(uri: str) -> int:
    """The dongle number of a ``radio://N/...`` or ``fake://N/...`` URI (the mission loader has checked it)."""
    return int(uri.partition("://")[2].split("/", 1)[0])


def radio_loads(mission: Mission) -> list[DongleLoad]:
    """Every dongle the mission uses, in dongle order."""
    per: dict[int, list[str]] = {}
    for drone in mission.drones:
        per.setdefault(dongle_of(drone.uri), []).append(drone.name)
    radio = mission.radio
    budget = radio.budget_packets_s if radio.budget_packets_s is not None else DONGLE_BUDGETS[radio.dongle_type]
    setpoint_hz, extpos_hz = mission.flight.rate_hz, radio.extpos_rate_hz
    own_transactions = max(0.0, STATUS_TELEMETRY_HZ - (setpoint_hz + extpos_hz + LINK_PING_HZ))
    loads = []
    for dongle in sorted(per):
        names = tuple(per[dongle])
        n = len(names)
        loads.append(DongleLoad(dongle, names, n * setpoint_hz, n * extpos_hz, n * LINK_PING_HZ, n * STATUS_TELEMETRY_HZ,
                                n * own_transactions, budget, radio.dongle_type))
    return loads


def over_budget_message(load: DongleLoad, mission_name: str = "") -> str:
    """One line naming the dongle, what it needs and what it has, and the ways out."""
    n = len(load.drones)
    per_drone = load.needed / n
    return (f"radio dongle {load.dongle} ({n} drones: {', '.join(load.drones)}) needs {load.needed:.0f} packets/s "
            f"({per_drone:.0f} a drone: setpoints at flight.rate_hz, extpos at radio.extpos_rate_hz and cflib's "
            f"{LINK_PING_HZ:.0f} pings); a "
            f"{load.radio_type} carries about {load.budget:.0f}: lower the rates, spread the drones over more "
            f"dongles (the URI's first number), or set radio.allow_over_budget: true")


def budget_table(loads: list[DongleLoad]) -> list[str]:
    """Plain lines for ``rpf-fly check``: one per dongle."""
    lines = ["dongle  drones  setpoints/s  extpos/s  pings/s  telemetry/s (on acks)  needed/s  budget/s  use"]
    for load in loads:
        flag = "  OVER BUDGET" if load.over else ""
        lines.append(f"{load.dongle:>6}  {len(load.drones):>6}  {load.setpoints:>11.0f}  {load.extpos:>8.0f}  "
                     f"{load.pings:>7.0f}  "
                     f"{load.telemetry:>21.0f}  {load.needed:>8.0f}  {load.budget:>8.0f}  {load.use:>4.0%}{flag}")
    return lines
