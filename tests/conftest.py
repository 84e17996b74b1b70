"""Fixtures shared by the emulator and radio tests: one fake world per test, a warm cflib TOC cache per worker,
a hang guard (autouse in tests/emulator and tests/radio, through their conftest)."""

from __future__ import annotations

import faulthandler
import json
import os
import signal
import sys
import tempfile
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path

if os.environ.pop("PYTHONDONTWRITEBYTECODE", None):
    # The suite starts a few hundred Python processes (its workers, each dry run's flight and simulated drones):
    # on a host that sets PYTHONDONTWRITEBYTECODE each of them compiles everything it imports, about 13 s of the
    # suite's wall in a fresh clone. They keep their bytecode in a cache of their own outside the checkout instead
    # (the checkout stays as clean as the variable keeps it); this process is not affected.
    os.environ.setdefault("PYTHONPYCACHEPREFIX", str(Path(tempfile.gettempdir()) / f"rpf-fly-pycache-{os.getuid()}"))

import cflib.crtp
import pytest
from cflib.crazyflie import Crazyflie
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie
from host_retry import STARVED_KINDS, fly_on_time, wait_for_a_calm_host
from xdist_ids import keep_failures_by_plain_id

from rpf_fly.emulator import fake_radio
from rpf_fly.emulator.fake_world import FakeDroneConfig, FakeWorld

ADDRESS_BASE = 0xE7E7E7E700
HANG_GUARD_S = 120.0
"""A radio test that runs longer than this is stuck (cflib waits forever on silence): dump stacks and exit."""


def address(index: int) -> int:
    """Radio address of drone `index` in the test worlds."""
    return ADDRESS_BASE + index


def fake_drivers() -> list[type]:
    return [c for c in cflib.crtp.CLASSES if isinstance(c, type) and issubclass(c, fake_radio.FakeRadioDriver)]


def _behind_in(host_log: Path) -> list[float]:
    """The seconds behind that the dry runs in other processes wrote to ``host_log`` (`host_watch.HOST_LOG_ENV`;
    this process's own are in `host_watch.WATCHED`)."""
    try:
        lines = host_log.read_text().splitlines()
    except OSError:
        return []
    out = []
    for line in lines:
        try:
            record = json.loads(line)
            if record["pid"] != os.getpid():
                out.append(float(record["behind_s"]))
        except (ValueError, KeyError, TypeError):
            continue
    return out


HOST_TRIES = 2
"""A test whose own dry run the host held back (its report's ``host`` section) and that failed runs this many times in
all, the next once the host is calm, as the fault campaign flies such a run again; one that failed on time fails."""
HOST_CALM_WAIT_S = 30.0
"""How long a test to be run again waits for a calm host at most (`host_retry.wait_for_a_calm_host`)."""


def _held_back(reports: list[pytest.TestReport]) -> bool:
    return any(r.failed and any(name == "host" for name, _ in r.sections) for r in reports)


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> bool:
    """Run the test; run it again (up to `HOST_TRIES` in all) when it failed and its own dry run says the host
    held it back (`pytest_runtest_makereport` below adds the ``host`` section): its verdict was the host's. Only the
    last run's reports are reported; they say how many ran before."""
    from _pytest.runner import runtestprotocol

    item.ihook.pytest_runtest_logstart(nodeid=item.nodeid, location=item.location)
    earlier: list[str] = []
    for attempt in range(HOST_TRIES):
        reports = runtestprotocol(item, nextitem=nextitem, log=False)
        if attempt == HOST_TRIES - 1 or not _held_back(reports):
            break
        failed = next(r for r in reports if r.failed)
        waited = wait_for_a_calm_host(HOST_CALM_WAIT_S)
        earlier.append(
            f"run {attempt + 1} failed ({failed.when}) with the host behind: {failed.longreprtext.splitlines()[0]}; "
            f"run again after {waited:.0f} s"
        )
    for report in reports:
        if earlier:
            report.sections.append(("host: runs before", "\n".join(earlier)))
        item.ihook.pytest_runtest_logreport(report=report)
    item.ihook.pytest_runtest_logfinish(nodeid=item.nodeid, location=item.location)
    return True


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo) -> Iterator[None]:
    """A failed test whose dry run fell behind on a host that could not keep up says so first: its verdict is the
    host's, not the stack's (rpf_fly/emulator/host_lag.py)."""
    from rpf_fly.emulator.host_lag import HOST_BEHIND_REPORT_S
    from rpf_fly.flight.host_watch import HOST_LOG_ENV, WATCHED

    host_log = Path(tempfile.gettempdir()) / f"rpf-fly-host-{os.getpid()}.jsonl"
    if call.when == "setup":
        WATCHED.clear()
        host_log.write_text("")  # the dry runs this test flies in processes of their own append here
        os.environ[HOST_LOG_ENV] = str(host_log)
    outcome = yield
    report = outcome.get_result()
    if call.when == "call" and report.failed:
        behind = sum(WATCHED) + sum(_behind_in(host_log))
        if behind >= HOST_BEHIND_REPORT_S:
            report.sections.append(
                (
                    "host",
                    f"the host could not keep up for {behind:.1f} s: this dry run is not "
                    "evidence (rerun on an idle machine)",
                )
            )
            report.longrepr = (
                f"the host could not keep up for {behind:.1f} s: this dry run is not evidence\n{report.longrepr}"
            )


LONGEST_GROUPS = ("scenario", "lab", "cli_flights", "calibrate_flights", "replay_logs")
"""The shared flights' groups, longest first (one worker each: 60-130 s, 126, 87, 68 and 56 s)."""
FLIGHT_DIRS = ("flight", "runtime", "tools", "campaign", "calibrate", "cli", "log")
"""Where the dry-run flight tests of 5-25 s each live."""


def longest_first(item: pytest.Item) -> tuple[int, int]:
    """The order xdist hands out the work: the long shared flights first, then the folders of dry-run flights, then
    the rest (a worker that ends with a 20 s flight while the others are done is the suite's tail; the work is handed
    out in collection order, so the short tests go last and end the workers together). Stable: each module's tests
    keep their order."""
    mark = item.get_closest_marker("xdist_group")
    group = (mark.args[0] if mark.args else mark.kwargs.get("name")) if mark is not None else None
    if group in LONGEST_GROUPS:
        return (0, LONGEST_GROUPS.index(group))
    folder = item.path.parent.name
    return (1, FLIGHT_DIRS.index(folder)) if folder in FLIGHT_DIRS else (2, 0)


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Refuse to run when pytest-xdist's ``--dist loadgroup`` (pyproject addopts) has not grouped the marked tests.

    The CLI flights, crash logs and bench runs are shared by the tests of one ``xdist_group`` only while those tests
    share a worker; otherwise each worker flies them again (minutes) and two workers race over one install
    (tools/mcap_js). Under pytest 9.2 xdist 3.8's grouping is a silent no-op (it renames ``item._nodeid``, which 9.2
    does not read), so pyproject pins pytest below 9.2."""
    if not getattr(config.option, "loadgroup", False):
        return  # not a loadgroup worker: a run without -n, or another --dist (the controller checks the version)
    items.sort(key=longest_first)
    ungrouped = [
        item.nodeid for item in items if item.get_closest_marker("xdist_group") is not None and "@" not in item.nodeid
    ]
    if ungrouped:
        raise pytest.UsageError(
            f"pytest-xdist's loadgroup did not group {len(ungrouped)} marked tests (first: {ungrouped[0]}) under "
            f"pytest {pytest.__version__}: install the pytest that pyproject's dev extra pins"
        )


def pytest_configure(config: pytest.Config) -> None:
    """Run the tests as a foreground Python program: Ctrl-C raises KeyboardInterrupt, and the programs the tests start
    (``rpf-fly mocap watch``, a library user's flight) hear SIGINT. A test run started in the background of a shell
    without job control (``pytest ... &`` in a script) inherits SIGINT ignored; Python keeps an ignored SIGINT, and
    so does every child it starts, so the Ctrl-C tests would fail there for a reason that is not theirs."""
    # A pytest that breaks xdist's grouping is named here, on the controller (pytest_collection_modifyitems below
    # catches any other cause, on the workers, less legibly).
    if (
        config.getoption("dist", "no") == "loadgroup"
        and config.getoption("numprocesses", None)
        and tuple(int(part) for part in pytest.__version__.split(".")[:2]) >= (9, 2)
    ):
        raise pytest.UsageError(
            f"pytest {pytest.__version__} ignores pytest-xdist's --dist loadgroup (the shared test "
            f"flights would fly on every worker): pip install 'pytest>=8,<9.2' (pyproject's dev "
            f"extra)"
        )
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    # `pytest --lf` reruns the failures alone after a run with or without -n (the grouped tests' ids: xdist_ids.py).
    keep_failures_by_plain_id(config)


@pytest.fixture(autouse=True)
def sigint_handler_left_as_found() -> Iterator[None]:
    """Every test leaves Python's SIGINT handler as it found it: a handler left behind by one test (a flight's
    Ctrl-C hook) would take the next test's Ctrl-C, and that flight would never hear it."""
    before = signal.getsignal(signal.SIGINT)
    yield
    after = signal.getsignal(signal.SIGINT)
    if after is not before:
        signal.signal(signal.SIGINT, before)
        pytest.fail(f"the test left SIGINT handled by {after!r} (it found {before!r})")


@pytest.fixture
def hang_guard() -> Iterator[None]:
    faulthandler.dump_traceback_later(HANG_GUARD_S, exit=True, file=sys.stderr)
    yield
    faulthandler.cancel_dump_traceback_later()


MakeWorld = Callable[..., FakeWorld]


@pytest.fixture
def make_world() -> Iterator[MakeWorld]:
    """``make_world(n_or_configs, **FakeWorld kwargs)``: a registered `FakeWorld`; drones ``i`` at (0.5 i, 0, 0)
    when given a count. Teardown unregisters the driver and powers the world off."""
    worlds: list[FakeWorld] = []

    def make(drones: int | Mapping[int, FakeDroneConfig], **kwargs: object) -> FakeWorld:
        configs = (
            {address(i): FakeDroneConfig.at(0.5 * i, 0.0) for i in range(drones)}
            if isinstance(drones, int)
            else dict(drones)
        )
        world = FakeWorld(configs, **kwargs)  # type: ignore[arg-type]
        fake_radio.register(world)
        worlds.append(world)
        return world

    yield make
    fake_radio.unregister()
    for world in worlds:
        world.close()
    assert fake_drivers() == []


@pytest.fixture(scope="session")
def toc_cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A cflib TOC cache directory, warmed by one connection (one JSON file per TOC)."""
    path = tmp_path_factory.mktemp("toc_cache")
    world = FakeWorld({address(0): FakeDroneConfig()})
    fake_radio.register(world)
    try:
        with SyncCrazyflie(world.uri(address(0)), cf=Crazyflie(rw_cache=str(path))) as scf:
            scf.wait_for_params()
    finally:
        fake_radio.unregister()
        world.close()
    assert len(list(path.glob("*.json"))) == 2
    return path


# --------------------------------------------------------------------------- real flights through the real CLI

CLI_MISSION = """\
name: short-3
arena: {x: [-2.0, 2.0], y: [-2.0, 2.0], z: [0.0, 1.5]}
flight: {height: 0.5, speed: 0.5, rate_hz: 10, goal_tolerance: 0.1, takeoff_s: 1.0, land_s: 1.0, timeout_s: 60}
planner: {kind: apf, margin: 0}
mocap: {kind: sim, rate_hz: 100}
obstacles:
  - {shape: circle, center: [0.0, 0.9], radius: 0.1}
drones:
  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [-1.0, -0.6], goal: [1.5, -0.6]}
  - {name: cf2, uri: radio://0/80/2M/E7E7E7E702, start: [-1.0, 0.0], goal: [1.5, 0.0]}
  - {name: cf3, uri: radio://0/80/2M/E7E7E7E703, start: [-1.0, 0.6], goal: [1.5, 0.6]}
"""
"""Three drones, 2.5 m each, one pole: a dry run of about 15 s through ``python -m rpf_fly fly``."""


class CliFlight:
    """A dry run of ``rpf-fly fly`` in a real process (stdout and stderr piped: not a terminal) and its log."""

    def __init__(self, returncode: int, stdout: str, stderr: str, log: Path):
        self.returncode, self.stdout, self.stderr, self.log = returncode, stdout, stderr, log


def fly_cli(folder: Path, *, interrupts: int = 0, kill: bool = False, args: tuple[str, ...] = ()) -> CliFlight:
    """Fly :data:`CLI_MISSION` with ``--dry-run``; ``interrupts`` SIGINTs (0.2 s apart) or a SIGKILL 2.5 s after the
    swarm starts flying."""
    import os
    import signal
    import subprocess
    import time

    mission = folder / "short.yaml"
    mission.write_text(CLI_MISSION)
    log = folder / "flight.mcap"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen(
        [sys.executable, "-m", "rpf_fly", "fly", str(mission), "--dry-run", "--log", str(log), *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=folder,
    )
    if interrupts or kill:
        lines = []
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            line = proc.stderr.readline()
            if not line:
                break
            lines.append(line)
            if "swarm: flying" in line:
                break
        else:
            proc.kill()
            raise AssertionError("the flight never started:\n" + "".join(lines))
        time.sleep(2.5 if kill else 1.0)
        if kill:
            proc.send_signal(signal.SIGKILL)
        for _ in range(interrupts):
            proc.send_signal(signal.SIGINT)
            time.sleep(0.2)
        out, err = proc.communicate(timeout=90)
        err = "".join(lines) + err
    else:
        out, err = proc.communicate(timeout=120)
    return CliFlight(proc.returncode, out, err, log)


STARVED_LINES = tuple(f"[{kind}] " for kind in STARVED_KINDS)
"""A CLI flight's event lines that say the host held it back (`host_retry.STARVED_KINDS`)."""


def fly_cli_on_time(folder: Path, exit_code: int, interrupts: int = 0) -> CliFlight:
    """`fly_cli` for a flight other tests read, flown again while it did not exit with ``exit_code`` and its stderr
    says the host held it back (`host_retry.fly_on_time`)."""
    return fly_on_time(
        lambda at: fly_cli(at, interrupts=interrupts),
        folder,
        lambda flight: flight.returncode == exit_code,
        lambda flight: any(line.startswith(STARVED_LINES) for line in flight.stderr.splitlines()),
    )


@pytest.fixture(scope="session")
def clean_cli_flight(tmp_path_factory: pytest.TempPathFactory) -> CliFlight:
    """Every drone reaches its goal and lands."""
    return fly_cli_on_time(tmp_path_factory.mktemp("clean-flight"), 0)


@pytest.fixture(scope="session")
def landed_cli_flight(tmp_path_factory: pytest.TempPathFactory) -> CliFlight:
    """Ctrl-C once in flight: every drone lands early, exit 130."""
    return fly_cli_on_time(tmp_path_factory.mktemp("landed-flight"), 130, interrupts=1)


@pytest.fixture(scope="session")
def stopped_cli_flight(tmp_path_factory: pytest.TempPathFactory) -> CliFlight:
    """Ctrl-C twice in flight: every motor cut (emergency stop), exit 130."""
    return fly_cli_on_time(tmp_path_factory.mktemp("stopped-flight"), 130, interrupts=2)


@pytest.fixture(scope="session")
def killed_cli_flight(tmp_path_factory: pytest.TempPathFactory) -> CliFlight:
    """SIGKILL in flight: a log without its summary and footer."""
    return fly_cli(tmp_path_factory.mktemp("killed-flight"), kill=True)
