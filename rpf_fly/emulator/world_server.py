"""The simulated world of a dry run or a lab with what reaches it from outside: the radio server (one UDP socket
answering every fake link's transactions, rpf_fly/emulator/radio_wire.py), the NatNet emulator serving the
simulated mocap, and the call table of the fault hooks and snapshots. A dry run's child process
(rpf_fly/emulator/world_process.py) and a lab (rpf_fly/flight/lab.py) serve it.
"""

from __future__ import annotations

import logging
import socket
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from .crtp import Packet
from .fake_world import FakeWorld
from .host_lag import HostLag, host_lag
from .radio_wire import (
    BROADCAST,
    BROADCAST_QUIET,
    CLOSE,
    DOWN,
    INFO,
    LINK_STATE,
    OPEN,
    PIPE_INFO,
    PIPED,
    PUSH,
    PUSH_MARK,
    RECORD,
    RECORDED,
    REPLY,
    REQUEST,
    STATE,
    STATE_EVERY_S,
)
from .sim_drone import DronePort, SimDrone
from .simulated_bodies import SimulatedBodies

logger = logging.getLogger(__name__)


class _PipedLink:
    """A piped link's end here: where its drone's downlink packets and state go."""

    def __init__(self, sock: socket.socket, peer: Any, drone: SimDrone) -> None:
        self.sock = sock
        self.peer = peer
        self.drone = drone
        self.state: tuple[bool, tuple[float, float] | None, int] | None = None
        self.sent_s = 0.0
        self.recorded_s = time.monotonic()
        """When it last recorded a transaction (its opening first): its drone's next downlink packet goes to the
        link that transacted last, as a Crazyflie's next acknowledgement goes to whichever link's packet comes
        next."""

    def push_down(self, packet: Packet) -> None:
        port, channel, payload = packet
        head = PUSH.pack(PUSH_MARK, DOWN, self.drone.address)
        self._send(head + bytes((port & 0xFF, channel & 0xFF)) + bytes(payload))

    def push_state(self, now_s: float) -> None:
        """The drone's link state, when it changed or `STATE_EVERY_S` after the last."""
        state = self.drone.link_state()
        if state == self.state and now_s - self.sent_s < STATE_EVERY_S:
            return
        self.state, self.sent_s = state, now_s
        answering, override, flushes = state
        rate, until = override if override is not None else (0.0, -1.0)
        self._send(PUSH.pack(PUSH_MARK, STATE, self.drone.address) + LINK_STATE.pack(answering, rate, until, flushes))

    def _send(self, data: bytes) -> None:
        try:
            self.sock.sendto(data, self.peer)
        except OSError:
            pass  # the link's process is gone: its CLOSE never comes, the flight is over


class RadioServer:
    """The child's end of the fake links: one UDP socket, one thread, every link's transactions in turn; the world's
    dynamics thread pushes the piped links' drone states after each step (rpf_fly/emulator/piped_port.py)."""

    def __init__(self, world: FakeWorld, host: str = "127.0.0.1") -> None:
        self._world = world
        self._ports: dict[int, DronePort | None] = {}
        self._wakers: dict[tuple[Any, int], threading.Event] = {}
        self._piped: dict[tuple[Any, int], _PipedLink] = {}
        self._piped_lock = threading.Lock()
        self._sinks: dict[int, Callable[[Packet], None]] = {}
        """drone address -> the one sink its piped links share (`_push_down`)."""
        self._after_reply: list[Callable[[], object]] = []
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, 0))
        self._thread = threading.Thread(target=self._run, name="fake-radio-server", daemon=True)
        world.after_step.append(self._push_states)

    def start(self) -> RadioServer:
        self._thread.start()
        return self

    def close(self) -> None:
        if self._push_states in self._world.after_step:
            self._world.after_step.remove(self._push_states)
        self.sock.close()

    def _push_states(self, _world_s: float) -> None:
        """After each world step: the piped links' drone states that changed (or are due: `STATE_EVERY_S`)."""
        if not self._piped:
            return
        now = time.monotonic()
        with self._piped_lock:
            links = list(self._piped.values())
        for link in links:
            link.push_state(now)

    def _port(self, address: int) -> DronePort | None:
        if address not in self._ports:
            self._ports[address] = self._world.port(address)
        return self._ports[address]

    def _run(self) -> None:
        while True:
            try:
                data, peer = self.sock.recvfrom(2048)
            except OSError:
                return  # closed
            try:
                reply = self._handle(data, peer)
            except Exception:  # noqa: BLE001 - a bad request loses one transaction, never the radio
                logger.exception("fake radio server: bad request")
                continue
            if reply is None:
                continue  # a piped link's record or quiet broadcast: nobody waits for an answer
            try:
                self.sock.sendto(reply, peer)
            except OSError:
                pass
            while self._after_reply:  # a piped link's first pushes come after its OPEN reply
                self._after_reply.pop(0)()

    def _handle(self, data: bytes, peer: Any) -> bytes | None:
        op, seq, address, channel, flags = REQUEST.unpack_from(data)
        if op in (BROADCAST, BROADCAST_QUIET):
            body = data[REQUEST.size :]
            self._world.broadcast(channel, (body[0], bytes(body[1:])), flags)
            return REPLY.pack(seq, 1, 0, 0, 0) if op == BROADCAST else None
        port = self._port(address)
        if op == RECORD:
            if port is not None:
                acked, retries = RECORDED.unpack_from(data, REQUEST.size)
                link = self._piped.get((peer, address))
                if link is not None:
                    link.recorded_s = time.monotonic()
                body = data[REQUEST.size + RECORDED.size :]
                uplink = (body[0], bytes(body[1:])) if flags & 1 else None
                port.drone.record(bool(acked), retries, uplink, self._world.time_s())
            return None
        if op == OPEN:
            if port is None:
                return REPLY.pack(seq, 0, 0, 0, 0)
            port.attach(self._wakers.setdefault((peer, address), threading.Event()))
            reply = REPLY.pack(seq, 1, 0, 0, 0) + INFO.pack(port.faults.latency_s, port.rssi_dbm)
            if flags & PIPED:
                reply += self._open_piped(port.drone, peer)
            return reply
        if op == CLOSE:
            waker = self._wakers.pop((peer, address), None)
            with self._piped_lock:
                link = self._piped.pop((peer, address), None)
            if port is not None and link is not None:
                self._detach_piped(link)
            if port is not None and waker is not None:
                port.detach(waker)
            return REPLY.pack(seq, 1, 0, 0, 0)
        if port is None:
            return REPLY.pack(seq, 0, self._world.timing.arc_retries, 0, 0)
        body = data[REQUEST.size :]
        uplink = (body[0], bytes(body[1:])) if flags & 1 else None
        ok, retry, down = port.transact(channel, uplink)
        more = port.has_downlink()
        if down is None:
            return REPLY.pack(seq, ok, retry, more, 0)
        return REPLY.pack(seq, ok, retry, more, 1) + bytes((down[0] & 0xFF, down[1] & 0xFF)) + bytes(down[2])

    def _open_piped(self, drone: SimDrone, peer: Any) -> bytes:
        """Attach a piped link to ``drone``: its downlink packets go to the link from now on; the link gets what
        it needs to decide its transactions (`PIPE_INFO`) and, next, the drone's state."""
        faults, burst = drone.config.faults, drone.config.faults.burst
        info = PIPE_INFO.pack(
            self._world.time_s(),
            faults.packet_loss,
            drone.seed,
            burst is not None,
            burst.good_loss if burst else 0.0,
            burst.bad_loss if burst else 0.0,
            burst.mean_good_s if burst else 1.0,
            burst.mean_bad_s if burst else 1.0,
            drone.config.channel if drone.config.channel is not None else 255,
            self._world.timing.arc_retries,
        )
        self._after_reply.append(lambda: self._attach_piped(_PipedLink(self.sock, peer, drone)))
        return info

    def _attach_piped(self, link: _PipedLink) -> None:
        drone = link.drone
        with self._piped_lock:
            self._piped[(link.peer, drone.address)] = link
            first = drone.address not in self._sinks
            if first:
                self._sinks[drone.address] = lambda packet: self._push_down(drone, packet)
        if first:
            drone.attach_sink(self._sinks[drone.address])
        link.push_state(time.monotonic())

    def _detach_piped(self, link: _PipedLink) -> None:
        drone = link.drone
        with self._piped_lock:
            if any(other.drone is drone for other in self._piped.values()):
                return
            sink = self._sinks.pop(drone.address, None)
        if sink is not None:
            drone.detach_sink(sink)

    def _push_down(self, drone: SimDrone, packet: Packet) -> None:
        """One downlink packet of ``drone`` to the piped link to it that transacted last (two programs on one
        drone: each gets the packets its own acknowledgements would have carried, about in proportion)."""
        with self._piped_lock:
            links = [link for link in self._piped.values() if link.drone is drone]
        if links:
            max(links, key=lambda link: link.recorded_s).push_down(packet)


class WorldServer:
    """The simulated world of a dry run or a lab, with what reaches it from outside: the radio server (UDP), the
    NatNet emulator and the call table of the fault hooks and snapshots (by the names of `WorldProcess`'s methods).
    ``settings``: as `WorldProcess` sends them. The caller serves the calls (`handle`) over its connections."""

    def __init__(self, settings: Mapping[str, Any]) -> None:
        self.world = FakeWorld(
            settings["drones"],
            seed=settings["seed"],
            obstacles=settings.get("obstacles", ()),
            timing=settings.get("timing"),
        ).start()
        self.bodies: dict[int, str] = dict(settings["bodies"])
        self.tracked = SimulatedBodies(self.world, self.bodies, settings.get("mocap_noise"), seed=settings["seed"])
        self.host = settings.get("host", "127.0.0.1")
        self.radio = RadioServer(self.world, self.host).start()
        self.natnet: Any = None
        natnet = settings.get("natnet")
        if natnet is not None:
            from rpf_fly.emulator.natnet_server import NatNetServer

            self.natnet = NatNetServer(
                self.tracked.poses,
                version=natnet["version"],
                multicast=natnet.get("multicast", False),
                local_ip=self.host,
                rate_hz=natnet["rate_hz"],
                up_axis=natnet["up_axis"],
                bodies=list(self.bodies.values()),
                extra_latency_s=self.tracked.extra_latency_s,
            ).start()
        world, tracked = self.world, self.tracked
        self.calls: dict[str, Any] = {
            "drop_link": world.drop_link,
            "restore_link": world.restore_link,
            "disturb": world.disturb,
            "set_battery": world.set_battery,
            "reboot": world.reboot,
            "snapshot": world.snapshot,
            "true_poses": world.true_poses,
            "truth_samples": world.truth_samples,
            "poses": tracked.poses,
            "hide": tracked.hide,
            "blackout": tracked.blackout,
            # fault hooks of a campaign (same names and arguments as on FakeWorld and SimulatedBodies)
            "packet_loss": world.packet_loss,
            "gust": world.gust,
            "estimator_divergence": world.estimator_divergence,
            "radio_counters": world.radio_counters,
            "radio_bursts": world.radio_bursts,
            "time_s": world.time_s,
            "pose_jump": tracked.pose_jump,
            "orientation_flip": tracked.orientation_flip,
            "mocap_delay": tracked.mocap_delay,
            "host_lag": self.host_lag,
        }

    def host_lag(self) -> HostLag:
        """How far the host let this world fall behind its own time so far (`HostLag`)."""
        return host_lag(self.world.lag, self.natnet.lag if self.natnet is not None else None)

    def ports(self) -> dict[str, Any]:
        """Where the world is reached: the radio server's UDP address and the NatNet emulator's command port."""
        return {
            "radio": list(self.radio.sock.getsockname()),
            "natnet_command_port": self.natnet.command_port if self.natnet is not None else None,
        }

    def handle(self, method: str, args: Sequence[Any]) -> tuple[str, Any]:
        """One call: ``("ok", value)`` or ``("error", "Type: message")`` (the caller stays up)."""
        try:
            return "ok", self.calls[method](*args)
        except Exception as err:  # noqa: BLE001 - reported to the caller
            return "error", f"{type(err).__name__}: {err}"

    def close(self) -> None:
        if self.natnet is not None:
            self.natnet.close()
        self.world.close()
        self.radio.close()
