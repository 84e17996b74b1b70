"""The simulated world of a dry run or a lab with what reaches it from outside: the radio server (one UDP socket
answering every fake link's transactions, rpf_fly/emulator/radio_wire.py), the NatNet emulator serving the
simulated mocap, and the call table of the fault hooks and snapshots. A dry run's child process
(rpf_fly/emulator/world_process.py) and a lab (rpf_fly/flight/lab.py) serve it.
"""

from __future__ import annotations

import logging
import socket
import threading
from collections.abc import Mapping, Sequence
from typing import Any

from .fake_world import FakeWorld
from .host_lag import HostLag, host_lag
from .radio_wire import BROADCAST, CLOSE, INFO, OPEN, REPLY, REQUEST
from .sim_drone import DronePort
from .simulated_bodies import SimulatedBodies

logger = logging.getLogger(__name__)


class RadioServer:
    """The child's end of the fake links: one UDP socket, one thread, every link's transactions in turn."""

    def __init__(self, world: FakeWorld, host: str = "127.0.0.1") -> None:
        self._world = world
        self._ports: dict[int, DronePort | None] = {}
        self._wakers: dict[tuple[Any, int], threading.Event] = {}
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, 0))
        self._thread = threading.Thread(target=self._run, name="fake-radio-server", daemon=True)

    def start(self) -> RadioServer:
        self._thread.start()
        return self

    def close(self) -> None:
        self.sock.close()

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
            try:
                self.sock.sendto(reply, peer)
            except OSError:
                pass

    def _handle(self, data: bytes, peer: Any) -> bytes:
        op, seq, address, channel, flags = REQUEST.unpack_from(data)
        if op == BROADCAST:
            body = data[REQUEST.size :]
            self._world.broadcast(channel, (body[0], bytes(body[1:])), flags)
            return REPLY.pack(seq, 1, 0, 0, 0)
        port = self._port(address)
        if op == OPEN:
            if port is None:
                return REPLY.pack(seq, 0, 0, 0, 0)
            port.attach(self._wakers.setdefault((peer, address), threading.Event()))
            return REPLY.pack(seq, 1, 0, 0, 0) + INFO.pack(port.faults.latency_s, port.rssi_dbm)
        if op == CLOSE:
            waker = self._wakers.pop((peer, address), None)
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
