"""The distributed swarm's acceptance flights (docs/distributed.md), each judged on the simulated world's truth.

    python tools/swarm_acceptance.py                         # the 40-drone flight, then the kill (about 2 minutes)
    python tools/swarm_acceptance.py --runs flight --json out.json
    python tools/swarm_acceptance.py --mission missions/cross-40-4dongles.yaml     # the kill in the others' paths

Each run is ``rpf-fly fly MISSION --dry-run --distributed --no-console --log L`` in a process of its own, as a user
types it. The verdict does not trust the stack: it reads the log with the mcap library itself (the fault campaign's
reader, tools/fault_campaign.py) and judges the ``/truth/<drone>`` topics, the ``/radio/<dongle>`` loads and the
events, then runs ``rpf-fly review --json`` on the log as a user would.

``flight``: every drone at its goal and landed (true position within 0.25 m of its goal, motors off, on the floor,
and its outcome ``reached``); no drone crashed; no two airborne drones' true centres closer than 0.13 m; every
dongle's measured load within its budget (each ``/radio/<dongle>`` window's packets a second); the log reviews as one
flight (one ``runtime.flight_id``, every drone in it, exit 0).

``kill``: the same mission; once every drone plans, the worker of ``--kill-dongle`` is SIGKILLed. An event of level
warning or above naming that worker must come within 1 s of the kill; every other drone reaches its goal and lands,
none crashes, and none comes within 0.13 m of any drone (the dead worker's drones included: they hover, then their
firmware's watchdog levels them and cuts their motors, and they fall where they are).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tools"))

from fault_campaign import CONTACT_M, GOAL_M, ON_FLOOR_M, read_log  # noqa: E402

from rpf_fly.mission import load_mission  # noqa: E402
from rpf_fly.radio.budget import dongle_of  # noqa: E402

MISSION = ROOT / "missions" / "lanes-40-4dongles.yaml"
EVENT_WINDOW_S = 1.0
KILL_AFTER_PLANNING_S = 1.0
"""The kill comes this long after the drones start planning (the coordinator's ``swarm: flying`` plus the mission's
take-off time): mid-flight, every drone moving."""


@dataclass
class Verdict:
    run: str
    mission: str
    drones: int
    passed: bool = False
    exit_code: int | None = None
    seconds: float = 0.0
    reached: int = 0
    failures: list[str] = field(default_factory=list)
    min_separation_m: float | None = None
    radio_peak_per_s: dict[str, float] = field(default_factory=dict)
    radio_budget_per_s: dict[str, float] = field(default_factory=dict)
    killed: str | None = None
    noticed_after_s: float | None = None
    notice: str | None = None
    log: str = ""


def _worker_pid(flight_log: Path, dongle: int, timeout_s: float = 60.0) -> int:
    """The pid of the local worker process flying ``dongle`` (found as ``ps`` would: by its command line)."""
    deadline = time.monotonic() + timeout_s
    needle = ["worker", "--dongle", str(dongle), "--flight", flight_log.stem]
    while time.monotonic() < deadline:
        for pid in os.listdir("/proc"):
            if not pid.isdigit():
                continue
            try:
                args = Path(f"/proc/{pid}/cmdline").read_bytes().decode().split("\0")
            except OSError:
                continue
            if all(word in args for word in needle):
                return int(pid)
        time.sleep(0.1)
    raise RuntimeError(f"no worker process for dongle {dongle} within {timeout_s:.0f} s")


def fly(
    mission_path: Path, workdir: Path, kill_dongle: int | None = None, kill_after_s: float = KILL_AFTER_PLANNING_S
) -> Verdict:
    mission = load_mission(mission_path)
    names = [d.name for d in mission.drones]
    run = "flight" if kill_dongle is None else f"kill dongle-{kill_dongle}"
    verdict = Verdict(run, mission.name, len(names))
    log = workdir / f"{mission.name}-{'flight' if kill_dongle is None else 'kill'}.mcap"
    verdict.log = str(log)
    limit = mission.flight.timeout_s + 180.0
    started = time.monotonic()
    child = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "rpf_fly",
            "fly",
            str(mission_path),
            "--dry-run",
            "--distributed",
            "--no-console",
            "--log",
            str(log),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        cwd=workdir,
    )
    assert child.stdout is not None
    output: list[str] = []
    flying = threading.Event()

    def read() -> None:
        for line in child.stdout:  # type: ignore[union-attr]
            output.append(line)
            if "swarm: flying" in line:
                flying.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    killed_ns: int | None = None
    if kill_dongle is not None:
        pid = _worker_pid(log, kill_dongle)
        if flying.wait(limit):
            time.sleep(mission.flight.takeoff_s + kill_after_s)
            killed_ns = time.time_ns()
            os.kill(pid, signal.SIGKILL)
            verdict.killed = f"dongle-{kill_dongle} (pid {pid})"
        else:
            verdict.failures.append("the swarm never flew: nothing killed")
    try:
        verdict.exit_code = child.wait(timeout=limit)
    except subprocess.TimeoutExpired:
        child.kill()
        verdict.failures.append(f"did not exit within {limit:.0f} s")
        return verdict
    reader.join(5.0)
    verdict.seconds = round(time.monotonic() - started, 1)
    fail = verdict.failures.append
    text = "".join(output)
    if "Traceback" in text:
        fail("traceback in the output")
    outcomes = {}
    for line in text.splitlines():
        name, _, rest = line.partition(": ")
        if name in names:
            outcomes[name] = rest.split(" ")[0]
    topics, _ = read_log(log)
    dead = set() if kill_dongle is None else {d.name for d in mission.drones if dongle_of(d.uri) == kill_dongle}
    _judge_truth(verdict, mission, topics, outcomes, dead)
    _judge_radio(verdict, topics)
    _judge_review(verdict, log, workdir, len(names))
    if killed_ns is not None:
        worker = f"dongle-{kill_dongle}"
        events = [
            (t, m)
            for t, m in topics.get("/events", [])
            if m.get("level", 0) >= 3 and worker in m.get("message", "") and t >= killed_ns
        ]
        if not events:
            fail(f"no warning naming {worker} after the kill")
        else:
            t, m = events[0]
            verdict.noticed_after_s = round((t - killed_ns) / 1e9, 3)
            verdict.notice = m.get("message", "")[:160]
            if verdict.noticed_after_s > EVENT_WINDOW_S:
                fail(f"{worker} named {verdict.noticed_after_s:.2f} s after the kill (> {EVENT_WINDOW_S:g} s)")
    expected = 0 if kill_dongle is None else 1
    if verdict.exit_code != expected:
        fail(f"exit code {verdict.exit_code}, expected {expected}")
    verdict.passed = not verdict.failures
    return verdict


def _judge_truth(verdict: Verdict, mission: Any, topics: dict, outcomes: dict[str, str], dead: set[str]) -> None:
    fail = verdict.failures.append
    names = [d.name for d in mission.drones]
    truth = {n: topics.get(f"/truth/{n}", []) for n in names}
    missing = [n for n, s in truth.items() if not s]
    if missing:
        fail("no /truth for " + ", ".join(missing))
        return
    crashed = sorted(n for n, s in truth.items() if n not in dead and any(m["crashed"] for _, m in s))
    if crashed:
        fail("crashed: " + ", ".join(crashed))
    goals = {d.name: d.goal for d in mission.drones}
    for n in names:
        if n in dead:
            continue
        last = truth[n][-1][1]
        p = last["position"]
        if last["motors"] or p["z"] > ON_FLOOR_M:
            fail(f"{n} not down at the end (motors {last['motors']}, z {p['z']:.2f} m)")
        if math.dist((p["x"], p["y"]), goals[n]) < GOAL_M and outcomes.get(n) == "reached":
            verdict.reached += 1
        else:
            fail(
                f"{n} did not reach its goal ({outcomes.get(n)}, {math.dist((p['x'], p['y']), goals[n]):.2f} m from it)"
            )
    verdict.min_separation_m = _min_separation(truth, dead)
    if verdict.min_separation_m is not None and verdict.min_separation_m < CONTACT_M:
        fail(f"two drones {verdict.min_separation_m:.3f} m apart (< {CONTACT_M} m)")


def _min_separation(truth: dict[str, list[tuple[int, dict]]], dead: set[str]) -> float | None:
    """Smallest true distance between two drones at the same world step where at least one is airborne and one is
    a survivor (the dead worker's drones among themselves are not the others' business), vectorised over pairs."""
    import numpy as np

    names = list(truth)
    length = min(len(s) for s in truth.values())
    pos = np.array(
        [[[m["position"]["x"], m["position"]["y"], m["position"]["z"]] for _, m in truth[n][:length]] for n in names]
    )  # (drones, steps, 3)
    airborne = np.array([[m["motors"] or m["position"]["z"] > ON_FLOOR_M for _, m in truth[n][:length]] for n in names])
    alive = np.array([n not in dead for n in names])
    best: float | None = None
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            if not (alive[i] or alive[j]):
                continue
            both = airborne[i] | airborne[j]
            if not both.any():
                continue
            d = float(np.min(np.linalg.norm(pos[i][both] - pos[j][both], axis=1)))
            best = d if best is None or d < best else best
    return best


def _judge_radio(verdict: Verdict, topics: dict) -> None:
    for topic, samples in topics.items():
        if not topic.startswith("/radio/"):
            continue
        dongle = topic.split("/")[2]
        peak = max((m["packets_per_s"] for _, m in samples), default=0.0)
        budget = max((m.get("budget_per_s", 0.0) for _, m in samples), default=0.0)
        verdict.radio_peak_per_s[dongle] = round(peak, 1)
        verdict.radio_budget_per_s[dongle] = budget
        if budget and peak > budget:
            verdict.failures.append(f"dongle {dongle}: {peak:.0f} packets/s, over its budget of {budget:.0f}")
    if not verdict.radio_peak_per_s:
        verdict.failures.append("no /radio/<dongle> topic in the log")


def _judge_review(verdict: Verdict, log: Path, workdir: Path, drones: int) -> None:
    review = subprocess.run(
        [sys.executable, "-m", "rpf_fly", "review", str(log), "--json"],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=workdir,
    )
    if review.returncode != 0:
        verdict.failures.append(f"review failed: {review.stderr.strip()[-200:]}")
        return
    data = json.loads(review.stdout)
    if data.get("drones") != drones:
        verdict.failures.append(f"review: {data.get('drones')} drones, expected {drones}")
    from mcap.reader import make_reader

    with open(log, "rb") as f:
        flights = {
            r.metadata["flight_id"]
            for r in make_reader(f).iter_metadata()
            if r.name == "runtime" and "flight_id" in r.metadata
        }
    if len(flights) != 1:
        verdict.failures.append(f"runtime.flight_id: {sorted(flights) or 'none'}, expected one")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--mission", type=Path, default=MISSION)
    parser.add_argument("--runs", default="flight,kill", help="flight, kill or both (default)")
    parser.add_argument("--kill-dongle", type=int, default=1)
    parser.add_argument(
        "--kill-after",
        type=float,
        default=KILL_AFTER_PLANNING_S,
        help="seconds after the drones start planning (default %(default)s)",
    )
    parser.add_argument("--json", type=Path, default=None, help="write the verdicts here")
    parser.add_argument("--out", type=Path, default=None, help="where the logs go (default: a temporary folder)")
    args = parser.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="rpf-swarm-acceptance-"))
    out.mkdir(parents=True, exist_ok=True)
    mission = args.mission.resolve()
    verdicts = []
    for run in args.runs.split(","):
        verdict = fly(mission, out, None if run == "flight" else args.kill_dongle, args.kill_after)
        verdicts.append(verdict)
        print(json.dumps(asdict(verdict)), flush=True)
    if args.json:
        args.json.write_text(json.dumps([asdict(v) for v in verdicts], indent=1) + "\n")
    print(f"logs: {out}", file=sys.stderr)
    return 0 if all(v.passed for v in verdicts) else 1


if __name__ == "__main__":
    sys.exit(main())
