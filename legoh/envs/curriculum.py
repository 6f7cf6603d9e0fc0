"""Terrain curriculum (appendix 6.2.1, with its typo corrected)."""

import numpy as np


def update_levels(levels: np.ndarray, covered: np.ndarray, expected: np.ndarray,
                  reached: np.ndarray, num_levels: int, rng: np.random.Generator,
                  up: float = 0.8, down: float = 0.4) -> np.ndarray:
    """New terrain levels for envs whose episode just ended.

    A robot moves up a level when it covered more than ``up`` of the expected distance (or
    reached the terminus), down when it covered less than ``down``; past the top level it is
    sent to a random level, which keeps every level in the training mix.

    Args:
        levels: (E,) current levels. covered, expected: (E,) metres along the trail.
        reached: (E,) bool. num_levels: levels are 0..num_levels-1.
    """
    ratio = covered / np.maximum(expected, 1e-6)
    move_up = (ratio > up) | reached
    move_down = (ratio < down) & ~move_up
    new = levels + move_up.astype(np.int64) - move_down.astype(np.int64)
    past_top = new >= num_levels
    new[past_top] = rng.integers(0, num_levels, int(past_top.sum()))
    return np.clip(new, 0, num_levels - 1)
