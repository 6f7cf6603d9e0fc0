"""Algorithm config schemas (``conf/algo/*.yaml``)."""

from dataclasses import dataclass


@dataclass
class OracleConfig:
    """Stage 1: PPO with privileged inputs. Defaults: Extreme Parkour / legged_gym (see docs)."""

    name: str = "oracle"
    num_envs: int = 64
    steps_per_env: int = 24  # policy steps per env per iteration
    total_frames: int = 200_000  # env steps over the whole run
    lr: float = 2e-4
    desired_kl: float = 0.01  # adaptive learning rate target
    clip_epsilon: float = 0.2
    entropy_coef: float = 0.01
    epochs: int = 5
    minibatches: int = 4
    gamma: float = 0.99
    gae_lambda: float = 0.95
    max_grad_norm: float = 1.0
    episode_length_s: float = 20.0  # s, training episodes
