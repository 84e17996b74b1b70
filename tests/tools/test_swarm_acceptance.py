"""The swarm acceptance tool's smoke test (tools/swarm_acceptance.py, docs/distributed.md): the kill run on the tests'
4-drone, 2-dongle mission, flown through the CLI and judged exactly as the 40-drone runs are (its own reader of the
log, the /truth topics, the dongles' loads, the review), so the command cannot rot between runs; and its judge can
fail."""

from __future__ import annotations

from tool_modules import ROOT, load_tool


def test_a_killed_worker_on_the_two_dongle_mission_passes_the_judge(tmp_path):
    tool = load_tool("swarm_acceptance")
    verdict = tool.fly(ROOT / "tests" / "runtime" / "two-dongles.yaml", tmp_path, kill_dongle=1, kill_after_s=0.5)
    assert verdict.passed, verdict.failures
    assert verdict.exit_code == 1 and verdict.reached == 2  # cf1, cf2; dongle 1's cf3, cf4 were killed
    assert verdict.noticed_after_s is not None and verdict.noticed_after_s < 1.0
    assert set(verdict.radio_peak_per_s) == {"0", "1"}
    assert verdict.min_separation_m is not None and verdict.min_separation_m > 0.13


def test_the_judge_counts_contact_with_a_dead_workers_drones_and_ignores_theirs_among_themselves():
    tool = load_tool("swarm_acceptance")

    def sample(x: float, z: float, motors: bool) -> tuple[int, dict]:
        return 0, {"position": {"x": x, "y": 0.0, "z": z}, "motors": motors, "crashed": False}

    truth = {"cf1": [sample(0.0, 1.0, True)], "cf3": [sample(0.1, 0.95, False)], "cf4": [sample(0.15, 0.4, False)]}
    assert tool._min_separation(truth, dead={"cf3", "cf4"}) < tool.CONTACT_M  # noqa: SLF001 - a falling drone
    apart = {"cf1": [sample(0.0, 1.0, True)], "cf3": [sample(2.0, 0.5, False)], "cf4": [sample(2.05, 0.4, False)]}
    assert tool._min_separation(apart, dead={"cf3", "cf4"}) > 1.9  # noqa: SLF001 - the dead pair is not judged
