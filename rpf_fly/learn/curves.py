"""Training curves: the CSV the trainer writes, drawn as a PNG (return, success, approx-KL, gains)."""

from __future__ import annotations

import csv
from pathlib import Path


def plot_curves(csv_path: str | Path, png_path: str | Path, title: str = "") -> Path:
    """Draw ``training_curve.csv`` into a 2 x 2 figure; returns the PNG path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with Path(csv_path).open() as f:
        rows = list(csv.DictReader(f))
    x = [int(r["episodes"]) for r in rows]

    def col(name: str) -> list[float]:
        return [float(r[name]) for r in rows]

    fig, axes = plt.subplots(2, 2, figsize=(10, 7), dpi=110)
    axes[0, 0].plot(x, col("mean_return"))
    axes[0, 0].set_ylabel("mean robot return (last 200 episodes)")
    axes[0, 1].plot(x, col("success_rate"), label="all")
    axes[0, 1].plot(x, col("success_rate_a"), label="arena A", alpha=0.7)
    axes[0, 1].plot(x, col("success_rate_b"), label="arena B", alpha=0.7)
    validated = [
        (xi, float(r["eval_success"])) for xi, r in zip(x, rows) if r.get("eval_success") not in (None, "", "nan")
    ]
    validated = [(xi, v) for xi, v in validated if v == v]
    if validated:
        axes[0, 1].plot(*zip(*validated), "ko", ms=3, label="validation (deterministic)")
    axes[0, 1].set_ylabel("episode success (last 200; early values favour short episodes)")
    axes[0, 1].set_ylim(-0.02, 1.02)
    axes[0, 1].legend(fontsize=8)
    axes[1, 0].plot(x, col("approx_kl"), label="approx KL")
    axes[1, 0].plot(x, col("clip_fraction"), label="clip fraction")
    axes[1, 0].set_yscale("log")
    axes[1, 0].legend(fontsize=8)
    eta, lam = col("eta_mean"), col("lam_mean")
    if any(v == v for v in eta):  # not all NaN: a gains policy
        ax = axes[1, 1]
        ax.plot(x, eta, color="tab:blue", label="eta")
        ax.set_ylabel("mean eta", color="tab:blue")
        ax2 = ax.twinx()
        ax2.plot(x, lam, color="tab:orange", label="lambda")
        ax2.set_ylabel("mean lambda", color="tab:orange")
    else:
        axes[1, 1].plot(x, col("explained_variance"))
        axes[1, 1].set_ylabel("explained variance")
    for ax in axes.flat:
        ax.set_xlabel("arena episodes")
        ax.grid(True, lw=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    png_path = Path(png_path)
    fig.savefig(png_path)
    plt.close(fig)
    return png_path
