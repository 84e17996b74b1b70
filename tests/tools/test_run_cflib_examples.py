"""Smoke test of tools/run_cflib_examples.py on example-shaped programs written here (no network, no cflib example
code): the URI injected through ``CFLIB_URI`` or rewritten in a copy, cflib's own ``init_drivers()`` keeping the
fake driver, and each kind of result (ok, failed with its first error line, timeout, ran until timeout, excluded)."""

from __future__ import annotations

import importlib.util
import json
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def load_runner():  # type: ignore[no-untyped-def]
    spec = importlib.util.spec_from_file_location("run_cflib_examples", ROOT / "tools" / "run_cflib_examples.py")
    module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    sys.modules["run_cflib_examples"] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)  # type: ignore[union-attr]
    return module


FLY_FROM_ENV = """
import sys, time
import cflib.crtp
from cflib.crazyflie import Crazyflie
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie
from cflib.utils import uri_helper

uri = uri_helper.uri_from_env(default='radio://0/80/2M/E7E7E7E7E7')

if __name__ == '__main__':
    cflib.crtp.init_drivers()
    with SyncCrazyflie(uri, cf=Crazyflie(rw_cache='./cache')) as scf:
        scf.cf.high_level_commander.takeoff(0.3, 0.5)
        time.sleep(0.7)
        print('estimator', scf.cf.param.get_value('stabilizer.estimator'), 'uri', uri)
        scf.cf.high_level_commander.land(0.0, 0.5)
        time.sleep(0.6)
"""

HARDCODED_SWARM = """
import sys

import cflib.crtp
from cflib.crazyflie.swarm import CachedCfFactory, Swarm

uris = ['radio://0/80/2M/E7E7E7E701', 'radio://0/80/2M/E7E7E7E702']

if __name__ == '__main__':
    cflib.crtp.init_drivers()
    with Swarm(uris, factory=CachedCfFactory(rw_cache='./cache')) as swarm:
        # one write a line: print() from the swarm's threads writes its parts apart, and they interleave
        swarm.parallel_safe(lambda scf: sys.stdout.write(f"{scf.cf.link_uri} {scf.cf.param.get_value('cpu.flash')}\\n"))
"""

MISSING_LOG_VARIABLE = """
import cflib.crtp
from cflib.crazyflie import Crazyflie
from cflib.crazyflie.log import LogConfig
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie
from cflib.utils import uri_helper

if __name__ == '__main__':
    cflib.crtp.init_drivers()
    config = LogConfig(name='x', period_in_ms=100)
    config.add_variable('nosuch.variable', 'float')
    with SyncCrazyflie(uri_helper.uri_from_env(), cf=Crazyflie(rw_cache='./cache')) as scf:
        scf.cf.log.add_config(config)
"""

CUT_IN_FLIGHT = """
import time
import cflib.crtp
from cflib.crazyflie import Crazyflie
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie
from cflib.utils import uri_helper

if __name__ == '__main__':
    cflib.crtp.init_drivers()
    with SyncCrazyflie(uri_helper.uri_from_env(), cf=Crazyflie(rw_cache='./cache')) as scf:
        scf.cf.high_level_commander.takeoff(0.4, 0.5)
        time.sleep(0.8)
        scf.cf.commander.send_stop_setpoint()  # motors off in the air: it falls and locks 2 s later
        time.sleep(2.3)
"""

FOREVER = """
import time
while True:
    time.sleep(0.1)
"""


def write(folder: Path, name: str, source: str) -> Path:
    path = folder / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(textwrap.dedent(source))
    return path


def test_the_runner_runs_example_shaped_programs_against_fake(tmp_path: Path) -> None:
    runner = load_runner()
    examples = tmp_path / "examples"
    env_example = write(examples, "mine/fly_from_env.py", FLY_FROM_ENV)
    write(examples, "mine/hardcoded_swarm.py", HARDCODED_SWARM)
    write(examples, "mine/missing_log_variable.py", MISSING_LOG_VARIABLE)
    write(examples, "mine/cut_in_flight.py", CUT_IN_FLIGHT)
    before = env_example.read_text()
    report = tmp_path / "results.json"
    outputs = tmp_path / "outputs"
    code = runner.main(
        ["--examples", str(examples), "--json", str(report), "--output-dir", str(outputs), "--timeout", "60"]
    )
    results = {r["name"]: r for r in json.loads(report.read_text())}
    assert results["mine/fly_from_env.py"]["result"] == "ok", results
    assert results["mine/hardcoded_swarm.py"]["result"] == "ok", results
    failed = results["mine/missing_log_variable.py"]
    assert failed["result"] == "failed" and "KeyError" in failed["detail"] and "nosuch.variable" in failed["detail"]
    assert code == 1  # a failure makes the command fail
    # what the drones did, from the fake world's truth: an example that exits cleanly but drops its drone fails
    assert results["mine/fly_from_env.py"]["flight"].startswith("1 drone: up to 0.30 m")
    assert results["mine/fly_from_env.py"]["flight"].endswith("landed")
    assert results["mine/hardcoded_swarm.py"]["flight"] == "2 drones: did not fly"
    cut = results["mine/cut_in_flight.py"]
    assert cut["result"] == "failed" and cut["detail"] == "E7E7E7E7E7 ended locked", cut
    # the URI came from CFLIB_URI, the file itself untouched; the hard-coded one was rewritten to fake:// in a copy
    assert "uri fake://0/80/2M/E7E7E7E7E7" in (outputs / "mine_fly_from_env.py.txt").read_text()
    assert env_example.read_text() == before
    swarm_output = (outputs / "mine_hardcoded_swarm.py.txt").read_text()
    assert "fake://0/80/2M/E7E7E7E701 1024" in swarm_output and "fake://0/80/2M/E7E7E7E702 1024" in swarm_output
    assert "radio://" in (examples / "mine/hardcoded_swarm.py").read_text()


def test_timeouts_exclusions_and_error_lines(tmp_path: Path) -> None:
    runner = load_runner()
    examples = tmp_path / "examples"
    write(examples, "forever.py", FOREVER)
    server = runner.ExampleSpec("forever.py", timeout_s=1.5, runs_until_stopped=True)
    assert runner.run_one(server, examples).result == "ran until timeout"
    stuck = runner.run_one(runner.ExampleSpec("forever.py", timeout_s=1.5), examples)
    assert stuck.result == "timeout" and 1.5 <= stuck.seconds < 10
    excluded = runner.plan(["step-by-step/sbs_motion_commander.py", "logging/basiclog.py", "other/new.py"])
    assert [s.excluded != "" for s in excluded] == [False, True, False]
    assert "Flow deck" in excluded[1].excluded and "not in the list" in excluded[2].note
    traceback = 'noise\nTraceback (most recent call last):\n  File "x.py", line 1\n    boom()\nNameError: boom\nrest'
    assert runner.first_error_line(traceback) == "NameError: boom"
    assert runner.first_error_line("a\nlast words\n\n") == "last words"
