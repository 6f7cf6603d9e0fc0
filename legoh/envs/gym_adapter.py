"""A thin ``gymnasium.Env`` over a single-robot HikingEnv, for users who want one.

Observations are a dict of float32 arrays named after the ``("obs", ...)`` keys ("proprio",
"proprio_history", "scandots", "privileged", "goal", and "depth" when enabled), without the
batch dimension. Episodes end with ``terminated`` (fell) or ``truncated`` (reached, timeout
or a diverged simulation; ``info["reached"]`` tells a reach); as gymnasium expects, the caller
resets. ``info`` carries the ``("info", ...)`` signals as Python scalars, the reward terms and
the expert goals.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded

from legoh import keys
from legoh.envs.hiking_env import HikingEnv, make_env


def _box(spec: Any) -> gym.spaces.Box:
    """Box of one env's slice of a (1, ...) spec: the spec's bounds, or unbounded."""
    shape = tuple(spec.shape[1:])
    if isinstance(spec, Bounded):
        low, high = spec.space.low[0].numpy(), spec.space.high[0].numpy()
        return gym.spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)
    return gym.spaces.Box(-np.inf, np.inf, shape, dtype=np.float32)


class HikingGymEnv(gym.Env):
    """One robot on the trails of a ``HikingEnv`` built with ``num_envs=1``."""

    metadata = {"render_modes": []}

    def __init__(self, env: HikingEnv) -> None:
        if env.num_envs != 1:
            raise ValueError(f"HikingGymEnv wraps a single env; got num_envs={env.num_envs}")
        self.env = env
        obs_spec = env.observation_spec["obs"]
        self.obs_keys = list(obs_spec.keys())
        self.observation_space = gym.spaces.Dict({k: _box(obs_spec[k]) for k in self.obs_keys})
        self.action_space = _box(env.action_spec)
        self._fresh = env.curriculum_state()

    @classmethod
    def from_config(cls, cfg, evaluation: bool = False, **env_overrides) -> HikingGymEnv:
        """From a composed run config, as ``make_env`` (overrides go to ``env``)."""
        return cls(make_env(cfg, num_envs=1, evaluation=evaluation, **env_overrides))

    def _obs(self, td: TensorDictBase) -> dict[str, np.ndarray]:
        # float32 throughout, as the Box spaces say (the depth_fresh flag included)
        return {k: td["obs", k][0].numpy().astype(np.float32) for k in self.obs_keys}

    def _info(self, td: TensorDictBase) -> dict[str, Any]:
        values = {k: td[keys.INFO, k][0] for k in td[keys.INFO].keys()
                  if k != "reward_terms"}
        info = {k: v.item() if v.numel() == 1 else v.numpy().copy() for k, v in values.items()}
        info["reward_terms"] = {k: v[0].item() for k, v in td[keys.REWARD_TERMS].items()}
        info["expert_goals"] = td[keys.EXPERT_GOALS][0].numpy().copy()
        return info

    def reset(self, *, seed: int | None = None, options: dict | None = None
              ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """New episode; a ``seed`` reseeds the env's random draws (spawn, tile, physics) and
        sets its schedule (level, step counter, randomisation gate) back to a fresh env's,
        so a seeded episode replays exactly."""
        super().reset(seed=seed)
        if seed is not None:
            self.env.set_seed(seed)
            self.env.load_curriculum_state(self._fresh)
        td = self.env.reset()
        return self._obs(td), self._info(td)

    def step(self, action: np.ndarray
             ) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """One policy step; ``action`` (A,) joint offsets (see HikingEnv)."""
        act = torch.as_tensor(np.asarray(action, dtype=np.float32)).reshape(1, -1)
        td = self.env.step(TensorDict({keys.ACTION: act}, batch_size=[1]))["next"]
        return (self._obs(td), float(td[keys.REWARD][0, 0]), bool(td[keys.TERMINATED][0, 0]),
                bool(td[keys.TRUNCATED][0, 0]), self._info(td))

    def close(self) -> None:
        """Stop the env's thread pools."""
        self.env.close()
