"""Flying one faulted run and keeping what it left: the flight's process as a lab would start it (``rpf-fly fly
MISSION --dry-run --faults F``, or ``--lab`` against an ``rpf-fly lab`` of its own), its output, exit and logs.

Nothing here judges: the record is all the judge (`rpf_fly.campaign.judge`) reads, so a made-up record can be
judged as a flown one is. The logs are read with the mcap library alone, not with `rpf_fly.log`: the verdict must
not trust the stack it judges.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.reader import make_reader

from rpf_fly.campaign.schedules import schedule_of
from rpf_fly.mission import load_mission
from rpf_fly.mission.model import Mission

Topics = dict[str, list[tuple[int, dict]]]
"""A log's messages: topic -> [(log time ns, message)]."""

START_S = 60.0
"""Connecting, the preflight and the take-off come before the flight's timeout starts."""
EXIT_EXTRA_S = 10.0
"""A flight exits by itself within its timeout plus this, after `START_S`."""
LAB_AFTER_S = 6.0
"""The lab runs on this long after the fault before it is stopped (its log then covers the judgement)."""
LAB_START_S = 60.0
"""A lab that has not written its lab file by then did not start."""


@dataclass
class FlightRecord:
    """What one faulted flight left, for the judge: the mission and its faults, the process's exit (None: it did
    not exit within ``limit_s`` and was killed), its output, its log's messages and whether the log reviews."""

    mission: Mission
    faults: list[dict[str, Any]]
    exit_code: int | None = None
    limit_s: float = 0.0
    seconds: float = 0.0
    stdout: str = ""
    stderr: str = ""
    topics: Topics = field(default_factory=dict)
    log_error: str | None = None
    """The flight's log could not be read (then ``topics`` is empty)."""
    review_error: str | None = None
    """``rpf-fly review LOG --json`` failed on the flight's log: the end of its stderr."""


@dataclass
class LabRecord(FlightRecord):
    """A flight against a lab of its own: the lab's log (its ``/truth`` outlives the flight's process), what went
    wrong with the lab itself, and when the fault struck (a kill's stderr line, read as it came) and the flight's
    process ended (both ns since the Unix epoch). ``topics`` is the flight's own log, read only for an unplug (a
    killed flight's log is cut where the kill found it)."""

    lab_started: bool = True
    """False: the lab never wrote its lab file, so nothing flew."""
    lab_topics: Topics = field(default_factory=dict)
    lab_log_error: str | None = None
    """The lab's log could not be read (then ``lab_topics`` is empty)."""
    lab_problems: list[str] = field(default_factory=list)
    struck_ns: int | None = None
    exited_ns: int | None = None


def read_log(path: Path) -> Topics:
    """Every message of the MCAP log at ``path``, by topic, with the mcap library alone."""
    topics: Topics = {}
    with open(path, "rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages():
            topics.setdefault(channel.topic, []).append((message.log_time, json.loads(message.data)))
    return topics


def _rpf_fly(*args: str) -> list[str]:
    return [sys.executable, "-m", "rpf_fly", *args]


def _review(log: Path, workdir: Path) -> str | None:
    """None when ``rpf-fly review LOG --json`` reads the log, else the end of its stderr."""
    done = subprocess.run(
        _rpf_fly("review", str(log), "--json"), capture_output=True, text=True, timeout=120, cwd=workdir
    )
    return None if done.returncode == 0 else (done.stderr.strip()[-200:] or f"exit {done.returncode}")


def _keep_output(path: Path, stdout: str, stderr: str) -> None:
    """The flight's standard output and error beside its log (``--keep DIR`` keeps them): a traceback the judge
    fails a run for is read there."""
    path.write_text(f"--- stdout\n{stdout}--- stderr\n{stderr}")


def _stem(mission: Mission, faults: list[dict[str, Any]], tag: str) -> str:
    return f"{mission.name}-{'+'.join(f['kind'] for f in faults)}{tag}"


def fly_dry_run(mission_path: Path, faults: list[dict[str, Any]], workdir: Path, tag: str = "") -> FlightRecord:
    """Fly ``mission_path`` on simulated drones with the schedule ``faults`` in a process of its own, in
    ``workdir`` (the schedule and the log stay there), and record what it left."""
    mission = load_mission(mission_path)
    stem = _stem(mission, faults, tag)
    schedule_file, log = workdir / f"{stem}.yaml", workdir / f"{stem}.mcap"
    schedule_file.write_text(schedule_of(faults))
    record = FlightRecord(mission, faults, limit_s=mission.flight.timeout_s + START_S + EXIT_EXTRA_S)
    started = time.monotonic()
    try:
        done = subprocess.run(
            _rpf_fly(
                "fly", str(mission_path), "--dry-run", "--faults", str(schedule_file), "--no-console", "--log", str(log)
            ),
            capture_output=True,
            text=True,
            timeout=record.limit_s,
            cwd=workdir,
        )
    except subprocess.TimeoutExpired:
        record.seconds = time.monotonic() - started
        return record
    record.seconds = time.monotonic() - started
    record.exit_code, record.stdout, record.stderr = done.returncode, done.stdout, done.stderr
    _keep_output(workdir / f"{stem}.out", done.stdout, done.stderr)
    try:
        record.topics = read_log(log)
    except Exception as err:  # noqa: BLE001 - an unreadable log is the judge's to fail, not a crash of the campaign
        record.log_error = str(err) or type(err).__name__
        return record
    record.review_error = _review(log, workdir)
    return record


def fly_against_lab(mission_path: Path, fault: dict[str, Any], workdir: Path, tag: str = "") -> LabRecord:
    """Start ``rpf-fly lab MISSION`` with a lab file of its own, fly ``rpf-fly fly MISSION --lab --faults F``
    against it with the one lab-kind ``fault``, stop the lab (SIGTERM) `LAB_AFTER_S` after the fault, and record
    both logs."""
    mission = load_mission(mission_path)
    kind = fault["kind"]
    label = "-".join(str(v) for k, v in fault.items() if k != "kind")
    stem = _stem(mission, [fault], f"-{label}{tag}")
    schedule_file, log, lab_log = workdir / f"{stem}.yaml", workdir / f"{stem}.mcap", workdir / f"{stem}.lab.mcap"
    schedule_file.write_text(schedule_of([fault]))
    lab_file = workdir / f"{stem}.lab.json"
    env = dict(os.environ, PYTHONUNBUFFERED="1", RPF_FLY_LAB=str(lab_file))
    record = LabRecord(mission, [fault], limit_s=mission.flight.timeout_s + START_S + EXIT_EXTRA_S)
    started = time.monotonic()
    flown = None
    with open(workdir / f"{stem}.lab.out", "w+") as lab_out:
        lab = subprocess.Popen(
            _rpf_fly("lab", str(mission_path), "--log", str(lab_log)),
            stdout=lab_out,
            stderr=subprocess.STDOUT,
            text=True,
            env=env,
            cwd=workdir,
        )
        try:
            deadline = time.monotonic() + LAB_START_S
            while not lab_file.exists() and lab.poll() is None and time.monotonic() < deadline:
                time.sleep(0.05)
            if not lab_file.exists():
                record.lab_started = False
                return record
            flown = _fly(mission_path, schedule_file, log, env, workdir, record.limit_s, kind)
        finally:
            lab.send_signal(signal.SIGTERM)
            try:
                lab.wait(timeout=60)
            except subprocess.TimeoutExpired:
                lab.kill()
                record.lab_problems.append("the lab did not stop on SIGTERM")
        lab_out.seek(0)
        if "Traceback" in lab_out.read():
            record.lab_problems.append("traceback in the lab's output")
    record.seconds = time.monotonic() - started
    if flown is None:
        return record
    record.exit_code, record.stdout, record.stderr, record.struck_ns, record.exited_ns = flown
    _keep_output(workdir / f"{stem}.out", record.stdout, record.stderr)
    try:
        record.lab_topics = read_log(lab_log)
    except Exception as err:  # noqa: BLE001 - the judge's to fail
        record.lab_log_error = str(err) or type(err).__name__
        return record
    record.review_error = _review(log, workdir)
    if kind != "ground_station_kill":
        try:
            record.topics = read_log(log)
        except Exception as err:  # noqa: BLE001
            record.log_error = str(err) or type(err).__name__
    return record


def _fly(
    mission_path: Path, schedule_file: Path, log: Path, env: dict[str, str], workdir: Path, limit: float, kind: str
) -> tuple[int, str, str, int | None, int] | None:
    """``rpf-fly fly --lab --faults`` in a process of its own: (exit code, stdout, stderr, when the fault's line came
    on stderr, when the process ended), or None when it outlived ``limit``. A kill's moment is the stderr line the
    injection writes just before it; an unplug's flight lives on and returns when it ends. Returns `LAB_AFTER_S`
    after the fault at the earliest, so the lab's log covers that much of the drones without their ground station."""
    flight = subprocess.Popen(
        _rpf_fly("fly", str(mission_path), "--lab", "--faults", str(schedule_file), "--no-console", "--log", str(log)),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=workdir,
    )
    lines: list[tuple[int, str]] = []
    out: list[str] = []
    stderr, stdout = flight.stderr, flight.stdout
    assert stderr is not None and stdout is not None  # both PIPE above

    def read_stderr() -> None:
        for line in stderr:
            lines.append((time.time_ns(), line))

    def read_stdout() -> None:
        out.append(stdout.read())

    readers = [threading.Thread(target=read_stderr, daemon=True), threading.Thread(target=read_stdout, daemon=True)]
    for reader in readers:
        reader.start()
    try:
        code = flight.wait(timeout=limit)
    except subprocess.TimeoutExpired:
        flight.kill()
        flight.wait()
        return None
    exited_ns = time.time_ns()
    for reader in readers:
        reader.join(timeout=10)
    struck = next((t for t, line in lines if f"injected {kind}" in line), None)
    if kind == "ground_station_kill" or struck is not None:
        time.sleep(max(0.0, ((struck or exited_ns) + LAB_AFTER_S * 1e9 - time.time_ns()) / 1e9))
    return code, "".join(out), "".join(line for _, line in lines), struck, exited_ns
