"""The gymnasium adapter: gymnasium's own checker, spaces respected over a few steps."""

from collections.abc import Iterator

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from legoh.envs.gym_adapter import HikingGymEnv
from legoh.envs.hiking_env import make_env
from tests.conftest import compose_config

OVERRIDES = ("robot=h1", "trail=flat", "trail.levels=1", "trail.variants=1",
             "env.depth.enabled=true")


@pytest.fixture(scope="module")
def env() -> Iterator[HikingGymEnv]:
    gym_env = HikingGymEnv.from_config(compose_config(*OVERRIDES))
    yield gym_env
    gym_env.close()


def test_spaces(env: HikingGymEnv) -> None:
    assert set(env.observation_space.spaces) == {"proprio", "proprio_history", "scandots",
                                                 "privileged", "goal", "command", "depth",
                                                 "depth_fresh"}
    depth = env.observation_space["depth"]
    assert depth.low.min() == -0.5 and depth.high.max() == 0.5
    assert env.action_space.shape == (env.env.num_actions,)
    assert env.action_space.high.max() == env.env.cfg.action_clip


# Expected advice, not failures: actions are joint offsets clipped at +-action_clip (not
# [-1, 1]) and most observations are unbounded (physical quantities).
@pytest.mark.filterwarnings("ignore:.*symmetric and normalized space")
@pytest.mark.filterwarnings("ignore:.*observation space (minimum|maximum) value is")
def test_gymnasium_check_env(env: HikingGymEnv) -> None:
    # Render check skipped: the adapter has no render modes, and without a registered
    # gymnasium spec the checker can only warn that it cannot try any.
    check_env(env, skip_render_check=True)


def test_steps_respect_spaces(env: HikingGymEnv) -> None:
    obs, info = env.reset(seed=5)
    assert obs in env.observation_space
    assert {"reached", "fell", "progress", "waypoint", "level"} <= set(info)
    env.action_space.seed(5)
    for _ in range(5):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample() * 0.1)
        assert obs in env.observation_space
        assert isinstance(reward, float) and np.isfinite(reward)
        assert isinstance(terminated, bool) and isinstance(truncated, bool)
        assert isinstance(info["reached"], bool) and 0.0 <= info["progress"] <= 1.0
        assert set(info["reward_terms"]) == set(env.env.reward_terms)
        assert info["expert_goals"].shape == (3, 2)


def test_single_env_only() -> None:
    batched = make_env(compose_config(*OVERRIDES[:-1]), num_envs=2)
    try:
        with pytest.raises(ValueError, match="num_envs=2"):
            HikingGymEnv(batched)
    finally:
        batched.close()
