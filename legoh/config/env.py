"""HikingEnv config schema (the ``env`` node of ``conf/config.yaml``)."""

from dataclasses import dataclass, field


def table6_weights() -> dict[str, float]:
    """Reward weights of appendix Table 6 (robot-specific ones come from robot.reward_weights).

    ``pn_distance`` (point-navigation distance) is used by the unified stage only: 0 here.
    """
    return {
        "tracking_goal_vel": 10.0,
        "tracking_yaw": 0.5,
        "lin_vel_z": -2.0,
        "ang_vel_xy": -1.0,
        "orientation": -1.0,
        "dof_acc": -3.5e-8,
        "collision": -10.0,
        "action_rate": -0.01,
        "delta_torques": -1.0e-7,
        "torques": -1.0e-5,
        "hip_pos": -0.5,
        "dof_error": -0.04,
        "feet_stumble": -1.0,
        "feet_edge": -1.0,
        "feet_air_time": 1.0,
        "base_height": -100.0,
        "pn_distance": 0.0,
        "dof_pos_limits": 0.0,
    }


@dataclass
class DepthConfig:
    """Egocentric depth input (camera pose and FOV: robot.camera)."""

    enabled: bool = False  # stages that need no depth do not pay for it
    every: int = 5  # policy steps between frames (10 Hz at 50 Hz)
    frames: int = 4  # frame history length
    width: int = 32  # pixels: the cost of depth grows with pixels (experiments/bench_env.py)
    height: int = 24  # pixels
    far: float = 3.0  # m: range clip


@dataclass
class RandomizationConfig:
    """Appendix Table 5. Per-env physics parameters come from a pool of model copies."""

    enabled: bool = True
    pool_size: int = 8  # model copies with their own friction, mass, CoM, motor strength
    friction: list[float] = field(default_factory=lambda: [0.6, 2.0])
    base_mass_offset: list[float] = field(default_factory=lambda: [0.0, 3.0])  # kg
    base_com_offset: float = 0.2  # m: base CoM shifted by U(-x, x) per axis
    motor_strength: list[float] = field(default_factory=lambda: [0.8, 1.2])
    push_interval_s: float = 8.0  # s
    push_max_vel: float = 0.5  # m/s, xy
    max_action_delay: int = 1  # policy steps of delay reachable once delay_after_steps passed
    delay_after_steps: int = 192_000  # global env steps (24 x 8000) before delays switch on


@dataclass
class CurriculumConfig:
    """Appendix 6.2.1 (corrected): up above ``up``, down below ``down`` of the expected distance."""

    enabled: bool = True
    up: float = 0.8
    down: float = 0.4
    start_level: int = 0  # max initial level (uniform in 0..start_level)


@dataclass
class EnvConfig:
    """HikingEnv: batch, observations, rewards, terminations."""

    num_envs: int = 16
    episode_length_s: float = 20.0  # s (training; evaluation sets 30)
    action_clip: float = 4.8  # actions are clipped to [-clip, clip] before scaling
    goal_speed: float = 0.8  # m/s, the speed the goal-velocity reward asks for
    waypoint_radius: float = 0.6  # m: an expert waypoint counts as passed within this
    reach_radius: float = 0.5  # m: terminus reached (0.5 training, 0.89 evaluation)
    max_roll: float = 0.8  # rad, pose check
    max_pitch: float = 1.0  # rad, pose check
    min_base_height: float = 0.5  # fraction of the nominal base height above the ground
    history: int = 10  # proprioception history length
    spawn_noise: float = 0.3  # m, xy jitter of the spawn point
    divergence_qvel: float = 1.0e3  # |qvel| above this counts as a diverged simulation
    rewards: dict[str, float] = field(default_factory=table6_weights)
    # legged_gym's default: clip the step's total at 0, so that ending an episode early (a
    # fall) is never a way to escape the penalties. Without it, our first 2M-frame study
    # learned to dive toward the goal and fall sooner than the untrained policy.
    only_positive_rewards: bool = True
    # legged_gym's "termination" term (its biped, Cassie, uses -200), added after the clip
    # and scaled by dt like every term: a fall costs 4 at 50 Hz. Not in Table 6; without it
    # the study's oracle learned to dive toward the goal (docs/env.md).
    termination_penalty: float = -200.0
    air_time_target: float = 0.5  # s, Table 6 feet air time
    depth: DepthConfig = field(default_factory=DepthConfig)
    randomization: RandomizationConfig = field(default_factory=RandomizationConfig)
    curriculum: CurriculumConfig = field(default_factory=CurriculumConfig)
