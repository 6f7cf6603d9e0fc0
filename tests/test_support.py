"""Heights against the support the robot stands on, and the gait clock's weight
(``legoh.envs.mdp.support``): a foot over a gap or a box reads the lift a person would
measure; the clock yields near edges, pits and obstacles."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from legoh.envs.hiking_env import make_env
from legoh.envs.mdp.support import clock_weights, support_heights
from tests.conftest import compose_config

RES = 0.05  # m per cell


def pit_and_box() -> np.ndarray:
    """10 x 4 m of flat ground at 0: a 0.6 m wide, 1 m deep pit across x = 3.0-3.6 m, a
    2 m wide one across x = 6-8 m, and a 0.3 m box top over x = 1.0-1.2 m."""
    x = np.arange(0, 10, RES)[:, None] * np.ones((1, 80))
    h = np.zeros_like(x)
    h[(x >= 3.0) & (x < 3.6)] = -1.0
    h[(x >= 6.0) & (x < 8.0)] = -1.0
    h[(x >= 1.0) & (x < 1.2)] = 0.3
    return h


def test_narrow_pits_are_filled_to_the_rim_boxes_and_wide_pits_stay() -> None:
    h = pit_and_box()
    s = support_heights(h, RES, window=1.0)
    cell = lambda x: int(round(x / RES))  # noqa: E731 - a row of the grid at x metres
    assert np.allclose(s[cell(3.3)], 0.0)  # over the 0.6 m gap: its rim
    assert np.allclose(s[cell(1.1)], 0.3)  # on the box: its top
    assert np.allclose(s[cell(7.0)], -1.0)  # the 2 m pit is a floor to stand on
    assert np.allclose(s[cell(0.5)], 0.0) and np.allclose(s[cell(9.5)], 0.0)


def test_clock_weight_is_zero_at_features_and_one_far_from_them() -> None:
    h = pit_and_box()
    edges = np.zeros(h.shape, dtype=bool)
    w = clock_weights(np.minimum(h, 0.0), h, support_heights(h, RES, 1.0), edges, RES,
                      near=0.6, fade=0.6)
    cell = lambda x: int(round(x / RES))  # noqa: E731
    assert w[cell(2.7)].max() == 0.0  # 0.3 m before the gap
    assert w[cell(1.5)].max() == 0.0  # 0.3 m past the box
    assert np.allclose(w[cell(5.0)], 1.0)  # 1.4 m from both pits
    assert 0.0 < w[cell(2.1)].max() < 1.0  # 0.9 m from both: fading
    assert clock_weights(h, h, h, edges, RES, near=0.0, fade=0.6) is None


@pytest.mark.parametrize("reference", ["support", "ground"])
def test_a_foot_over_a_gap_reads_its_lift_above_the_rim(reference: str) -> None:
    """The env's height grid over a Gap pit: the rim (support) or the pit floor (ground,
    the shipped oracles' recipe)."""
    cfg = compose_config("trail=gap", "trail.levels=5", "trail.variants=1",  # pits 0.2-1 m
                         f"env.height_reference={reference}")
    env = make_env(cfg, num_envs=1)
    tm, h = env.terrain, env.terrain.heights
    reach = 8  # cells: a gap under 0.8 m along the trail (x), stones on both sides
    deep = h[reach:-reach] < -0.5
    near = [(np.roll(h, k, 0)[reach:-reach] > -0.1) for k in range(1, reach)]
    before, after = np.any(near, 0), np.any([np.roll(h, -k, 0)[reach:-reach] > -0.1
                                             for k in range(1, reach)], 0)
    i, j = np.argwhere(deep & before & after)[0]
    i += reach
    rim = max(h[i - reach:i, j].max(), h[i:i + reach, j].max())
    xy = tm.origin + np.array([i, j]) * tm.resolution  # a cell deep in a narrow gap
    here = float(env.support.bilinear(torch.as_tensor(xy, dtype=env.dtype)[None])[0])
    floor = float(h[i, j])
    if reference == "support":
        assert abs(here - rim) < 0.15 and here > floor + 0.5
    else:
        assert here == pytest.approx(floor, abs=1e-6)
    env.close()


def test_a_foot_over_a_hurdle_reads_its_lift_above_the_top() -> None:
    cfg = compose_config("trail=hurdle", "trail.levels=1", "trail.variants=1")
    env = make_env(cfg, num_envs=1)
    x, y, z, hx, hy, hz, yaw = env.terrain.boxes[0]
    top = float(env.support.bilinear(torch.tensor([[x, y]], dtype=env.dtype))[0])
    assert top == pytest.approx(z + hz, abs=0.02)
    env.close()
