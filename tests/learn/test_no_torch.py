"""Flight and simulation code run with torch not installed: a subprocess where importing torch fails."""

import subprocess
import sys
import textwrap
from pathlib import Path

import torch  # noqa: F401  (the test itself needs torch only to export a policy)

from rpf_fly.learn.export import export_onnx
from rpf_fly.learn.model import ActorCritic, ModelConfig

ROOT = Path(__file__).resolve().parents[2]

BLOCK_TORCH = textwrap.dedent(
    """
    import importlib.abc, sys
    class NoTorch(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name == "torch" or name.startswith("torch."):
                raise ImportError("torch is not installed (blocked by the test)")
            return None
    sys.meta_path.insert(0, NoTorch())
    """
)


def test_sim_with_onnx_policy_and_runtime_packages_without_torch(tmp_path):
    policy = export_onnx(ActorCritic(ModelConfig()), tmp_path / "rpf.onnx")
    script = BLOCK_TORCH + textwrap.dedent(
        f"""
        import importlib, pkgutil
        import rpf_fly
        for package in ("planning", "sim", "mission", "mocap", "radio", "log", "flight"):
            module = importlib.import_module("rpf_fly." + package)
            for info in pkgutil.walk_packages(module.__path__, module.__name__ + "."):
                importlib.import_module(info.name)
        try:
            import torch
        except ImportError:
            pass
        else:
            raise SystemExit("torch import was not blocked")
        assert "torch" not in sys.modules
        from rpf_fly.cli import main
        sys.argv = ["rpf-fly", "sim", {str(ROOT / "missions" / "circle-8-r3.yaml")!r}, "--planner", "rpf",
                    "--policy", {str(policy)!r}, "--json"]
        main()
        """
    )
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert '"planner": "rpf"' in proc.stdout
