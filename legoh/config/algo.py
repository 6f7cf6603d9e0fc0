"""Algorithm config schemas (``conf/algo/*.yaml``)."""

from dataclasses import dataclass


@dataclass
class OracleConfig:
    """Stage 1: PPO with privileged inputs. Defaults: Extreme Parkour / legged_gym (see docs)."""

    name: str = "oracle"
    num_envs: int = 64  # overrides env.num_envs for training
    workers: int = 1  # collector processes (MultiSyncCollector above 1), num_envs split evenly
    steps_per_env: int = 24  # policy steps per env per iteration
    total_frames: int = 500_000  # env steps over the whole run: ~5 min on a 2-core CPU
    lr: float = 2e-4
    desired_kl: float = 0.01  # adaptive learning rate target
    clip_epsilon: float = 0.2
    entropy_coef: float = 0.01
    epochs: int = 5
    minibatches: int = 4
    gamma: float = 0.99
    gae_lambda: float = 0.95
    value_coef: float = 1.0  # critic loss weight (rsl_rl)
    init_noise_std: float = 0.5  # initial action std (EP: 1.0; with kp 800 that saturates torques)
    max_grad_norm: float = 1.0
    adaptation_lr: float = 1e-3  # the adaptation module's own optimiser
    checkpoint_every: int = 20  # iterations between checkpoints (and one at the end)
    trajectory_every: int = 10  # iterations between trajectories logged to MCAP
