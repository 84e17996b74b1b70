"""Run cflib's own examples, unchanged, against the fake radio (``fake://``), and report a table of the results.

    python tools/run_cflib_examples.py [--examples DIR] [--cache DIR] [--only NAME ...] [--timeout S]
                                       [--markdown] [--json FILE]

Without ``--examples`` the examples of the installed cflib's source distribution are used: ``pip download
cflib==<installed version> --no-binary :all: --no-deps`` into ``--cache`` (default ``~/.cache/rpf_fly/cflib``),
unpacked once (cflib 0.1.34's sdist carries ``examples/``; its GitHub repository at the reference commit holds the
same files minus the Lighthouse ones). ``--examples DIR`` takes any directory of example scripts instead.

Each example runs in its own child interpreter, in a temporary copy of the examples directory (so ``./cache``, the
TOC cache the examples pass to cflib, and the files an example reads beside it are where it expects them), with
stdin closed:
- the child first calls ``rpf_fly.emulator.fake_radio.register()`` (drones appear on their first connection; for an
  example that needs its drones somewhere, a world with them there, see `ExampleSpec.drones`), then runs the example
  with ``runpy.run_path(..., run_name="__main__")``. The examples call ``cflib.crtp.init_drivers()`` themselves; it
  only appends cflib's drivers to ``cflib.crtp.CLASSES``, so the fake driver registered before stays first and
  takes ``fake://`` URIs (cflib/crtp/__init__.py);
- the URI: an example that takes it from ``cflib.utils.uri_helper.uri_from_env`` gets ``CFLIB_URI=fake://...`` and
  runs byte for byte unchanged; one with URIs written in the file gets a copy in which ``radio://`` is replaced by
  ``fake://`` and nothing else;
- a timeout (`ExampleSpec.timeout_s`, or ``--timeout``) kills it. An example documented to run until stopped
  (`ExampleSpec.runs_until_stopped`) that is still running without an error when its time is up counts as "ran
  until timeout", separately from "ok".

Results: ``ok`` (exit status 0, no Python traceback in its output, no drone crashed, none left locked or with its
motors on), ``failed`` (with the first error line: the exception of the first traceback, or the last output line;
or what went wrong with a drone), ``timeout``, ``ran until timeout``, ``excluded`` (not
run: the example needs a deck or something else the fake drone does not have, with the reason). Examples found in
the directory that this tool does not know are run with the defaults and marked "not in the list". The table also
says what the drones did, from the fake world's truth (how high and how far they flew, whether they landed).
"""

from __future__ import annotations

import argparse
import importlib.metadata
import json
import os
import re
import shutil
import subprocess
import sys
import tarfile
import tempfile
import time
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_CACHE = Path("~/.cache/rpf_fly/cflib").expanduser()
DEFAULT_TIMEOUT_S = 120.0
FAKE_URI = "fake://0/80/2M/E7E7E7E7E7"
"""The URI an example that reads ``CFLIB_URI`` gets: the examples' own default address, on the fake radio."""

CHILD = r"""
import atexit, json, os, runpy, sys, threading, time
from rpf_fly.emulator import fake_radio
from rpf_fly.emulator.fake_world import FakeDroneConfig, FakeWorld
drones = json.loads(os.environ.get("RPF_FAKE_DRONES", "{}"))
if drones:
    world = FakeWorld({int(a, 16): FakeDroneConfig.at(x, y) for a, (x, y) in drones.items()}, appear_on_connect=True)
    fake_radio.register(world)
else:
    world = fake_radio.register().world
flights = {}
def watch():
    while True:
        for address, snap in world.snapshots().items():
            f = flights.setdefault(address, {"start": snap.position, "max_z": 0.0, "max_xy_m": 0.0})
            f["max_z"] = max(f["max_z"], snap.position[2] - f["start"][2])
            f["max_xy_m"] = max(f["max_xy_m"], ((snap.position[0] - f["start"][0]) ** 2
                                                + (snap.position[1] - f["start"][1]) ** 2) ** 0.5)
            f.update(end=snap.position, motors_on=snap.motors_on, crashed=snap.crashed, locked=snap.locked,
                     crash_reason=snap.crash_reason)
        time.sleep(0.05)
threading.Thread(target=watch, daemon=True).start()
def report():
    deadline = time.monotonic() + 1.0  # a drone whose motors just stopped is still falling: let it land
    while time.monotonic() < deadline and any(not s.motors_on and any(s.velocity)
                                              for s in world.snapshots().values()):
        time.sleep(0.02)
    time.sleep(0.1)  # one more sample of the watch
    with open(os.environ["RPF_FAKE_REPORT"], "w") as out:
        json.dump({f"{a:010X}": f for a, f in flights.items()}, out)
atexit.register(report)
path = sys.argv[1]
sys.argv = sys.argv[1:]
sys.path.insert(0, os.path.dirname(path))
runpy.run_path(path, run_name="__main__")
"""
"""The child's bootstrap (``python -c CHILD example.py args...``): register the fake driver, watch the drones
(every 50 ms: how high and how far each flew, where it ended, motors, crash, lock; written at exit to the file
``RPF_FAKE_REPORT`` names), run the example."""


@dataclass(frozen=True)
class ExampleSpec:
    """How to run one example (or why not)."""

    path: str
    """Relative to the examples directory, with forward slashes."""
    excluded: str = ""
    """Non-empty: not run, and why."""
    args: tuple[str, ...] = ()
    timeout_s: float = DEFAULT_TIMEOUT_S
    runs_until_stopped: bool = False
    drones: dict[str, tuple[float, float]] = field(default_factory=dict)
    """Radio address (hex) -> (x, y) where the drone stands, for examples written for a given layout."""
    label: str = ""
    """The table's name for this run (default: `path`, plus the arguments)."""
    note: str = ""

    @property
    def name(self) -> str:
        return self.label or " ".join((self.path, *self.args))


SBS_SWARM_LAYOUT = {
    "E7E7E7E701": (-0.5, 0.5),
    "E7E7E7E702": (0.5, 0.5),
    "E7E7E7E703": (0.5, -0.5),
    "E7E7E7E704": (-0.5, -0.5),
}
"""sbs_swarm.py's drones, "1 m apart" as its comment draws them (0 top left, 1 top right, 2 bottom right, 3 bottom
left): its relative go-tos swap them around that square; on the fake's default 0.5 m row they would collide."""

KNOWN: tuple[ExampleSpec, ...] = (
    ExampleSpec(
        "autonomy/autonomous_sequence.py",
        note="written for Loco/Lighthouse positioning: the fake drone's onboard positioning stands in",
    ),
    ExampleSpec("autonomy/autonomous_sequence_high_level.py", note="uploads and flies a figure-8 trajectory"),
    ExampleSpec(
        "autonomy/autonomous_sequence_high_level.py",
        args=("--relative-yaw",),
        note="the same, rotated to the take-off yaw",
    ),
    ExampleSpec(
        "autonomy/motion_commander_demo.py",
        note="written for the Flow deck (uses none of its API): the onboard positioning stands in",
    ),
    ExampleSpec("logging/basiclog.py"),
    ExampleSpec("logging/basiclog_sync.py"),
    ExampleSpec("parameters/basicparam.py"),
    ExampleSpec(
        "parameters/persistent_params.py",
        note="stores ring.effect, a parameter of the LED-ring driver the firmware always has",
    ),
    ExampleSpec(
        "parameters/persistent_params_from_file.py",
        note="stores activeMarker.back, a parameter of the active-marker driver the firmware always has",
    ),
    ExampleSpec("step-by-step/sbs_connect_log_param.py"),
    ExampleSpec(
        "step-by-step/sbs_swarm.py",
        drones=SBS_SWARM_LAYOUT,
        note="4 drones placed as its comment draws them (1 m square)",
    ),
    ExampleSpec(
        "step-by-step/sbs_motion_commander.py",
        excluded="needs a Flow deck v2: it waits for deck.bcFlow2 = 1 and exits without one",
    ),
    ExampleSpec(
        "lighthouse/multi_bs_geometry_estimation.py",
        excluded="needs a Lighthouse deck (its sensor sweeps, the Lighthouse memory) and a person: it "
        "waits for input() at every step",
    ),
    ExampleSpec(
        "lighthouse/upload_geos.py",
        excluded="needs a Lighthouse deck (writes the Lighthouse memory, which only its driver registers) "
        "and the user's geometry file (/path/to/your/geo.yaml)",
    ),
)


@dataclass
class Result:
    """One row of the table."""

    name: str
    result: str
    """ok, failed, timeout, ran until timeout, excluded."""
    seconds: float
    detail: str = ""
    """The first error line of a failure, the reason of an exclusion, or a note."""
    flight: str = ""
    """What the drones did (`describe_flights`), from the child's watch of the fake world."""


def installed_cflib_version() -> str:
    return importlib.metadata.version("cflib")


def fetch_examples(cache: Path, version: str) -> Path:
    """The examples directory of cflib `version`'s sdist, downloaded with pip into `cache` and unpacked once."""
    target = cache / f"cflib-{version}"
    examples = target / "examples"
    if examples.is_dir():
        return examples
    cache.mkdir(parents=True, exist_ok=True)
    archive = cache / f"cflib-{version}.tar.gz"
    if not archive.exists():
        command = [
            sys.executable,
            "-m",
            "pip",
            "download",
            f"cflib=={version}",
            "--no-binary",
            ":all:",
            "--no-deps",
            "--quiet",
            "-d",
            str(cache),
        ]
        done = subprocess.run(command, capture_output=True, text=True)
        if done.returncode != 0 or not archive.exists():
            last = ((done.stderr or done.stdout).strip().splitlines() or ["no output"])[-1]
            raise SystemExit(
                f"error: could not download the cflib {version} sdist with pip ({last}); "
                f"give a local copy with --examples DIR"
            )
    with tarfile.open(archive) as tar:
        members = [
            m
            for m in tar.getmembers()
            if m.name.startswith(f"cflib-{version}/examples/")
            and ".." not in Path(m.name).parts
            and (m.isfile() or m.isdir())
        ]
        try:
            tar.extractall(cache, members=members, filter="data")
        except TypeError:  # Python before 3.10.12 / 3.11.4: no extraction filters (the names were checked above)
            tar.extractall(cache, members=members)
    if not examples.is_dir():
        raise SystemExit(f"error: the cflib {version} sdist has no examples/ directory")
    return examples


def discover(examples: Path) -> list[str]:
    """Every example script (``*.py``) under `examples`, relative, sorted."""
    return sorted(p.relative_to(examples).as_posix() for p in examples.rglob("*.py") if p.is_file())


def plan(found: Iterable[str]) -> list[ExampleSpec]:
    """The runs for the examples found: each known one as listed (some twice, with other arguments), unknown ones
    with the defaults; known ones not found are left out."""
    found = list(found)
    specs = [spec for spec in KNOWN if spec.path in found]
    known_paths = {spec.path for spec in KNOWN}
    specs += [
        ExampleSpec(path, note="not in the list: run with the defaults") for path in found if path not in known_paths
    ]
    return specs


def uses_uri_from_env(source: str) -> bool:
    """True when the example takes its URI from ``uri_helper.uri_from_env`` (then ``CFLIB_URI`` is enough)."""
    return "uri_from_env(" in source


def first_error_line(output: str) -> str:
    """The exception line of the first traceback in `output`, else its last non-empty line."""
    lines = output.splitlines()
    for index, line in enumerate(lines):
        if line.startswith("Traceback (most recent call last):"):
            for candidate in lines[index + 1 :]:
                if candidate and not candidate.startswith((" ", "\t")):
                    return candidate.strip()
    rest = [line.strip() for line in lines if line.strip()]
    return rest[-1] if rest else ""


def describe_flights(flights: dict[str, dict]) -> tuple[str, str]:
    """(summary, problem) of the child's flight report: e.g. "1 drone: up to 1.20 m and 0.71 m across, landed";
    the problem is non-empty when a drone crashed, or ended locked or with its motors on."""
    if not flights:
        return "no drone", ""
    rising = max(f["max_z"] for f in flights.values())
    across = max(f["max_xy_m"] for f in flights.values())
    count = f"{len(flights)} drone" + ("s" if len(flights) > 1 else "")
    if rising < 0.05:
        summary = f"{count}: did not fly"
    else:
        down = all(not f["motors_on"] and f["end"][2] - f["start"][2] < 0.02 for f in flights.values())
        summary = f"{count}: up to {rising:.2f} m and {across:.2f} m across, " + ("landed" if down else "not landed")
    problems = [f"{a} crashed ({f['crash_reason']})" for a, f in flights.items() if f["crashed"]]
    problems += [f"{a} ended locked" for a, f in flights.items() if f["locked"] and not f["crashed"]]
    problems += [f"{a} ended with its motors on" for a, f in flights.items() if f["motors_on"]]
    return summary, "; ".join(problems)


def run_one(
    spec: ExampleSpec, examples: Path, timeout_s: float | None = None, keep_output: Path | None = None
) -> Result:
    """Run one example (see the module docstring); never raises for the example's own failures."""
    if spec.excluded:
        return Result(spec.name, "excluded", 0.0, spec.excluded)
    timeout = timeout_s if timeout_s is not None else spec.timeout_s
    with tempfile.TemporaryDirectory(prefix="cflib-example-") as tmp:
        copy = Path(tmp) / "examples"
        shutil.copytree(examples, copy)
        (copy / "cache").mkdir(exist_ok=True)
        script = copy / spec.path
        source = script.read_text(encoding="utf-8")
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH", "")) if p)
        env["PYTHONUNBUFFERED"] = "1"
        if uses_uri_from_env(source):
            env["CFLIB_URI"] = FAKE_URI
        else:
            script.write_text(source.replace("radio://", "fake://"), encoding="utf-8")
        if spec.drones:
            env["RPF_FAKE_DRONES"] = json.dumps(spec.drones)
        flight_report = Path(tmp) / "flights.json"
        env["RPF_FAKE_REPORT"] = str(flight_report)
        log = Path(tmp) / "output.txt"
        start = time.monotonic()
        with open(log, "w", encoding="utf-8") as out:
            child = subprocess.Popen(
                [sys.executable, "-c", CHILD, str(script), *spec.args],
                cwd=copy,
                env=env,
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=subprocess.STDOUT,
            )
            try:
                code: int | None = child.wait(timeout)
            except subprocess.TimeoutExpired:
                child.kill()
                child.wait()
                code = None
        seconds = time.monotonic() - start
        output = log.read_text(encoding="utf-8", errors="replace")
        flights = json.loads(flight_report.read_text()) if flight_report.exists() else {}
        if keep_output is not None:
            keep_output.mkdir(parents=True, exist_ok=True)
            (keep_output / (re.sub(r"[^A-Za-z0-9_.-]+", "_", spec.name) + ".txt")).write_text(output)
    traceback = "Traceback (most recent call last):" in output
    flight, problem = describe_flights(flights) if flights or code is not None else ("", "")
    if code is None:
        if spec.runs_until_stopped and not traceback:
            return Result(spec.name, "ran until timeout", seconds, f"stopped after {timeout:g} s, no error", flight)
        return Result(
            spec.name, "timeout", seconds, f"killed after {timeout:g} s; last line: {first_error_line(output)}", flight
        )
    if code != 0 or traceback:
        return Result(spec.name, "failed", seconds, f"exit {code}: {first_error_line(output)}", flight)
    if problem:
        return Result(spec.name, "failed", seconds, problem, flight)
    return Result(spec.name, "ok", seconds, spec.note, flight)


def summary(results: Sequence[Result]) -> str:
    run = [r for r in results if r.result != "excluded"]
    counts = {kind: sum(r.result == kind for r in run) for kind in ("ok", "ran until timeout", "failed", "timeout")}
    return (
        f"{counts['ok']} of {len(run)} runs ok, {counts['ran until timeout']} ran until their timeout without "
        f"error, {counts['failed']} failed, {counts['timeout']} timed out; "
        f"{len(results) - len(run)} excluded"
    )


def table(results: Sequence[Result], markdown: bool) -> str:
    rows = [
        (r.name, r.result, f"{r.seconds:.1f}" if r.result != "excluded" else "-", r.flight, r.detail) for r in results
    ]
    header = ("example", "result", "seconds", "drones (the fake world's truth)", "notes")
    if markdown:
        lines = ["| " + " | ".join(header) + " |", "|---|---|---|---|---|"]
        lines += ["| " + " | ".join(cell.replace("|", "\\|") for cell in row) + " |" for row in rows]
        return "\n".join(lines)
    widths = [max(len(row[i]) for row in (header, *rows)) for i in range(4)]
    return "\n".join(
        f"{row[0]:<{widths[0]}}  {row[1]:<{widths[1]}}  {row[2]:>{widths[2]}}  {row[3]:<{widths[3]}}  {row[4]}"
        for row in (header, *rows)
    )


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--examples", type=Path, help="a directory of example scripts (default: cflib's sdist)")
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE, help="where the sdist is downloaded")
    parser.add_argument("--only", nargs="+", default=None, help="run only the examples whose path contains these")
    parser.add_argument("--timeout", type=float, default=None, help="seconds per example (default: each one's)")
    parser.add_argument("--markdown", action="store_true", help="print the table as Markdown")
    parser.add_argument("--json", type=Path, default=None, help="also write the results as JSON")
    parser.add_argument("--output-dir", type=Path, default=None, help="keep each example's output there")
    args = parser.parse_args(argv)
    if args.examples is not None and not args.examples.is_dir():
        parser.error(f"--examples {args.examples}: not a directory")
    if args.timeout is not None and not args.timeout > 0:
        parser.error(f"--timeout {args.timeout}: must be > 0 seconds")
    examples = args.examples.resolve() if args.examples else fetch_examples(args.cache, installed_cflib_version())
    specs = plan(discover(examples))
    if args.only:
        specs = [s for s in specs if any(word in s.name for word in args.only)]
    if not specs:
        parser.error(f"no examples to run in {examples}")
    results = []
    for spec in specs:
        result = run_one(spec, examples, args.timeout, args.output_dir)
        print(
            f"{result.name}: {result.result} ({result.seconds:.1f} s) {result.flight} {result.detail}",
            file=sys.stderr,
            flush=True,
        )
        results.append(result)
    print(f"cflib {installed_cflib_version()}, examples from {examples}")
    print(table(results, args.markdown))
    print(summary(results))
    if args.json is not None:
        args.json.write_text(json.dumps([asdict(r) for r in results], indent=2))
    return 0 if all(r.result in ("ok", "ran until timeout", "excluded") for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
