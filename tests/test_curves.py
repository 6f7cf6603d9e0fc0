"""Learning curves (``legoh.eval.curves``): panels follow the logged columns, frames and
minutes on the x axes, episode lengths in seconds."""

import csv
from pathlib import Path

import numpy as np
import pytest

from legoh.eval.curves import learning_panels, minutes_at, plot_learning_curve, read_columns

DT = 0.02  # s, policy period


def write_csv(path: Path, columns: dict[str, list[float]]) -> Path:
    with path.open("w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(columns)
        writer.writerows(zip(*columns.values(), strict=True))
    return path


@pytest.fixture
def walk_run(tmp_path: Path) -> Path:
    """Three iterations of an oracle run with the walk preset and the randomisation gate."""
    return write_csv(tmp_path / "train.csv", {
        "iteration": [1, 2, 3], "frames_per_s": [1000.0, 500.0, 1000.0],
        "reward": [0.01, 0.02, 0.03], "reward/alive": [0.003] * 3,
        "reward/tracking_lin_vel": [0.01, 0.02, 0.03],
        "reward/orientation": [-0.001, -0.002, -0.001], "progress": [0.0, 0.1, 0.2],
        "episode_frames": [float("nan"), 100.0, 250.0], "fell_frac": [0.0, 1.0, 0.5],
        "reached_frac": [0.0, 0.0, 0.1], "level_mean": [0.0, 0.0, 0.5],
        "randomization": [0.0, 0.1, 0.2], "gate_survival": [float("nan"), 0.9, 0.8],
        "loss_critic": [0.1, 0.05, 0.02],
    })


def test_panels_follow_the_logged_columns(walk_run: Path) -> None:
    panels = {p.title: [k for k, _ in p.lines]
              for p in learning_panels(read_columns(walk_run), DT)}
    assert panels["reward terms: bonuses"] == ["reward/alive", "reward/tracking_lin_vel"]
    assert panels["reward terms: penalties"] == ["reward/orientation"]
    assert panels["episode length (s)"] == ["episode_frames"]
    assert panels["randomisation"] == ["randomization", "gate_survival"]
    assert "imitation losses" not in panels  # an oracle run: no distillation columns
    assert all(lines for lines in panels.values())  # no empty panel
    # the goal-velocity term is not in the walk preset: no panel asks for it
    assert not any("tracking_goal_vel" in k for lines in panels.values() for k in lines)


def test_minutes_from_frames_per_second(walk_run: Path) -> None:
    frames = np.array([1.0, 2.0, 3.0]) * 6000  # 6000 frames an iteration
    minutes = minutes_at(read_columns(walk_run), frames)
    np.testing.assert_allclose(minutes, np.array([6.0, 18.0, 24.0]) / 60.0)


def test_plot_writes_a_png(walk_run: Path, tmp_path: Path) -> None:
    out = plot_learning_curve(walk_run, tmp_path / "curve.png", frames_per_iteration=6000,
                              dt=DT)
    assert out.stat().st_size > 0
