"""Learning curves from a training run's CSV log (``train.csv``, ``legoh.logs.ScalarCSV``).

The panels follow what the run logged, so they match its reward preset and stage: the total
reward, its terms (``reward/<name>``: bonuses and penalties apart), trail progress, episode
length in seconds, how episodes ended, the terrain level (per category when logged), the
randomisation strength, and the losses; a panel whose columns are missing or empty is left
out. The x axis is frames (millions); a top axis gives the wall-clock minutes the
``frames_per_s`` column implies.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import NamedTuple

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

COLUMNS = 3  # panels per row
SECONDS_PER_MINUTE = 60.0


class Panel(NamedTuple):
    """One plot: a title and its lines as (CSV column, legend label)."""

    title: str
    lines: list[tuple[str, str]]


def read_columns(path: str | Path) -> dict[str, np.ndarray]:
    """A scalar CSV (``legoh.logs.ScalarCSV``) as column -> float array (blank: NaN)."""
    with Path(path).open(newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    return {key: np.array([float(r[key]) if r[key] not in ("", None) else np.nan for r in rows])
            for key in (rows[0].keys() if rows else [])}


def _logged(cols: dict[str, np.ndarray], key: str) -> bool:
    return key in cols and bool(np.isfinite(cols[key]).any())


def learning_panels(cols: dict[str, np.ndarray], dt: float | None = None) -> list[Panel]:
    """The panels a run's columns ``cols`` fill, in reading order; ``dt`` (s, the policy
    period) turns episode steps into seconds. Every panel has at least one logged line."""
    terms = sorted(k for k in cols if k.startswith("reward/") and k.count("/") == 1
                   and _logged(cols, k))  # reward/<term>/<category>: per-category columns
    bonuses = [k for k in terms if np.nanmean(cols[k]) >= 0]
    penalties = [k for k in terms if k not in bonuses]
    length = (f"episode length ({'s' if dt else 'policy steps'})",
              [("episode_frames", "ended episodes")])
    levels = [("level_mean", "all")] + [(k, k.split("/", 1)[1]) for k in sorted(cols)
                                        if k.startswith("level/")]
    losses = [(k, k.split("/", 1)[-1]) for k in sorted(cols) if k.startswith("distill/loss_")]
    candidates = [
        Panel("reward per step (x dt)", [("reward", "total")]),
        Panel("reward terms: bonuses", [(k, k.split("/", 1)[1]) for k in bonuses]),
        Panel("reward terms: penalties", [(k, k.split("/", 1)[1]) for k in penalties]),
        Panel("trail progress (fraction of the path)", [("progress", "mean")]),
        Panel(*length),
        Panel("episode ends (share of ended episodes)",
              [("fell_frac", "fell"), ("reached_frac", "reached")]),
        Panel("terrain level", levels),
        Panel("randomisation", [("randomization", "strength"),
                                ("gate_survival", "gate: share not fallen")]),
        Panel("critic loss", [("loss_critic", "value")]),
        Panel("imitation losses", losses),
    ]
    return [Panel(p.title, [(k, label) for k, label in p.lines if _logged(cols, k)])
            for p in candidates if any(_logged(cols, k) for k, _ in p.lines)]


def minutes_at(cols: dict[str, np.ndarray], frames: np.ndarray) -> np.ndarray | None:
    """Wall-clock minutes at the end of each iteration, from ``frames_per_s``; None when
    the column is missing or not positive throughout."""
    rate = cols.get("frames_per_s")
    if rate is None or len(frames) < 2 or not (np.isfinite(rate) & (rate > 0)).all():
        return None
    per_iteration = np.diff(frames, prepend=0.0)
    return np.cumsum(per_iteration / rate) / SECONDS_PER_MINUTE


def plot_learning_curve(csv_path: str | Path, out: str | Path, title: str = "oracle PPO",
                        frames_per_iteration: int | None = None,
                        dt: float | None = None) -> Path:
    """The panels of :func:`learning_panels` for the CSV at ``csv_path``; returns the PNG.

    ``frames_per_iteration`` (env steps per iteration: ``algo.num_envs x
    algo.steps_per_env``) puts frames on the x axis (else iterations, and no minutes);
    ``dt`` (s, policy period) gives episode lengths in seconds.
    """
    cols, out = read_columns(csv_path), Path(out)
    panels = learning_panels(cols, dt) if cols else []
    rows = max(1, math.ceil(len(panels) / COLUMNS))
    fig, axes = plt.subplots(rows, COLUMNS, figsize=(4 * COLUMNS, 3.2 * rows), squeeze=False)
    if panels:
        it = cols["iteration"]
        frames = it * frames_per_iteration if frames_per_iteration else None
        x = frames / 1e6 if frames is not None else it
        minutes = minutes_at(cols, frames) if frames is not None else None
        for ax, panel in zip(axes.ravel(), panels, strict=False):
            for key, label in panel.lines:
                y = cols[key] * dt if key == "episode_frames" and dt else cols[key]
                ax.plot(x, y, lw=1.2, label=label)
            ax.set_title(panel.title, fontsize=10)
            ax.set_xlabel("frames (M)" if frames is not None else "iteration", fontsize=9)
            ax.grid(alpha=0.3)
            if len(panel.lines) > 1:
                ax.legend(fontsize=7, ncol=2 if len(panel.lines) > 4 else 1)
            if minutes is not None:
                top = ax.secondary_xaxis("top", functions=(
                    lambda v, m=minutes: np.interp(v, x, m),
                    lambda v, m=minutes: np.interp(v, m, x)))
                top.set_xlabel("minutes", fontsize=8)
                top.tick_params(labelsize=7)
    for ax in axes.ravel()[len(panels):]:
        ax.set_visible(False)  # no empty panel
    fig.suptitle(title)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return out
