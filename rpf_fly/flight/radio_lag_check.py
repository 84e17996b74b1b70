"""A radio that does not carry a drone's setpoint stream: the drone lands (docs/flight.md, "The supervisor").

A setpoint its outbox replaced by a newer one before the radio link took it never reached the drone: the link took
longer than a planning period to get to it. A few are a busy moment; a steady share means every setpoint the drone
does get is old, and with it every hold the separation check orders. Eight drones on one Crazyradio PA through
cflib's radio driver on a host that could not keep up (136 transactions a second of the 260 the plan needed) had
61 % of their setpoints replaced, the link's echo round trip near 0.5 s: their holds arrived too late and four
drones collided. A high-level landing is one command, and the firmware flies it alone: the drone needs the radio
no more, and the drones still streaming get its share.

A link that takes none of the drone's setpoints at all is worse than late: the firmware levels the drone out 0.5 s
after the last setpoint it received (it drifts at the speed it had) and stops its motors at 2 s (COMMANDER_WDT_TIMEOUT
_STABILIZE, _SHUTDOWN, `commander.c`). The same eight drones, their links taking none of 90 % of their setpoints,
had their motors stopped 1 m up by that watchdog before two windows had passed. So a drone whose setpoint has waited
`SETPOINT_STARVED_S` unsent lands at once: the landing command goes before any setpoint (rpf_fly/radio/outbox.py)."""

from __future__ import annotations

from rpf_fly.flight.agent import DroneAgent
from rpf_fly.flight.events import ERROR, INFO, WARNING
from rpf_fly.flight.findings import Finding
from rpf_fly.flight.phases import DronePhase
from rpf_fly.radio.backend import DroneState

RADIO_LAG_WINDOW_S = 1.0
"""The setpoints superseded are counted over this window (ten planning ticks at 10 Hz)."""

RADIO_LAG_WARN_SHARE = 0.1
"""A window with this share of the drone's setpoints superseded is said (once, until a window under half of it)."""

RADIO_LAG_LAND_SHARE = 0.3
"""Two windows in a row with this share superseded (3 of every 10 setpoints a second never sent): the drone lands."""

RADIO_LAG_LAND_WINDOWS = 2

SETPOINT_STARVED_S = 0.5
"""A streaming drone whose setpoint has waited this long for its link (`DroneState.setpoint_waiting_s`) has had none
for longer: the firmware's level-out (its setpoint 0.5 s old) has begun or is at hand, and its motors stop at 2 s.
It lands at once. A ground station that queues nothing (its loop stalled) leaves nothing waiting: its own watchdog
lands its drones then."""

STREAMING = frozenset({DronePhase.PLANNING, DronePhase.HOLDING, DronePhase.ARRIVED})
"""The phases in which the ground station streams the drone's setpoints (take-off and landing are the firmware's)."""


class RadioLagCheck:
    """Each streaming drone's superseded setpoints over `RADIO_LAG_WINDOW_S` windows (the supervisor runs it)."""

    def __init__(self, rate_hz: float) -> None:
        self.rate_hz = rate_hz
        self._window: dict[str, tuple[float, int]] = {}
        """Drone -> when its open window began and its superseded count then."""
        self._over: dict[str, int] = {}
        """Drone -> windows in a row at or over `RADIO_LAG_LAND_SHARE`."""
        self._said: set[str] = set()
        self._landed: set[str] = set()

    def check(self, now_s: float, agents: list[DroneAgent], states: dict[str, DroneState]) -> list[Finding]:
        out: list[Finding] = []
        for a in agents:
            state = states.get(a.name)
            if a.phase not in STREAMING or state is None or not state.link.up:
                self._window.pop(a.name, None)  # a window counts only what was streamed
                self._over.pop(a.name, None)
                continue
            if state.setpoint_waiting_s >= SETPOINT_STARVED_S and a.name not in self._landed:
                self._landed.add(a.name)
                out.append(
                    Finding(
                        "radio_lag",
                        ERROR,
                        f"its radio link took none of its setpoints for {state.setpoint_waiting_s:.1f} s: the "
                        "firmware levels it out at 0.5 s and stops its motors at 2 s: landing",
                        a.name,
                        "land",
                    )
                )
                continue
            start_s, start = self._window.setdefault(a.name, (now_s, state.setpoints_superseded))
            if now_s - start_s < RADIO_LAG_WINDOW_S:
                continue  # not a whole window yet
            self._window[a.name] = (now_s, state.setpoints_superseded)
            share = (state.setpoints_superseded - start) / max(1.0, self.rate_hz * (now_s - start_s))
            out += self._judge(a.name, share)
        return out

    def _judge(self, name: str, share: float) -> list[Finding]:
        out: list[Finding] = []
        if share >= RADIO_LAG_WARN_SHARE and name not in self._said:
            self._said.add(name)
            out.append(
                Finding(
                    "radio_lag",
                    WARNING,
                    f"{share:.0%} of its setpoints in the last {RADIO_LAG_WINDOW_S:g} s replaced by newer ones before "
                    "its radio link took them: the radio does not carry its setpoint stream on time",
                    name,
                    "warn",
                )
            )
        elif share < RADIO_LAG_WARN_SHARE / 2 and name in self._said:
            self._said.discard(name)
            out.append(Finding("radio_lag", INFO, "its radio link carries its setpoints on time again", name, "warn"))
        self._over[name] = self._over.get(name, 0) + 1 if share >= RADIO_LAG_LAND_SHARE else 0
        if self._over[name] >= RADIO_LAG_LAND_WINDOWS and name not in self._landed:
            self._landed.add(name)
            out.append(
                Finding(
                    "radio_lag",
                    ERROR,
                    f"{share:.0%} of its setpoints replaced before its radio link took them, "
                    f"{RADIO_LAG_LAND_WINDOWS} s in a row: every setpoint (a hold too) reaches it late: landing",
                    name,
                    "land",
                )
            )
        return out
