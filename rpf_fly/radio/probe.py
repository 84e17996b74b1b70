"""Measure one Crazyradio through cflib's own radio driver: what it carries a second, with one link and with several,
and what a setpoint's round trip takes (``rpf-fly radio probe``, docs/radio.md "Probing a dongle").

Why measure: a dongle's capacity depends on how many links take turns on it (cflib sends a SET_RADIO_ADDRESS before
every packet whose address differs from the last, one USB control transfer each), on its type, on the host's USB
and on the room's radio; docs/radio.md gives the figures of the emulated dongles, a lab gets its own with a real one
and gives the mission the result (``radio.budget_packets_s``).

How (the same code for a real dongle and an emulated one, `rpf_fly.emulator.crazyradio`): each drone is reached by a
raw cflib link (``cflib.crtp.get_link_driver``: cflib's ``RadioDriver``, no TOC download, nothing but link packets
sent, so the drones may stand anywhere, powered on). A run opens its links and, for ``seconds``, counts the
acknowledged transactions of each (cflib's link statistics call back once per acknowledgement; a Crazyflie's
acknowledgement is never empty, so an open link polls back to back and the dongle runs at its ceiling) and sends an
echo request the size of a position setpoint every ``1 / ping_hz`` on each link (port 15 channel 0, which the
Crazyflie's firmware sends back: cflib's own latency ping), timing it from cflib's ``send_packet`` to the echo out of
``receive_packet``: a setpoint's way up plus an answer's way down. The first run has one link, the second all of
them. The address switch is what a transaction costs more when the links take turns: ``1 / total(N) - 1 / total(1)``.
Loss is the share of radio attempts lost, from cflib's link quality (each retransmission costs it 10 points).
"""

from __future__ import annotations

import statistics
import struct
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

PING_MARK = 0x50
"""The first byte of the probe's echo requests (cflib's own latency ping starts with 0)."""
SETPOINT_BYTES = 17
"""A position setpoint's CRTP payload (type byte and four floats: cflib ``send_position_setpoint``): the echo
request is as long, so it spends a setpoint's air time."""
ECHO_TIMEOUT_S = 0.5
"""An echo later than this is counted as lost (not in the round-trip figures)."""
CONNECT_TIMEOUT_S = 3.0
"""How long a link may take to get its first acknowledgement (cflib's safelink handshake) before the drone is taken
as not answering."""


class ProbeError(Exception):
    """What the probe cannot measure: one line naming the drone and what was expected."""


@dataclass(frozen=True)
class ProbeRun:
    """One run: ``links`` links open on dongle ``dongle`` of type ``radio``, for the run's seconds."""

    dongle: int
    radio: str
    links: int
    transactions_per_s: float
    """Acknowledged transactions a second, all links together (polls included): what the dongle carries."""
    per_link_per_s: list[float]
    setpoint_rtt_ms: dict[str, float]
    """``p50``, ``p99`` of the echo round trips of every link (milliseconds)."""
    address_switch_ms: float
    """What a transaction cost more than with one link (0 for the one-link run)."""
    loss: float
    """Share of radio attempts lost (retransmissions), from cflib's link quality."""
    echoes_lost: int = field(default=0, compare=False)

    def as_dict(self) -> dict[str, Any]:
        """The JSON object of ``rpf-fly radio probe --json`` (without the lost echoes)."""
        out = asdict(self)
        out.pop("echoes_lost")
        return out


def _percentile(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    ordered = sorted(values)
    k = min(len(ordered) - 1, max(0, int(round(q / 100.0 * (len(ordered) - 1)))))
    return ordered[k]


class _Link:
    """One raw cflib link: its acknowledgements counted, its echo round trips timed on its own thread."""

    def __init__(self, uri: str, ping_hz: float) -> None:
        import cflib.crtp

        self.uri = uri
        self._period_s = 1.0 / ping_hz
        self._lock = threading.Lock()
        self.acks = 0
        self._quality: list[float] = []
        self.measuring = False
        self.rtts_s: list[float] = []
        self.lost = 0
        self.error: str | None = None
        self._stop = threading.Event()
        self.driver = cflib.crtp.get_link_driver(uri, self._on_stats, self._on_error)
        if self.driver is None:
            raise ProbeError(
                f"{uri}: no cflib link driver takes this URI (expected radio://DONGLE/CHANNEL/RATE/ADDRESS)"
            )
        self._thread = threading.Thread(target=self._ping, name=f"probe-{uri}", daemon=True)

    def _on_stats(self, stats: dict[str, float]) -> None:
        if "link_quality" not in stats:
            return
        with self._lock:
            self.acks += 1
            if self.measuring:
                self._quality.append(stats["link_quality"])

    def _on_error(self, message: str) -> None:
        self.error = (message.strip().splitlines() or ["link error"])[0]

    def wait_up(self, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while self.acks == 0:
            if self.error is not None or time.monotonic() > deadline:
                raise ProbeError(
                    f"{self.uri}: no answer from the drone within {timeout_s:g} s "
                    f"({self.error or 'is it on, on this channel and address?'})"
                )
            time.sleep(0.01)
        self._thread.start()

    def window(self, on: bool) -> tuple[int, list[float], list[float], int]:
        """Start (``on``) or end a measuring window: the acknowledgements so far, and at the end the window's link
        qualities, round trips and lost echoes."""
        with self._lock:
            self.measuring = on
            if on:
                self._quality, self.rtts_s, self.lost = [], [], 0
            return self.acks, list(self._quality), list(self.rtts_s), self.lost

    def _ping(self) -> None:
        from cflib.crtp.crtpstack import CRTPPacket, CRTPPort

        seq = 0
        next_s = time.monotonic()
        while not self._stop.is_set() and self.error is None:
            seq = (seq + 1) & 0xFFFF
            pk = CRTPPacket()
            pk.set_header(CRTPPort.LINKCTRL, 0)
            pk.data = struct.pack("<BH", PING_MARK, seq) + bytes(SETPOINT_BYTES - 3)
            sent = time.monotonic()
            if not self.driver.send_packet(pk):
                return
            rtt = self._await_echo(seq, sent)
            with self._lock:
                if self.measuring:
                    if rtt is None:
                        self.lost += 1
                    else:
                        self.rtts_s.append(rtt)
            next_s = max(next_s + self._period_s, time.monotonic())
            self._stop.wait(next_s - time.monotonic())

    def _await_echo(self, seq: int, sent: float) -> float | None:
        deadline = sent + ECHO_TIMEOUT_S
        while True:
            left = deadline - time.monotonic()
            if left <= 0.0:
                return None
            pk = self.driver.receive_packet(left)
            if pk is None:
                continue
            data = bytes(pk.data)
            if (
                pk.port == 15
                and pk.channel == 0
                and len(data) >= 3
                and data[0] == PING_MARK
                and struct.unpack_from("<H", data, 1)[0] == seq
            ):
                return time.monotonic() - sent

    def radio_version(self) -> float | None:
        radio = getattr(self.driver, "_radio", None)
        return getattr(radio, "version", None)

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(ECHO_TIMEOUT_S + 1.0)
        try:
            self.driver.close()
        except Exception:  # noqa: BLE001 - a dongle gone under the probe: nothing more to close
            pass


def radio_type(version: float | None) -> str:
    """The dongle type from the firmware version cflib reads (a PA's 0.53, a 2.0's 5.x)."""
    if version is None:
        return "unknown"
    return "crazyradio_pa" if version < 1.0 else "crazyradio_2"


def uri_dongle(uri: str) -> int:
    """The dongle number of a ``radio://`` URI."""
    head = uri.partition("://")[2].split("/")[0]
    if not head.isdigit():
        raise ProbeError(f"{uri}: expected radio://DONGLE/CHANNEL/RATE/ADDRESS with a dongle number")
    return int(head)


def _measure(links: list[_Link], seconds: float) -> tuple[float, list[float], list[float], float, int]:
    starts = [link.window(True)[0] for link in links]
    t0 = time.monotonic()
    time.sleep(seconds)
    ends = [link.window(False) for link in links]
    elapsed = time.monotonic() - t0
    per_link = [(end[0] - start) / elapsed for start, end in zip(starts, ends)]
    quality = [q for end in ends for q in end[1]]
    rtts = [r for end in ends for r in end[2]]
    retries = (100.0 - statistics.fmean(quality)) / 10.0 if quality else 0.0
    return sum(per_link), per_link, rtts, retries / (1.0 + retries), sum(end[3] for end in ends)


def probe(
    uris: list[str],
    *,
    seconds: float = 2.0,
    ping_hz: float = 20.0,
    radio: str | None = None,
    warmup_s: float = 0.3,
    on_progress: Callable[[str], None] = lambda line: None,
) -> list[ProbeRun]:
    """Measure the dongle of ``uris`` (all on one dongle number): a run with the first link alone, then (with more
    than one URI) a run with all of them. ``radio``: the dongle type to report (None: from the version cflib reads).
    Needs cflib's radio driver registered (``cflib.crtp.init_drivers()``); raises `ProbeError` for what it cannot
    measure."""
    import cflib.crtp
    from cflib.crtp.radiodriver import RadioDriver

    if not uris:
        raise ProbeError("no drones to probe")
    dongles = {uri_dongle(u) for u in uris}
    if len(dongles) > 1:
        raise ProbeError(f"the drones are on dongles {sorted(dongles)}: probe one dongle at a time")
    if len(set(uris)) != len(uris):
        raise ProbeError("a drone is given twice")
    if not any(isinstance(c, type) and issubclass(c, RadioDriver) for c in cflib.crtp.CLASSES):
        cflib.crtp.init_drivers()
    dongle = dongles.pop()
    runs: list[ProbeRun] = []
    opened: list[_Link] = []
    try:
        single: float | None = None
        for count in [1, len(uris)] if len(uris) > 1 else [1]:
            while len(opened) < count:
                link = _Link(uris[len(opened)], ping_hz)
                opened.append(link)
                link.wait_up(CONNECT_TIMEOUT_S)
            kind = radio or radio_type(opened[0].radio_version())
            on_progress(f"dongle {dongle} ({kind}): {count} link{'s' if count > 1 else ''} for {seconds:g} s")
            time.sleep(warmup_s)
            total, per_link, rtts, loss, lost = _measure(opened, seconds)
            failed = next((link for link in opened if link.error is not None), None)
            if failed is not None:
                raise ProbeError(f"{failed.uri}: the link failed during the probe ({failed.error})")
            if total <= 0.0:
                raise ProbeError(f"dongle {dongle}: no acknowledged transaction in {seconds:g} s")
            if single is None:
                single = total
            switch_ms = 1000.0 * (1.0 / total - 1.0 / single) if count > 1 else 0.0
            runs.append(
                ProbeRun(
                    dongle,
                    kind,
                    count,
                    total,
                    per_link,
                    {"p50": 1000.0 * _percentile(rtts, 50), "p99": 1000.0 * _percentile(rtts, 99)},
                    switch_ms,
                    loss,
                    lost,
                )
            )
    finally:
        for link in opened:
            link.close()
    return runs


def dry_run_probe(
    links: int,
    *,
    dongle: int = 0,
    radio: str = "crazyradio_pa",
    seconds: float = 2.0,
    ping_hz: float = 20.0,
    seed: int = 0,
    on_progress: Callable[[str], None] = lambda line: None,
) -> list[ProbeRun]:
    """`probe` an emulated dongle ``dongle`` of type ``radio`` (`rpf_fly.emulator.crazyradio`) carrying ``links``
    simulated drones standing on the floor, each link with the dry run's bursty loss (`flight.dry_run.RADIO_LOSS`)."""
    from dataclasses import replace

    from rpf_fly.emulator import crazyradio
    from rpf_fly.emulator.crazyradio_timing import RADIO_TYPES
    from rpf_fly.emulator.fake_world import FakeDroneConfig, FakeWorld
    from rpf_fly.flight.dry_run import RADIO_LOSS

    if links < 1:
        raise ProbeError(f"--links {links}: expected at least 1")
    if radio not in RADIO_TYPES:
        raise ProbeError(f"--radio {radio}: expected one of {', '.join(sorted(RADIO_TYPES))}")
    if dongle < 0:
        raise ProbeError(f"--dongle {dongle}: expected a dongle number >= 0")
    addresses = [0xE7E7E7E700 + k for k in range(1, links + 1)]
    configs = {}
    for k, address in enumerate(addresses):
        config = FakeDroneConfig.at(0.5 * (k % 10), 0.5 * (k // 10))
        configs[address] = replace(config, faults=replace(config.faults, burst=RADIO_LOSS))
    world = FakeWorld(configs, seed=seed)
    crazyradio.plug(world, dongles=dongle + 1, radio=radio)
    try:
        return probe(
            [f"radio://{dongle}/80/2M/{a:010X}" for a in addresses],
            seconds=seconds,
            ping_hz=ping_hz,
            radio=radio,
            on_progress=on_progress,
        )
    finally:
        crazyradio.wait_released([dongle])
        crazyradio.unplug()
        world.close()


DEFAULT_DRY_RUN_LINKS = 4
"""Simulated drones on a dry-run probe's dongle when ``--links`` is not given."""


def probe_dongle(
    *,
    drones: list[str] | None = None,
    dry_run: bool = False,
    dongle: int | None = None,
    links: int | None = None,
    radio: str | None = None,
    seconds: float = 2.0,
    on_progress: Callable[[str], None] = lambda line: None,
) -> list[ProbeRun]:
    """``rpf-fly radio probe``: a real dongle with ``drones`` (``radio://`` URIs on one dongle; ``links``: the first
    that many), or with ``dry_run`` an emulated one of type ``radio`` carrying ``links`` simulated drones. Raises
    `ProbeError` (one line naming the option) for what cannot be probed."""
    if seconds <= 0:
        raise ProbeError(f"--seconds {seconds:g}: expected a positive number of seconds")
    if links is not None and links < 1:
        raise ProbeError(f"--links {links}: expected at least 1")
    if dongle is not None and dongle < 0:
        raise ProbeError(f"--dongle {dongle}: expected a dongle number >= 0")
    if dry_run:
        if drones:
            raise ProbeError(
                "--drones: a dry run probes simulated drones; give --links N with --dry-run, or real drones without it"
            )
        return dry_run_probe(
            DEFAULT_DRY_RUN_LINKS if links is None else links,
            dongle=dongle or 0,
            radio=radio or "crazyradio_pa",
            seconds=seconds,
            on_progress=on_progress,
        )
    if not drones:
        raise ProbeError(
            "--drones: expected the radio:// URIs of powered-on drones on one dongle "
            "(radio://0/80/2M/E7E7E7E701,...), or --dry-run for an emulated dongle"
        )
    bad = next((u for u in drones if not u.startswith("radio://")), None)
    if bad is not None:
        raise ProbeError(f"--drones: {bad!r} is not a radio:// URI (expected radio://DONGLE/CHANNEL/RATE/ADDRESS)")
    numbers = sorted({uri_dongle(u) for u in drones})
    if len(numbers) > 1:
        raise ProbeError(
            f"--drones: the URIs are on dongles {', '.join(map(str, numbers))}: probe one dongle at a "
            "time (the URI's first number)"
        )
    if dongle is not None and dongle != numbers[0]:
        raise ProbeError(f"--dongle {dongle}: the drones' URIs are on dongle {numbers[0]}")
    if links is not None and links > len(drones):
        raise ProbeError(f"--links {links}: only {len(drones)} drone(s) given in --drones")
    return probe(drones[:links] if links is not None else drones, seconds=seconds, radio=radio, on_progress=on_progress)


def describe(runs: list[ProbeRun]) -> list[str]:
    """The probe's report: a line per run, then the figure a mission can take (``radio.budget_packets_s``)."""
    lines = []
    for run in runs:
        rtt = run.setpoint_rtt_ms
        links = f"{run.links} link{'s' if run.links > 1 else ''}"
        share = f" ({statistics.fmean(run.per_link_per_s):.0f} a link)" if run.links > 1 else ""
        switch = f"; address switch {run.address_switch_ms:.2f} ms" if run.links > 1 else ""
        lost = f"; {run.echoes_lost} echo(es) lost" if run.echoes_lost else ""
        lines.append(
            f"dongle {run.dongle} ({run.radio}), {links}: {run.transactions_per_s:.0f} transactions/s"
            f"{share}; setpoint round trip p50 {rtt['p50']:.1f} ms, p99 {rtt['p99']:.1f} ms{switch}; "
            f"loss {100 * run.loss:.1f} %{lost}"
        )
    last = runs[-1]
    lines.append(
        f"radio.budget_packets_s: {last.transactions_per_s:.0f}   (what dongle {last.dongle} carried with "
        f"{last.links} link{'s' if last.links > 1 else ''}: the mission's radio section takes it)"
    )
    return lines
