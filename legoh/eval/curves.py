"""Learning curves from a training run's CSV log."""

from __future__ import annotations

import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

PANELS = (  # (column, title)
    ("reward", "mean reward per step"),
    ("progress", "trail progress (fraction)"),
    ("episode_frames", "frames per finished episode"),
    ("reward/tracking_goal_vel", "goal-velocity reward term"),
    ("loss_critic", "critic loss"),
    ("level_mean", "mean terrain level"),
)
STUDENT_PANELS = (  # stage 2: what the student learns from the oracle
    ("reward", "mean reward per step"),
    ("progress", "trail progress (fraction)"),
    ("episode_frames", "frames per finished episode"),
    ("distill/loss_action", "action imitation loss"),
    ("distill/loss_latent", "latent loss (z_uni vs z_tea)"),
    ("distill/loss_near_goals", "near-goal loss"),
)


def read_columns(path: str | Path) -> dict[str, np.ndarray]:
    """A scalar CSV (``legoh.logs.ScalarCSV``) as column -> float array (blank: NaN)."""
    with Path(path).open(newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    return {key: np.array([float(r[key]) if r[key] not in ("", None) else np.nan for r in rows])
            for key in (rows[0].keys() if rows else [])}


def plot_learning_curve(csv_path: str | Path, out: str | Path, title: str = "oracle PPO",
                        panels=PANELS) -> Path:
    """Six panels (``(column, title)``; missing columns stay empty) against iterations;
    returns the PNG path."""
    cols = read_columns(csv_path)
    out = Path(out)
    fig, axes = plt.subplots(2, 3, figsize=(12, 6))
    if cols:
        x = cols["iteration"]
        for ax, (key, name) in zip(axes.ravel(), panels, strict=True):
            if key in cols:
                ax.plot(x, cols[key], lw=1.2)
            ax.set_title(name, fontsize=10)
            ax.set_xlabel("iteration")
            ax.grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return out
