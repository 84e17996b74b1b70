"""The dry run: the same flight stack on simulated drones, before anyone arms a real one.

Every ``radio://`` URI of the mission becomes ``fake://`` with the same path, answered by a simulated Crazyflie of
the fake radio (:mod:`rpf_fly.emulator.fake_world`) standing at the drone's mission start (with
``radio="crazyradio"``, the mission's ``dry_run.radio``, the URIs stay ``radio://`` and emulated Crazyradios are
plugged into this process, :mod:`rpf_fly.emulator.crazyradio`: cflib's own radio driver carries every packet to the
same simulated drones). Their true poses are served by the NatNet server emulator over UDP on 127.0.0.1 in the
mission's up-axis convention, and the real NatNet client receives them; so the flight loop, the NatNet client, the
cflib backend and cflib itself all run for real.
``mocap="sim"`` uses the simulated mocap source instead of the UDP round trip. ``mocap="motioncapture"`` (the
default for a mission of kind ``motioncapture``, whatever its ``type``) has the emulator multicast on 127.0.0.1 and
reads it with the ``motioncapture`` package's OptiTrack decoder, in the child process of
:class:`~rpf_fly.mocap.motioncapture_source.MotioncaptureSource`: the library, its process and the frame pipe
fly for real, with the simulated drones' poses. The mission's ``type`` (Vicon, Qualisys, VRPN, the ``mock``'s fixed
bodies) is not what the dry run reads, as Motive's address is not for kind ``natnet``: no emulator of those
systems sees the simulated drones (docs/mocap.md, "Dry run").

The simulated drones and the NatNet emulator run in a process of their own (``process=True``, the default;
:mod:`rpf_fly.emulator.world_process`), as real drones and Motive are outside a real flight's process: on threads of
the flight's process they would hold its GIL at moments no real flight sees. ``process=False`` keeps them in this
process (debugging, packet observers).

Every link loses packets in bursts (``radio_loss``, default `RADIO_LOSS`: a Gilbert-Elliott channel per link,
docs/radio.md, "Bursty loss"), as a 2.4 GHz link does. If this process dies without closing the dry run (SIGKILL),
the simulated drones' process lets them fall by their firmware's watchdog, as real drones would, and writes an exit
report (``world_exit_report``, `world_exit_report_for` a log) before it exits.

The simulated drones crash on contact with each other or with the mission's obstacles
(:mod:`rpf_fly.emulator.fake_contact`), and their true states reach the flight log as ``/truth/<drone>``
(:meth:`DryRun.truth_samples`, :mod:`rpf_fly.flight.truth`).
Fault hooks for tests, demos and fault campaigns, by drone name, safe to call while the flight runs (durations
in seconds from the call; each behaves as the real thing would, see docs/radio.md, "Fault hooks"):

- mocap: :meth:`DryRun.hide` (a rigid body untracked for a while), :meth:`DryRun.blackout` (no body tracked at
  all), :meth:`DryRun.pose_jump` (a body reported in the wrong place, as tracked), :meth:`DryRun.orientation_flip`
  (a body reported turned, as tracked), :meth:`DryRun.mocap_delay` (every pose late);
- radio: :meth:`DryRun.packet_loss` (lossy link for a while, replacing the bursty loss every dry-run link has
  by default: ``radio_loss``, `RADIO_LOSS`);
- drone: :meth:`DryRun.gust` (an external push its controller fights), :meth:`DryRun.estimator_divergence` (the
  estimate runs away, the true drone the other way), :meth:`DryRun.reboot` (a brown-out: falls, radio silent,
  fresh firmware on the floor);
- at power-on: ``start_faults`` (a drone standing rotated or away from its mission start, :class:`StartFault`);
- and ``DryRun.world``'s ``drop_link``, ``set_battery`` and ``disturb`` (a teleport) by radio address, and the
  faults of ``drone_configs``.
"""

from __future__ import annotations

import math
import os
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rpf_fly.emulator.fake_world import BurstLoss, FakeDroneConfig, FakeWorld, RadioTiming
from rpf_fly.emulator.mocap_noise import MocapNoise
from rpf_fly.mission.model import Mission
from rpf_fly.mocap.frame import MocapSource

if TYPE_CHECKING:
    from rpf_fly.emulator.natnet_server import NatNetServer
    from rpf_fly.flight.lab import LabInfo


DRY_RUN_TOC_CACHE = Path.home() / ".cache" / "rpf_fly" / "toc-dry-run"
"""The simulated Crazyflies' TOC cache, kept between dry runs as a lab's computer keeps its drones' (the real
flight's is ``~/.cache/rpf_fly/toc``): cflib keys each TOC by its CRC, so a simulated firmware whose tables
change gets a new entry. Warm, three drones connect in 0.7 s instead of 1.1 s; cold, ten drones downloading their
TOCs at once through one simulated dongle on a loaded machine miss the 10 s connection deadline (measured with 40
drones on 4 dongles on 2 busy cores). ``DryRun(cache_dir=None)`` connects cold."""
AIR_TIME_S = 0.001
"""Air time of one radio transaction on a dry run's dongle: a Crazyradio carries about 1000 transactions a second,
shared by every link on it (github.com/bitcraze/crazyradio2-firmware/issues/9, /16 and /22; docs/radio.md), so a
dry run shows what a full radio does to latency. Each transaction holds its dongle that long and only that long
(the drone's answer, a UDP round trip to the world process, is computed outside it:
`rpf_fly.emulator.fake_world.DongleAir`)."""

RADIO_LOSS = BurstLoss()
"""The dry run's radio loss on every link: bursty (a Gilbert-Elliott channel, `BurstLoss`), a Crazyradio PA in a
lab: 1 % of attempts lost between bursts, 60 % within them, a 30 ms burst about once a second, 2.7 % in the long
run (docs/radio.md, "Bursty loss", for each figure's source). ``DryRun(radio_loss=None)`` turns it off."""


def default_world_exit_report() -> Path:
    """Where the simulated drones' process writes its exit report when the dry run has no other path for it:
    ``<temp dir>/rpf-fly-world-exit-<pid of the flight's process>.json``."""
    return Path(tempfile.gettempdir()) / f"rpf-fly-world-exit-{os.getpid()}.json"


def world_exit_report_for(log_path: Path) -> Path:
    """The exit report next to a flight log: ``<log>.world-exit.json`` (``rpf-fly fly --dry-run``)."""
    return log_path.with_name(log_path.name + ".world-exit.json")


def client_ip(server: str) -> str:
    """The local address a NatNet client of the emulator at ``server`` binds: loopback for a loopback server (as
    before: nothing else needed), else any (the system picks the card that routes to it)."""
    return "127.0.0.1" if server.startswith("127.") else "0.0.0.0"


def emulator_motioncapture_source(host: str, command_port: int, up_axis: str, bodies: list[str]) -> Any:
    """The ``motioncapture`` package's OptiTrack decoder on the NatNet emulator at ``host`` (which multicasts for
    it: libmotioncapture receives no unicast frames, docs/mocap.md): the dry run of a ``motioncapture`` mission, in
    one process or in a distributed flight's relay."""
    from rpf_fly.mocap.motioncapture_source import MotioncaptureSource

    return MotioncaptureSource(
        "optitrack", host, {"interface_ip": host, "port_command": str(command_port)}, up_axis=up_axis, bodies=bodies
    )


def fake_uri(uri: str) -> str:
    """``radio://0/80/2M/E7E7E7E701`` -> ``fake://0/80/2M/E7E7E7E701`` (fake URIs pass through)."""
    scheme, _, rest = uri.partition("://")
    return "fake://" + rest if scheme in ("radio", "fake") else uri


def radio_uri(uri: str) -> str:
    """``fake://0/80/2M/E7E7E7E701`` -> ``radio://0/80/2M/E7E7E7E701`` (radio URIs pass through)."""
    scheme, _, rest = uri.partition("://")
    return "radio://" + rest if scheme in ("radio", "fake") else uri


def dongle_type(mission: Mission) -> str:
    """The emulated Crazyradios' type of a dry run through ``dry_run.radio: crazyradio``: ``dry_run.crazyradio``,
    else the dongles the budget checks the mission against (``radio.dongle_type``)."""
    return mission.dry_run.crazyradio or mission.radio.dongle_type


def release_dongles(plugged: Any) -> None:
    """Unplug a dry run's emulated Crazyradios (`rpf_fly.emulator.crazyradio.Plugged`) once cflib has closed them:
    cflib closes a dongle on its shared radio's thread after the last close_link, and the next dry run in this
    process must open its own dongles, not these."""
    from rpf_fly.emulator import crazyradio

    crazyradio.wait_released(range(len(plugged.dongles)))
    crazyradio.unplug()


def uri_dongle(uri: str) -> int:
    """The dongle number of a ``radio://`` or ``fake://`` URI (its first path element)."""
    return int(uri.partition("://")[2].split("/")[0])


def uri_address(uri: str) -> int:
    """The radio address of a URI, as an integer."""
    path = uri.partition("://")[2].partition("?")[0]
    return int(path.split("/")[3], 16)


@dataclass(frozen=True)
class StartFault:
    """How one simulated drone stands at power-on, unlike its mission says (``DryRun(start_faults=...)``)."""

    yaw_deg: float = 0.0
    """It stands rotated by this much (degrees, counter-clockwise from +x). Its estimator still starts at
    `kalman.initialYaw` = 0, as a real Crazyflie's does: only a reset to the mocap yaw or extpose cures that."""
    offset_m: tuple[float, float] = (0.0, 0.0)
    """It stands this far (x, y, metres) from its mission start (put down in the wrong place)."""
    upside_down: bool = False
    """It lies on its back: its supervisor reports tumbled and refuses to arm (`VehicleConfig.upside_down`)."""
    motor_fault: bool = False
    """A motor does not spin up: arming never gets ready to fly (`VehicleConfig.motor_fault`)."""


def mission_mocap_noise(mission: Mission) -> MocapNoise:
    """The mocap jitter and dropouts of the mission's ``dry_run`` section, its vehicle profile's position noise where
    it gives none, the emulator's figures where neither says anything."""
    default, d = MocapNoise.default(), mission.dry_run
    if d.mocap_noise_m is None and d.vehicle is not None and d.vehicle.mocap_noise_m is not None:
        default = replace(default, position_m=d.vehicle.mocap_noise_m)  # the vehicle profile's (dry_run.vehicle)
    return MocapNoise(
        default.position_m if d.mocap_noise_m is None else d.mocap_noise_m,
        default.orientation_deg if d.mocap_noise_deg is None else d.mocap_noise_deg,
        default.dropout if d.mocap_dropout is None else d.mocap_dropout,
    )


def simulated_drones(
    mission: Mission,
    drone_configs: Mapping[str, FakeDroneConfig] | None = None,
    start_faults: Mapping[str, StartFault] | None = None,
    radio_loss: BurstLoss | None = RADIO_LOSS,
    dynamics: str | None = None,
) -> dict[int, FakeDroneConfig]:
    """The simulated Crazyflie of each drone of ``mission`` by radio address: at its mission start, mocap
    positioning, every link with ``radio_loss``; ``drone_configs`` replaces a drone's (by name), ``start_faults``
    then moves or turns it before power-on. ``dynamics`` (``"firmware"`` or ``"first-order"``; default the
    mission's ``dry_run.dynamics``) is how every one of them flies (`VehicleConfig.dynamics`); the mission's
    ``dry_run.vehicle`` profile's parameters are stored in each one's EEPROM (`VehicleConfig.stored_params`)
    unless its config stores its own."""
    chosen = mission.dry_run.dynamics if dynamics is None else dynamics
    addresses = {d.name: uri_address(d.uri) for d in mission.drones}
    configs = dict(drone_configs or {})
    faults = dict(start_faults or {})
    unknown = sorted(set(faults) - set(addresses))
    if unknown:
        raise ValueError(f"start_faults for drones not in the mission: {', '.join(unknown)}")
    drones = {}
    for d in mission.drones:
        default = FakeDroneConfig.at(d.start[0], d.start[1], 0.0, positioning="extpos")
        config = configs.get(d.name, default)
        if radio_loss is not None and config.faults.burst is None:
            config = replace(config, faults=replace(config.faults, burst=radio_loss))
        config = replace(config, vehicle=replace(config.vehicle, dynamics=chosen))
        if mission.dry_run.vehicle is not None and not config.vehicle.stored_params:  # its EEPROM holds the profile
            config = replace(config, vehicle=replace(config.vehicle, stored_params=mission.dry_run.vehicle.params))
        drones[addresses[d.name]] = _with_start_fault(config, faults.get(d.name))
    return drones


class DryRun:
    """Context manager owning the fake drones, the fake-radio registration and the mocap source of a dry run.

    ``drone_configs`` replaces a drone's simulated Crazyflie (by drone name); ``start_faults`` then moves or turns
    the drone (its given config or the default one: at its mission start, mocap positioning) before power-on."""

    def __init__(
        self,
        mission: Mission,
        *,
        mocap: str | None = None,
        natnet_version: str = "4.1",
        drone_configs: Mapping[str, FakeDroneConfig] | None = None,
        start_faults: Mapping[str, StartFault] | None = None,
        mocap_rate_hz: float | None = None,
        cache_dir: Path | None = DRY_RUN_TOC_CACHE,
        seed: int | None = None,
        process: bool = True,
        truth: bool = True,
        air_time_s: float | None = None,
        radio_loss: BurstLoss | None = RADIO_LOSS,
        world_exit_report: Path | None = None,
        host: str = "127.0.0.1",
        mocap_noise: MocapNoise | None = None,
        lab: LabInfo | None = None,
        dynamics: str | None = None,
        radio: str | None = None,
        crazyradio: str | None = None,
    ):
        """``lab``: fly the drones of a running lab (`rpf_fly.flight.lab`, ``rpf-fly lab``) instead of starting
        private ones; they keep their firmware state, and closing the dry run leaves them to the lab. ``truth``: the
        flight log of a flight on this rig gets the world's truth (``/truth/<drone>``); False only to measure what that
        costs (tools/bench_flight.py ``--no-truth``). ``air_time_s``: how long each radio transaction holds its dongle,
        shared by every link on it (default ``AIR_TIME_S``, a Crazyradio's; 0: an infinitely fast radio, only to measure
        what the radio costs). ``radio_loss``: the bursty loss of every drone's link (default `RADIO_LOSS`; None: a
        lossless radio, for tests that count exact retries); a drone of ``drone_configs`` whose `LinkFaults.burst` is
        set keeps its own. ``world_exit_report``: where the simulated drones' process writes what became of the drones
        if this process dies without closing the dry run (SIGKILL: they fall by the firmware's watchdog;
        `rpf_fly.emulator.world_process`); default `default_world_exit_report()`; a stale report there is removed at the
        start. ``host``: the IPv4 address the simulated drones' radio server and NatNet emulator bind (default loopback:
        nothing opened to the network; a distributed flight's coordinator gives its listen address:
        docs/distributed.md). ``mocap_noise``: the jitter and single-frame dropouts of every pose the mocap serves
        (default `MocapNoise.default()`, a real room's: rpf_fly/emulator/mocap_noise.py; ``MocapNoise(0, 0, 0)``: the
        exact truth, for tests that compare poses to the millimetre). ``dynamics``: how the simulated drones fly,
        ``"firmware"`` (the firmware's PID cascade on the identified body, docs/dynamics.md) or ``"first-order"``
        (`VehicleConfig.dynamics`). ``seed``, ``mocap_noise`` and ``dynamics`` default to the mission's ``dry_run``
        section (docs/mission-format.md); a lab's drones fly the lab mission's. ``radio``: ``"fake"`` (the ``fake://``
        link driver) or ``"crazyradio"`` (the mission's ``radio://`` URIs through cflib's own radio driver and emulated
        dongles of type ``crazyradio``, plugged into this process until `close`); default the mission's
        ``dry_run.radio`` and ``dry_run.crazyradio`` (else ``radio.dongle_type``)."""
        if mocap is None:  # the mission's kind decides: its own client against the emulator
            mocap = "motioncapture" if mission.mocap.kind == "motioncapture" else "natnet"
        if mocap not in ("natnet", "sim", "motioncapture"):
            raise ValueError(f"dry-run mocap must be 'natnet', 'motioncapture' or 'sim', not {mocap!r}")
        self.mission = mission
        self.mocap_kind = mocap
        self.natnet_version = natnet_version
        self.rate_hz = mocap_rate_hz or mission.mocap.rate_hz
        self.radio = mission.dry_run.radio if radio is None else radio
        if self.radio not in ("fake", "crazyradio"):
            raise ValueError(f"dry-run radio must be 'fake' or 'crazyradio', not {self.radio!r}")
        self.crazyradio = crazyradio or dongle_type(mission)
        to_uri = radio_uri if self.radio == "crazyradio" else fake_uri
        self.uris = {d.name: to_uri(d.uri) for d in mission.drones}
        self.plugged: Any = None
        """The emulated Crazyradios (`rpf_fly.emulator.crazyradio.Plugged`) with ``radio="crazyradio"``, once
        started: their counters say what cflib's radio driver carried."""
        self.addresses = {d.name: uri_address(d.uri) for d in mission.drones}
        self.bodies = {d.name: d.rigid_body for d in mission.drones}
        if lab is not None and (drone_configs or start_faults):
            raise ValueError(
                "a running lab's drones are already powered on: give drone configs and power-on "
                "faults to the lab (rpf-fly lab --faults), not to a flight against it"
            )
        self.dynamics = mission.dry_run.dynamics if dynamics is None else dynamics
        self.drone_configs = simulated_drones(mission, drone_configs, start_faults, radio_loss, self.dynamics)
        self.lab = lab
        self._names = {address: name for name, address in self.addresses.items()}
        self.seed = mission.dry_run.seed if seed is None else seed
        self.timing = RadioTiming(transaction_s=AIR_TIME_S if air_time_s is None else float(air_time_s))
        self.radio_loss = radio_loss
        self.world_exit_report = (
            Path(world_exit_report) if world_exit_report is not None else default_world_exit_report()
        )
        self.in_process = not process
        from rpf_fly.emulator.host_lag import LINKS

        self._links_at_start = LINKS.snapshot()
        """This process's radio links' figures when the dry run began (`host_lag` counts from here)."""
        self.host = host
        self.truth = truth
        self.mocap_noise = mission_mocap_noise(mission) if mocap_noise is None else mocap_noise
        self.world: Any = None  # a FakeWorld, or the WorldProcess speaking to one (same hook names)
        self._bodies: Any = None
        self._cache: tempfile.TemporaryDirectory[str] | None = None
        self.cache_dir = self._toc_cache(cache_dir)
        self.server: NatNetServer | None = None
        self.mocap: MocapSource | None = None

    def _toc_cache(self, cache_dir: Path | None) -> Path:
        """cflib's TOC cache for the flight's connections: ``cache_dir`` made if missing, or (``None``, or a folder
        that cannot be made) a fresh one that lives as long as the dry run: every drone then downloads its TOC, as
        on its first connection to a lab's computer."""
        if cache_dir is not None:
            try:
                Path(cache_dir).mkdir(parents=True, exist_ok=True)
                return Path(cache_dir)
            except OSError:
                pass
        self._cache = tempfile.TemporaryDirectory(prefix="rpf-fly-toc-")
        return Path(self._cache.name)

    def entered_mocap(self) -> MocapSource:
        """The rig's mocap source, for a flight on it; the rig must be entered (``with DryRun(...)``)."""
        if self.mocap is None:
            raise RuntimeError("the dry run has no mocap: enter it first (with DryRun(...))")
        return self.mocap

    # ------------------------------------------------------------------------------------------- life

    def __enter__(self) -> DryRun:
        try:
            self._start()
        except BaseException:
            self.close()
            raise
        return self

    def _start(self) -> None:
        from rpf_fly.emulator.world_process import RemoteWorld, SimulatedBodies, WorldProcess

        up = self.mission.mocap.up_axis
        body_of_address = {self.addresses[n]: body for n, body in self.bodies.items()}
        served = self.mocap_kind in ("natnet", "motioncapture")  # by the NatNet emulator
        multicast = self.mocap_kind == "motioncapture"  # libmotioncapture receives no unicast frames (docs/mocap.md)
        natnet = {"version": self.natnet_version, "rate_hz": self.rate_hz, "up_axis": up, "multicast": multicast}
        if self.lab is not None:
            from rpf_fly.flight.lab import LabClient

            self.world = self._bodies = LabClient(self.lab)
            missing = sorted(set(self.drone_configs) - set(self.lab.addresses.values()))
            if missing:
                raise RuntimeError(
                    f"the lab ({self.lab.mission}) has no drone at address "
                    f"{', '.join(f'{a:010X}' for a in missing)}: start the lab with this mission"
                )
            lab_radio: Any = tuple(self.lab.radio)
            self._connect_radio(RemoteWorld(lab_radio, tuple(self.drone_configs), self.timing))
            command_port = self.lab.natnet_command_port
            if served and command_port is None:
                raise RuntimeError("the lab serves no NatNet emulator")
        elif self.in_process:
            self.world = FakeWorld(
                self.drone_configs, seed=self.seed, obstacles=self.mission.obstacles, timing=self.timing
            ).start()
            self._bodies = SimulatedBodies(self.world, body_of_address, self.mocap_noise, seed=self.seed)
            self._connect_radio(self.world)
            command_port = None
            if served:
                from rpf_fly.emulator.natnet_server import NatNetServer

                self.server = NatNetServer(
                    self._bodies.poses,
                    version=self.natnet_version,
                    multicast=multicast,
                    local_ip=self.host,
                    rate_hz=self.rate_hz,
                    up_axis=up,
                    bodies=list(self.bodies.values()),
                    extra_latency_s=self._bodies.extra_latency_s,
                ).start()
                command_port = self.server.command_port
        else:
            self.world_exit_report.unlink(missing_ok=True)  # a report there is about an earlier run
            self.world = self._bodies = WorldProcess(
                self.drone_configs,
                body_of_address,
                seed=self.seed,
                natnet=natnet if served else None,
                obstacles=self.mission.obstacles,
                names=self._names,
                exit_report=self.world_exit_report,
                host=self.host,
                mocap_noise=self.mocap_noise,
            )
            self._connect_radio(RemoteWorld(self.world.radio, tuple(self.drone_configs), self.timing))
            command_port = self.world.natnet_command_port
        vehicle = self.mission.dry_run.vehicle
        if self.lab is None and vehicle is not None and vehicle.mocap_delay_s(self.rate_hz) > 0.0:
            self._bodies.mocap_delay(vehicle.mocap_delay_s(self.rate_hz), math.inf)  # the profile's mocap latency
        if self.mocap_kind == "natnet":
            from rpf_fly.mocap.natnet_client import NatNetClient

            server = "127.0.0.1" if self.host == "0.0.0.0" else self.host
            if command_port is None:  # served (a natnet dry run) gives it, or stopped above
                raise RuntimeError("dry run: no NatNet emulator serves the mocap")
            client = NatNetClient(
                server,
                multicast=False,
                local_ip=client_ip(server),
                command_port=command_port,
                data_port=None,
                up_axis=up,
            )
            self.mocap = client
            if not client.wait_for_server(5.0):
                raise RuntimeError("dry run: the NatNet emulator did not answer within 5 s")
        elif self.mocap_kind == "motioncapture":
            if command_port is None:  # served (a motioncapture dry run) gives it, or stopped above
                raise RuntimeError("dry run: no NatNet emulator serves the mocap")
            self.mocap = emulator_motioncapture_source(
                "127.0.0.1" if self.host == "0.0.0.0" else self.host, int(command_port), up, list(self.bodies.values())
            )
        else:
            from rpf_fly.emulator.simulated_mocap import SimulatedMocap

            m = self.mission.mocap
            self.mocap = SimulatedMocap(
                self.poses, rate_hz=self.rate_hz, noise_m=m.noise_m, latency_s=m.latency_s, dropout=m.dropout
            )

    def _connect_radio(self, world: Any) -> None:
        """Reach ``world``'s drones: the fake radio's ``fake://`` driver, or emulated Crazyradios (one per dongle
        number the mission's URIs use) behind cflib's own ``radio://`` driver."""
        from rpf_fly.emulator import fake_radio

        if self.radio == "crazyradio":
            from rpf_fly.emulator import crazyradio

            if crazyradio.plugged() is not None:
                raise RuntimeError(
                    "emulated Crazyradios are already plugged into this process (another dry run "
                    "through dry_run.radio: crazyradio): one at a time"
                )
            dongles = 1 + max(uri_dongle(u) for u in self.uris.values())
            self.plugged = crazyradio.plug(world, dongles=dongles, radio=self.crazyradio)
        else:
            fake_radio.register(world)

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        from rpf_fly.emulator import fake_radio

        if self.mocap is not None:
            self.mocap.close()
        if self.server is not None:
            self.server.close()
        if self.plugged is not None:
            release_dongles(self.plugged)
            self.plugged = None
        if self.world is not None:
            self.world.close()
        fake_radio.unregister()
        if self._cache is not None:
            self._cache.cleanup()

    # ------------------------------------------------------------------------------------------ poses

    def poses(self) -> dict[str, tuple[tuple[float, float, float], tuple[float, float, float, float], bool]]:
        """The fake drones' true poses keyed by rigid-body name, Z-up, with the tracking faults applied."""
        return self._bodies.poses()

    def hide(self, name: str, seconds: float) -> None:
        """Report drone ``name``'s rigid body as not tracked for ``seconds`` (occlusion)."""
        self._bodies.hide(self.bodies[name], seconds)

    def blackout(self, seconds: float) -> None:
        """Report every rigid body as not tracked for ``seconds`` (mocap lost)."""
        self._bodies.blackout(seconds)

    def truth_samples(self) -> list[tuple[float, dict[str, Any]]]:
        """The simulated world's truth since the previous call, keyed by drone name: ``[(monotonic_s, {drone:
        (position, yaw, motors, crashed, estimate)})]`` (one sample per world step; one round trip to the world
        process, or a direct call with ``process=False``). One reader: the flight log's truth feed."""
        names = self._names
        return [
            (stamp, {names[a]: state for a, state in states.items()}) for stamp, states in self.world.truth_samples()
        ]

    def pose_jump(self, name: str, offset_m: tuple[float, float, float], seconds: float) -> None:
        """Report drone ``name``'s rigid body ``offset_m`` metres from where it is, as tracked, for ``seconds`` (a
        marker swap, a wrong model fit); the drone does not move."""
        self._bodies.pose_jump(self.bodies[name], offset_m, seconds)

    def orientation_flip(self, name: str, deg: float, seconds: float) -> None:
        """Report drone ``name``'s rigid body turned by ``deg`` about the vertical, as tracked, for ``seconds`` (a
        wrong fit of a nearly symmetric marker set); the drone does not turn."""
        self._bodies.orientation_flip(self.bodies[name], deg, seconds)

    def mocap_delay(self, delay_s: float, seconds: float) -> None:
        """For ``seconds`` every mocap frame carries poses ``delay_s`` old (latency, not a frame-rate drop)."""
        self._bodies.mocap_delay(delay_s, seconds)

    def packet_loss(self, name: str, rate: float, seconds: float) -> None:
        """For ``seconds`` each radio attempt with drone ``name`` is lost with probability ``rate``."""
        self.world.packet_loss(self.addresses[name], rate, seconds)

    def gust(self, name: str, accel_m_s2: tuple[float, float, float], seconds: float) -> None:
        """Push drone ``name`` with ``accel_m_s2`` (m/s^2, world frame) for ``seconds``; its controller fights it
        (1.5 m/s^2: 17.6 cm off its setpoint) and it comes back after."""
        self.world.gust(self.addresses[name], accel_m_s2, seconds)

    def estimator_divergence(self, name: str, rate_m_s: float) -> None:
        """Drone ``name``'s estimate runs away at ``rate_m_s`` and ignores extpos until a reboot: the true drone
        drifts the other way while its telemetry looks fine."""
        self.world.estimator_divergence(self.addresses[name], rate_m_s)

    def reboot(self, name: str) -> None:
        """Brown-out of drone ``name``: motors off (it falls), radio silent for 1.5 s (its cflib link fails), then
        a fresh firmware on the floor that a new connection reaches."""
        self.world.reboot(self.addresses[name])

    def host_lag(self) -> Any:
        """How far the host let the simulated world fall behind its own time so far (`HostLag`), with this
        process's fake radio links' since the dry run began (`host_lag.LINKS`); a lab's world figures count from the
        lab's start."""
        from rpf_fly.emulator.host_lag import host_lag, with_links

        if self.in_process and self.lab is None:
            lag = host_lag(self.world.lag, self.server.lag if self.server is not None else None)
        else:
            lag = self.world.host_lag()
        return with_links(lag, since=self._links_at_start)

    def snapshot(self, name: str):
        """The fake firmware's state of drone ``name`` (position, motors, flags, ...)."""
        return self.world.snapshot(self.addresses[name])


def _with_start_fault(config: FakeDroneConfig, fault: StartFault | None) -> FakeDroneConfig:
    """``config`` with the drone moved by ``fault.offset_m`` and turned by ``fault.yaw_deg`` (no fault: as is)."""
    if fault is None:
        return config
    x, y, z = config.vehicle.position
    vehicle = replace(
        config.vehicle,
        position=(x + fault.offset_m[0], y + fault.offset_m[1], z),
        yaw_deg=config.vehicle.yaw_deg + fault.yaw_deg,
        upside_down=config.vehicle.upside_down or fault.upside_down,
        motor_fault=config.vehicle.motor_fault or fault.motor_fault,
    )
    return replace(config, vehicle=vehicle)
