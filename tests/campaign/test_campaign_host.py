"""A campaign run whose host fell behind its simulated world is no evidence either way (rpf_fly/campaign/runner.py
`fly_and_judge`): it is flown again until the host keeps up, the verdict says how many times it flew, and a run whose
host fell behind on every try fails as no evidence. The flights are made-up records: nothing flies."""

from __future__ import annotations

from pathlib import Path

from rpf_fly.campaign import runner
from rpf_fly.campaign.flights import FlightRecord, LabRecord
from rpf_fly.campaign.judge import Verdict
from rpf_fly.mission import load_mission

ROOT = Path(__file__).resolve().parents[2]
LAB_3 = ROOT / "missions" / "lab-3.yaml"
BEHIND = (
    "the host could not keep up for 0.4 s (simulated steps, mocap frames or radio transactions more than 50 ms "
    "late): this dry run is not evidence"
)


def record(behind: bool, lab: bool = False) -> FlightRecord:
    events = {"/events": [(1, {"level": 3, "file": "host", "message": BEHIND if behind else "swarm: flying"})]}
    if lab:
        return LabRecord(load_mission(LAB_3), [], exit_code=0, lab_topics=events)
    return FlightRecord(load_mission(LAB_3), [], exit_code=0, topics=events)


def stub(monkeypatch, behind: list[bool], lab: bool = False) -> list[FlightRecord]:
    flown: list[FlightRecord] = []

    def fly(*_args, **_kw) -> FlightRecord:
        flown.append(record(behind[len(flown)], lab))
        return flown[-1]

    def judge(rec: FlightRecord) -> Verdict:
        return Verdict("gust", rec.mission.name, "cf2", passed=True)

    monkeypatch.setattr(runner, "HOST_RETRY_WAIT_S", 0.0)
    monkeypatch.setattr(runner, "HOST_RETRY_MIN_WAIT_S", 0.0)
    monkeypatch.setattr(runner, "fly_dry_run", fly)
    monkeypatch.setattr(runner, "fly_against_lab", fly)
    monkeypatch.setattr(runner, "judge_flight", judge)
    monkeypatch.setattr(runner, "judge_lab", judge)
    return flown


def test_a_run_whose_host_kept_up_flies_once(monkeypatch, tmp_path):
    flown = stub(monkeypatch, [False])
    verdict = runner.fly_and_judge([], LAB_3, tmp_path)
    assert len(flown) == 1 and verdict.passed and verdict.events == []


def test_a_run_whose_host_fell_behind_is_flown_again_and_says_so(monkeypatch, tmp_path):
    flown = stub(monkeypatch, [True, True, False])
    verdict = runner.fly_and_judge([], LAB_3, tmp_path)
    assert len(flown) == 3 and verdict.passed
    assert verdict.events == ["campaign: flown 3 times, the host fell behind on the first 2"]
    lab = stub(monkeypatch, [True, False], lab=True)  # a lab's world falling behind counts the same
    assert runner.fly_and_judge_lab({"kind": "dongle_unplug"}, LAB_3, tmp_path).passed and len(lab) == 2


def test_a_run_whose_host_fell_behind_every_time_fails_as_no_evidence(monkeypatch, tmp_path):
    flown = stub(monkeypatch, [True] * runner.HOST_TRIES)
    verdict = runner.fly_and_judge([], LAB_3, tmp_path)
    assert len(flown) == runner.HOST_TRIES and not verdict.passed
    assert verdict.failures == [
        f"the host fell behind on each of {runner.HOST_TRIES} tries: not evidence, fly it again"
    ]
    # a killed flight leaves no log of its own: its output's line counts
    assert runner.host_fell_behind(FlightRecord(load_mission(LAB_3), [], stderr=f"[host] {BEHIND}\n"))
