"""An install that is not editable (a wheel: ``pip install .`` or from git) has no ``policies/`` beside the
package: the shipped policies travel as data files to ``<prefix>/share/rpf_fly/policies`` and the mission loader
finds them there, so the default planner (RPF-3) loads without a checkout."""

from __future__ import annotations

import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10: pip's own TOML reader (pip is in every venv this project installs into)
    from pip._vendor import tomli as tomllib  # type: ignore[no-redef]

from rpf_fly.mission.model import POLICY_KINDS
from rpf_fly.mission.policy_paths import INSTALLED_POLICIES, PROJECT_POLICIES

ROOT = Path(__file__).resolve().parents[2]


def test_the_wheel_ships_every_policy_a_kind_defaults_to_where_the_loader_looks():
    """pyproject's data files put ``policies/*.onnx`` and the model cards in ``share/rpf_fly/policies``, the
    folder the loader searches under the install prefix."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    data_files = config["tool"]["setuptools"]["data-files"]
    globs = data_files[INSTALLED_POLICIES.as_posix()]
    shipped = {p.name for pattern in globs for p in ROOT.glob(pattern)}
    for kind in POLICY_KINDS:
        assert f"{kind}.onnx" in shipped and f"{kind}.yaml" in shipped, kind


def test_a_wheel_layout_without_a_checkout_loads_the_default_planner(tmp_path):
    """The package and the data files laid out as pip installs a wheel into a prefix, imported without the
    editable install (``python -S``, the prefix's site-packages first): a mission naming no planner loads RPF-3's
    policy from ``<prefix>/share/rpf_fly/policies``, and one naming ``../policies/rpf3.onnx`` (lab-3 copied out of
    the checkout's ``missions/``) finds the shipped one there by file name."""
    prefix = tmp_path / "prefix"
    site = prefix / Path(sysconfig.get_path("purelib")).relative_to(sysconfig.get_path("data"))
    shutil.copytree(ROOT / "rpf_fly", site / "rpf_fly", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(PROJECT_POLICIES, prefix / INSTALLED_POLICIES, ignore=shutil.ignore_patterns("*.png", "*.csv"))
    mission = tmp_path / "flights" / "m.yaml"
    mission.parent.mkdir()
    mission.write_text(
        "name: m\narena: {x: [-2, 2], y: [-2, 2], z: [0, 2]}\n"
        "drones:\n  - {name: cf1, uri: 'radio://0/80/2M/E7E7E7E701', start: [0, 0], goal: [1, 0]}\n"
    )
    copied = tmp_path / "flights" / "copied.yaml"
    copied.write_text((ROOT / "missions" / "lab-3.yaml").read_text())
    script = (
        "import sys; from rpf_fly.mission import load_mission; import rpf_fly\n"
        "print(rpf_fly.__file__)\n"
        f"print(load_mission({str(mission)!r}).planner.policy)\n"
        f"print(load_mission({str(copied)!r}).planner.policy)\n"
    )
    venv_site = sysconfig.get_path("purelib")
    done = subprocess.run(
        [sys.executable, "-S", "-c", script],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={"PYTHONPATH": f"{site}:{venv_site}", "PATH": "/usr/bin:/bin"},
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    package, default_policy, copied_policy = done.stdout.split()
    assert Path(package).is_relative_to(site)
    assert Path(default_policy) == (prefix / INSTALLED_POLICIES / "rpf3.onnx").resolve()
    assert Path(copied_policy) == (prefix / INSTALLED_POLICIES / "rpf3.onnx").resolve()
