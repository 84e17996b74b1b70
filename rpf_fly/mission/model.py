"""Mission dataclasses: what a validated mission file holds.

A :class:`Mission` is only ever built by :func:`rpf_fly.mission.load_mission`, which checks every field; code
downstream (sim, flight, bench) can trust it. Units: metres, seconds, Hz. Positions in the planning plane are
``(x, y)`` in the Z-up world frame; the flight height is ``flight.height``.

Keys and their meaning are a contract (docs/mission-format.md): other tools read these files.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Literal

if TYPE_CHECKING:
    from rpf_fly.calibrate.profile import VehicleProfile

Vec2 = tuple[float, float]

PLANNER_KINDS = ("apf", "apf-paper", "rpf", "rpf-mean", "ppo", "rpf3", "orca")
"""Planner kinds a mission (or ``--planner``) may name. ``rpf``, ``rpf-mean``, ``ppo`` and ``rpf3`` need an ONNX policy
(``policies/<kind>.onnx`` by default). ``rpf3`` (RPF-3) is the attention policy trained with guidance and the margin
on the scene families (docs/learning.md): the product's learned planner, with guidance and margin on by default."""

POLICY_KINDS = ("rpf", "rpf-mean", "ppo", "rpf3")

DEFAULT_KIND = "rpf3"
"""``planner.kind`` of a mission that names none: RPF-3, the product's planner (docs/bench/rpf3.md)."""

GUIDANCE_MODES = ("none", "path")
"""``planner.guidance``: ``none`` (the attraction pulls at the goal) or ``path`` (at the next visible waypoint of the
shortest path around the inflated obstacles: docs/algorithm.md, *Global guidance*)."""

PAPER_KINDS = ("apf-paper", "rpf", "rpf-mean", "ppo")
"""The planners as the paper wrote them (RPF-1, RPF-2, the PPO baseline, the literal APF): kept for reproduction,
so without guidance and margin unless a mission asks (as is a planner with ``preset: paper``)."""

PRODUCT_MARGIN_M = 0.05
"""``planner.margin`` of every other planner: a Crazyflie tracks its setpoint within 2-5 cm."""


def default_guidance(kind: str, preset: str = "robust") -> str:
    """``path`` for the product's planners (``apf`` and ``rpf3``, robust preset: RPF-3 was trained with it), ``none``
    for the paper's planners and the ORCA baseline (the bench turns it on with ``planner.guidance``)."""
    return "path" if kind in ("apf", "rpf3") and preset == "robust" else "none"


CAPTURE_RADIUS_M = 0.3
"""``planner.capture_radius`` of the product's planners (docs/algorithm.md, *Arrival*)."""


def default_capture_radius(kind: str, preset: str = "robust") -> float:
    """0 for the paper's planners (they stay as the paper wrote them), :data:`CAPTURE_RADIUS_M` otherwise."""
    return 0.0 if kind in PAPER_KINDS or preset == "paper" else CAPTURE_RADIUS_M


def default_margin(kind: str, preset: str = "robust") -> float:
    """0 for the paper's planners (bit-identical reproduction), :data:`PRODUCT_MARGIN_M` otherwise (ORCA kept its
    0.05 m before the key existed)."""
    return 0.0 if kind in PAPER_KINDS or preset == "paper" else PRODUCT_MARGIN_M


@dataclass(frozen=True)
class Arena:
    """The geofence: an axis-aligned box, metres. Setpoints are clamped to it; a drone outside it lands."""

    x: Vec2
    y: Vec2
    z: Vec2 = (0.0, 2.0)


FIRMWARE_SETPOINT_WATCHDOG_S = 0.5
"""A Crazyflie levels out this long after its last streamed setpoint (and cuts its motors at 2 s)."""

STALL_TICKS = 3
"""The loop watchdog acts after this many planning ticks without one (flight/watchdog.py)."""

MIN_STALL_TIMEOUT_S = 0.35
"""The loop watchdog never acts sooner than this (a loaded machine's pauses are not stalls)."""

MAX_STALL_TIMEOUT_S = 0.4
"""The loop watchdog must act by then to land the drones before the firmware's watchdog levels them out (it polls at
a fifth of its timeout, so it acts within 1.2 timeouts: 0.48 s < 0.5 s)."""

MIN_RATE_HZ = STALL_TICKS / MAX_STALL_TIMEOUT_S
"""The lowest planning rate (``flight.rate_hz``) whose watchdog acts in time: 7.5 Hz."""


@dataclass(frozen=True)
class FlightSettings:
    """How the drones fly. ``rate_hz`` is the planning rate: the planner and the simulator step at 1/rate_hz."""

    height: float = 0.6
    speed: float = 0.5
    rate_hz: float = 10.0
    goal_tolerance: float = 0.1
    takeoff_s: float = 2.0
    land_s: float = 2.0
    timeout_s: float = 120.0

    @property
    def dt(self) -> float:
        """Planning step in seconds."""
        return 1.0 / self.rate_hz


@dataclass(frozen=True)
class PlannerSettings:
    """Which planner and its parameters (the paper's defaults: r 0.1, d_r 6, rho 10, F_in_bar 1)."""

    kind: str = DEFAULT_KIND
    """The shipped default is RPF-3 (:data:`DEFAULT_KIND`), whose policy a mission loader finds at
    ``policies/rpf3.onnx``; ``apf`` was the default until RPF-3 led the families bench (docs/mission-format.md)."""
    policy: Path | None = None
    sensing_range: float = 6.0
    safety_radius: float = 0.1
    influence_range: float = 10.0
    wall_following: bool = True
    wall_threshold: float = 1.0
    preset: Literal["robust", "paper"] = "robust"
    neighbour_aggregate: Literal["sum", "mean"] = "sum"
    eta: float = 0.05
    lam: float = 2.0
    guidance: Literal["none", "path"] | None = None
    """``planner.guidance``; None: the kind's default (:func:`default_guidance`), see :attr:`guidance_mode`."""
    margin: float | None = None
    """``planner.margin`` (m); None: the kind's default (:func:`default_margin`), see :attr:`margin_m`."""
    capture_radius: float | None = None
    """``planner.capture_radius`` (m): within it a drone nearer its goal than any surface heads straight at the
    goal (docs/algorithm.md, *Arrival*); None: the kind's default (:func:`default_capture_radius`: 0.3, 0 for the
    paper's planners), see :attr:`capture_radius_m`; 0 turns the rule off."""

    @property
    def guidance_mode(self) -> str:
        """The guidance this planner flies with: the mission's, else its kind's default."""
        return self.guidance if self.guidance is not None else default_guidance(self.kind, self.preset)

    @property
    def margin_m(self) -> float:
        """The margin this planner keeps (metres): the mission's, else its kind's default."""
        return self.margin if self.margin is not None else default_margin(self.kind, self.preset)

    @property
    def capture_radius_m(self) -> float:
        """The capture radius this planner flies with (metres): the mission's, else its kind's default."""
        if self.capture_radius is not None:
            return self.capture_radius
        return default_capture_radius(self.kind, self.preset)


@dataclass(frozen=True)
class MocapSettings:
    """Where poses come from. ``natnet``: an OptiTrack Motive server; ``sim``: simulated poses; ``motioncapture``:
    a system of the ``motioncapture`` package (libmotioncapture: Vicon, Qualisys, VRPN, OptiTrack, a mock), run in a
    child process (docs/mocap.md)."""

    kind: Literal["natnet", "sim", "motioncapture"] = "sim"
    server: str = "127.0.0.1"
    local_ip: str = "0.0.0.0"
    multicast: bool = True
    multicast_group: str = "239.255.42.99"
    command_port: int = 1510
    data_port: int = 1511
    up_axis: Literal["y", "z"] = "z"
    noise_m: float = 0.0
    latency_s: float = 0.0
    rate_hz: float = 100.0
    dropout: float = 0.0
    timeout_s: float = 0.5
    system: str | None = None
    """``motioncapture``: the library's type (YAML key ``type``), e.g. ``vicon``; None for the other kinds."""
    hostname: str | None = None
    """``motioncapture``: the system's host (None: the library's default, ``localhost``; ``mock`` has none)."""
    options: tuple[tuple[str, str], ...] = ()
    """``motioncapture``: the library's other options, checked and as the text its ``connect()`` gets."""


@dataclass(frozen=True)
class RadioSettings:
    """How setpoints reach the drones. ``cflib`` uses the URIs as given (``--dry-run`` maps radio:// to fake://)."""

    kind: Literal["cflib"] = "cflib"
    min_battery_v: float = 3.7
    extpos: Literal["extpos", "extpose", "packed"] = "extpos"
    """What each drone's estimator gets of its mocap pose: its position (extpos), its pose (extpose), both unicast,
    one packet a drone; or ``packed``: the positions of up to four drones of a dongle in one broadcast
    (rpf_fly/radio/packed_extpos.py)."""
    extpos_rate_hz: float = 30.0
    """How often each drone's mocap pose is forwarded to its estimator (every extpos costs radio time; 20-50 Hz is
    plenty for the Kalman filter)."""
    dongle_type: Literal["crazyradio_pa", "crazyradio_2"] = "crazyradio_pa"
    """The Crazyradio model, for its budget: its figures (rpf_fly/emulator/crazyradio_timing.py,
    rpf_fly/radio/budget.py)."""
    budget_packets_s: float | None = None
    """Transactions a second one dongle carries with its links taking turns (None: from the dongle type's figures);
    a lab's own measurement (``rpf-fly radio probe``)."""
    allow_over_budget: bool = False
    """Fly even when a dongle is asked for more than its budget (the radio then delays setpoints and extpos)."""


@dataclass(frozen=True)
class ZenohSettings:
    """The Zenoh sessions of a distributed flight (docs/distributed.md). The coordinator is always a router (it
    routes between its workers, the logger and any tap); ``mode`` is the workers' and the logger's. Defaults: no
    multicast scouting, the coordinator listening on loopback only (a free port, or 7447 with
    ``--remote-dongles``), no router to run beside it."""

    mode: Literal["client", "peer"] = "client"
    connect: tuple[str, ...] = ()
    """Endpoints to connect to (``tcp/HOST:7447``): where a worker finds its coordinator."""
    listen: tuple[str, ...] = ()
    """Endpoints the coordinator listens on (empty: loopback only)."""
    config: Path | None = None
    """A Zenoh configuration file (JSON5) every session of the flight starts from: TLS certificates, access
    control, anything Zenoh reads; rpf_fly then sets the mode, the endpoints, the lease and scouting off on top
    (docs/distributed.md, "Across hosts"). Resolved to an existing file at load."""


@dataclass(frozen=True)
class RuntimeSettings:
    """How the processes of a distributed flight talk (``rpf-fly fly --distributed``, ``rpf-fly worker``)."""

    zenoh: ZenohSettings = field(default_factory=ZenohSettings)
    mocap_relay: Literal["auto", "on", "off"] = "auto"
    """Whether one relay process reads the mocap and publishes the frames to the workers (``on``) or each worker
    opens the mocap itself (``off``); ``auto``: the relay for unicast NatNet (``mocap.multicast: false``) and for
    ``mocap.kind: motioncapture``, each worker its own client otherwise. Dry runs follow the same rule
    (rpf_fly/runtime/relay.py :func:`uses_relay`, docs/distributed.md)."""


@dataclass(frozen=True)
class SafetySettings:
    """What the flight supervisor checks every tick and how it responds (docs/flight.md)."""

    pose_timeout_s: float = 0.25
    """A drone whose newest valid mocap pose is older than this holds position (no planning on a stale pose)."""
    pose_lost_land_s: float = 1.5
    """A drone without a valid pose for this long lands; if every drone has none, all land."""
    on_separation: Literal["warn", "hold", "land"] = "warn"
    """Response when two drones come closer than 2r (always logged as an event)."""
    on_obstacle: Literal["warn", "hold", "land"] = "warn"
    """Response when a drone comes closer than r to an obstacle surface (always logged)."""
    planner_budget_s: float = 0.05
    """A planner call that raises, returns no finite direction or takes longer than this puts its drone on hold
    and lands it; the other drones fly on."""
    start_tolerance_m: float = 0.3
    """Preflight: each drone must sit within this distance (xy) of its mission start."""
    arrival_hold_s: float = 0.0
    """Extra hover time at the goals before landing."""
    on_preflight_failure: Literal["ground", "abort"] = "ground"
    """A drone that fails its preflight stays on the ground; ``ground``: the others fly (those whose start or goal
    is within 2r of a grounded drone stay down too: they could not take off or land there); ``abort``: nothing
    takes off. A connection failure always aborts."""
    blind_drift_m_s2: float = 0.45
    """How fast a drone without mocap may drift off where it believes it is (m/s^2: 0.5 a t^2 after t s blind): the
    supervisor's blind rule lands a drone near something, or cuts its motors, before that drift could reach it
    (docs/flight.md, "Blind"). 0.45 (rpf_fly/flight/blind.py, `BLIND_DRIFT_M_S2`) covers with a margin the
    dry run's drones, whose drift comes from the Crazyflie 2.1 IMU's typical zero-g offset and a small tilt error
    of the attitude estimate (at most 0.294 m/s^2); a lab that has measured its own drones' drift without a
    position source sets its figure here."""


@dataclass(frozen=True)
class CircleObstacle:
    """A vertical cylinder: centre (x, y) and radius in metres."""

    center: Vec2
    radius: float
    shape: Literal["circle"] = "circle"


@dataclass(frozen=True)
class BoxObstacle:
    """An axis-aligned box (vertical prism): lower and upper corners in metres."""

    min: Vec2
    max: Vec2
    shape: Literal["box"] = "box"


Obstacle = CircleObstacle | BoxObstacle


@dataclass(frozen=True)
class Drone:
    """One Crazyflie: its name, radio URI, mocap rigid body name, and planar start and goal (metres)."""

    name: str
    uri: str
    rigid_body: str
    start: Vec2
    goal: Vec2


@dataclass(frozen=True)
class SimSettings:
    """Simulation-only settings (ignored in flight): time limit and the seeded randomisation of starts.

    ``start_jitter_m`` moves every start (and, for a circle swap, keeps the goal antipodal) uniformly within a
    disc of that radius; ``angle_jitter_deg`` perturbs each drone's angle on a ``circle_swap`` formation. Both are
    drawn from ``--seed``; 0 means the nominal layout.
    """

    time_limit_s: float = 100.0
    start_jitter_m: float = 0.0
    angle_jitter_deg: float = 0.0


@dataclass(frozen=True)
class DryRunSettings:
    """What the dry run's simulated room does (ignored in flight), for a lab that wants its own figures.

    ``seed`` draws the simulated drones' IMU biases (so the direction a blind drone drifts), their turbulence,
    the radio's loss bursts and the mocap's jitter: the same seed flies the same draws, another seed other ones.
    ``mocap_noise_m`` / ``mocap_noise_deg`` (per-axis jitter of every served pose) and ``mocap_dropout`` (the
    share of a body's frames left untracked): None keeps the emulator's figures (rpf_fly/emulator/mocap_noise.py:
    0.5 mm, 0.5 deg, 0.1 %). ``dynamics``: how the simulated drones fly, ``first-order`` (the emulator's
    documented lags, rpf_fly/emulator/fake_vehicle.py) or ``firmware`` (the firmware's PID cascade on the identified
    Crazyflie 2.1+ body, docs/dynamics.md). ``vehicle``: a vehicle profile (``rpf-fly calibrate``'s, read at load
    time, its path relative to the mission's folder): its firmware parameters in every simulated drone's TOC, its
    mocap latency and noise in the simulated mocap (docs/dynamics.md, "Calibrating a vehicle profile"); it needs
    ``dynamics: firmware``.
    """

    seed: int = 0
    mocap_noise_m: float | None = None
    mocap_noise_deg: float | None = None
    mocap_dropout: float | None = None
    dynamics: str = "firmware"
    radio: Literal["fake", "crazyradio"] = "fake"
    """How the flight's cflib reaches the simulated drones: ``fake`` (the ``fake://`` link driver in front of them)
    or ``crazyradio`` (cflib's own ``radio://`` driver through emulated dongles, rpf_fly/emulator/crazyradio.py;
    docs/radio.md, "Dry runs through cflib's radio driver")."""
    crazyradio: Literal["crazyradio_pa", "crazyradio_2"] | None = None
    """The emulated dongles' type with ``radio: crazyradio`` (None: ``radio.dongle_type``, the lab's own)."""
    vehicle: VehicleProfile | None = None


@dataclass(frozen=True)
class Formation:
    """A generated layout. ``circle_swap``: ``count`` drones evenly on a circle, each flying to the antipode."""

    kind: Literal["circle_swap"]
    count: int
    radius: float
    center: Vec2 = (0.0, 0.0)
    uri_base: str = "radio://0/80/2M/E7E7E7E7"
    name_prefix: str = "cf"
    phase_deg: float = 0.0


@dataclass(frozen=True)
class Mission:
    """A validated mission. ``drones`` is always explicit (a formation is expanded at load time)."""

    name: str
    arena: Arena
    flight: FlightSettings
    planner: PlannerSettings
    mocap: MocapSettings
    radio: RadioSettings
    sim: SimSettings
    obstacles: tuple[Obstacle, ...]
    drones: tuple[Drone, ...]
    formation: Formation | None = None
    safety: SafetySettings = field(default_factory=SafetySettings)
    runtime: RuntimeSettings = field(default_factory=RuntimeSettings)
    dry_run: DryRunSettings = field(default_factory=DryRunSettings)
    source: Path | None = None
    text: str = field(default="", repr=False)
    """The file's text as loaded (logged into flight records as metadata)."""
