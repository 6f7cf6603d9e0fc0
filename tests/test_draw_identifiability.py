"""The history windows and the held-out R^2 of experiments/draw_identifiability.py."""

import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "experiments"))
from draw_identifiability import held_out, held_out_r2, windows  # noqa: E402


def rollout(steps: int = 40, robots: int = 8, seed: int = 0) -> dict:
    """Robot r steps draw r throughout; its proprio is the draw plus noise; robot 0 restarts
    at step 10."""
    rng = np.random.default_rng(seed)
    draws = np.repeat(rng.normal(size=(1, robots, 6)), steps, 0).astype(np.float32)
    proprio = np.concatenate([draws, rng.normal(size=(steps, robots, 2))], -1)
    starts = np.zeros((steps, robots), bool)
    starts[0] = True
    starts[10, 0] = True
    ids = np.repeat(np.arange(robots)[None], steps, 0)
    return {"proprio": proprio.astype(np.float32), "draws": draws, "starts": starts,
            "ids": ids}


def test_windows_stay_inside_one_episode() -> None:
    data = rollout()
    x, y, k = windows(data, 5)
    # robot 0: steps 4..9 end windows of its first episode, 14..39 of its second; others 36
    assert len(x) == 6 + 26 + 7 * 36 and x.shape[1] == 5 * 8
    assert np.array_equal(y[:32], data["draws"][np.r_[4:10, 14:40], 0])
    assert np.array_equal(x[0], data["proprio"][0:5, 0].reshape(-1))
    assert np.array_equal(np.unique(k[held_out(k)]), [0, 4])


def test_r2_reads_unseen_draws_the_proprio_carries() -> None:
    data = rollout(robots=32)
    r2 = held_out_r2(data, 1, iters=300)
    assert len(r2) == 6 and min(r2) > 0.8
    data["proprio"][..., :6] = np.random.default_rng(1).normal(size=data["proprio"][..., :6].shape)
    assert max(held_out_r2(data, 1, iters=300)) < 0.3  # noise: nothing to read


def test_constant_draws_are_refused() -> None:
    # Fault: a blind oracle's env shows every robot the nominal draw; read from there the
    # targets were constant and every R^2 came out 1.00
    data = rollout(robots=16)
    data["draws"][:] = data["draws"][:1, :1]
    with pytest.raises(ValueError, match="do not vary"):
        held_out_r2(data, 1, iters=10)
