"""Reward terms of appendix Table 6, each a small pure function of one step's state.

Terms are registered by name; weights come from a preset (``env.reward_preset``: ``walk``,
the default, or ``table6``, with the robot's Table 6 column) and ``env.rewards`` on top
(:func:`preset_weights`); zero-weight terms are never computed. Sign convention: every
term returns a non-negative magnitude or a bonus, and its weight carries the sign (Table 6's
weights, negative for penalties). Like legged_gym and Extreme Parkour, the weighted sum is
scaled by the policy period dt. Bookkeeping (air time, contacts, waypoint index) happens in
the env step, never here. Formulas as implemented: docs/env.md.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


@dataclass
class StepState:
    """Everything a reward term may read, for N envs (all numpy, batch first)."""

    dt: float  # s, policy period
    lin_vel_body: np.ndarray  # (N, 3) m/s
    ang_vel_body: np.ndarray  # (N, 3) rad/s
    gravity_body: np.ndarray  # (N, 3) unit gravity in the base frame
    lin_vel_world: np.ndarray  # (N, 3) m/s
    base_xy: np.ndarray  # (N, 2) m
    yaw: np.ndarray  # (N,) rad
    base_height: np.ndarray  # (N,) m above the ground under the base
    target_height: float  # m
    dof_pos: np.ndarray  # (N, J) rad, actuated joints
    dof_vel: np.ndarray  # (N, J) rad/s
    last_dof_vel: np.ndarray  # (N, J)
    default_pose: np.ndarray  # (J,)
    joint_range: np.ndarray  # (J, 2)
    hip_idx: np.ndarray  # indices of hip yaw/roll joints in J
    torques: np.ndarray  # (N, J) N m
    last_torques: np.ndarray  # (N, J)
    action: np.ndarray  # (N, A)
    last_action: np.ndarray  # (N, A)
    waypoint_xy: np.ndarray  # (N, 2) current expert waypoint
    terminus_xy: np.ndarray  # (N, 2)
    goal_speed: float  # m/s
    reach_radius: float  # m
    feet_force: np.ndarray  # (N, F, 3) net contact force with the world, N, world frame
    feet_contact: np.ndarray  # (N, F) bool
    first_contact: np.ndarray  # (N, F) bool: touched down this step
    air_time: np.ndarray  # (N, F) s of the flight that just ended (0 when no touch-down)
    air_time_target: float  # s
    feet_on_edge: np.ndarray  # (N, F) bool: in contact on a terrain edge
    unsafe_contacts: np.ndarray  # (N,) number of non-foot bodies touching the world
    level: np.ndarray  # (N,) terrain level
    command: np.ndarray  # (N, 2) forward speed m/s (yaw frame), yaw rate rad/s
    tracking_sigma: float  # m^2/s^2 (rad^2/s^2 for the yaw rate)
    stance: np.ndarray  # (N, F) bool: the gait clock wants this foot on the ground
    feet_height: np.ndarray  # (N, F) m: foot lift above its standing height
    swing_height: float  # m
    swing_target: np.ndarray  # (N, F) m: the lift the gait clock asks for now


RewardTerm = Callable[[StepState], np.ndarray]
REWARD_TERMS: dict[str, RewardTerm] = {}


def reward_term(fn: RewardTerm) -> RewardTerm:
    """Register ``fn`` under its name (add your own the same way)."""
    REWARD_TERMS[fn.__name__] = fn
    return fn


def _to_waypoint(s: StepState) -> tuple[np.ndarray, np.ndarray]:
    d = s.waypoint_xy - s.base_xy
    dist = np.linalg.norm(d, axis=1)
    return d / (dist[:, None] + 1e-5), dist


@reward_term
def tracking_goal_vel(s: StepState) -> np.ndarray:
    """min(v . dir_to_waypoint, v_cmd) / v_cmd: speed toward the next goal, capped."""
    direction, _ = _to_waypoint(s)
    along = np.sum(direction * s.lin_vel_world[:, :2], axis=1)
    return np.minimum(along, s.goal_speed) / (s.goal_speed + 1e-5)


@reward_term
def tracking_yaw(s: StepState) -> np.ndarray:
    """exp(-|yaw_target - yaw|), yaw_target pointing at the next goal."""
    direction, _ = _to_waypoint(s)
    err = np.arctan2(direction[:, 1], direction[:, 0]) - s.yaw
    return np.exp(-np.abs((err + np.pi) % (2 * np.pi) - np.pi))


@reward_term
def lin_vel_z(s: StepState) -> np.ndarray:
    """v_z^2 in the base frame."""
    return s.lin_vel_body[:, 2] ** 2


@reward_term
def ang_vel_xy(s: StepState) -> np.ndarray:
    """w_x^2 + w_y^2 in the base frame."""
    return np.sum(s.ang_vel_body[:, :2] ** 2, axis=1)


@reward_term
def orientation(s: StepState) -> np.ndarray:
    """g_x^2 + g_y^2 of gravity in the base frame (0 when upright)."""
    return np.sum(s.gravity_body[:, :2] ** 2, axis=1)


@reward_term
def dof_acc(s: StepState) -> np.ndarray:
    """sum ((qd_{t-1} - qd_t) / dt)^2."""
    return np.sum(((s.last_dof_vel - s.dof_vel) / s.dt) ** 2, axis=1)


@reward_term
def collision(s: StepState) -> np.ndarray:
    """Number of non-foot bodies in contact with the world (shins on hurdles, knees on walls)."""
    return s.unsafe_contacts.astype(np.float64)


@reward_term
def action_rate(s: StepState) -> np.ndarray:
    """||a_{t-1} - a_t||."""
    return np.linalg.norm(s.last_action - s.action, axis=1)


@reward_term
def delta_torques(s: StepState) -> np.ndarray:
    """sum (tau_t - tau_{t-1})^2."""
    return np.sum((s.torques - s.last_torques) ** 2, axis=1)


@reward_term
def torques(s: StepState) -> np.ndarray:
    """sum tau^2."""
    return np.sum(s.torques**2, axis=1)


@reward_term
def hip_pos(s: StepState) -> np.ndarray:
    """sum (q_hip - q_hip_default)^2 over hip yaw and roll."""
    d = s.dof_pos[:, s.hip_idx] - s.default_pose[s.hip_idx]
    return np.sum(d**2, axis=1)


@reward_term
def dof_error(s: StepState) -> np.ndarray:
    """sum (q - q_default)^2."""
    return np.sum((s.dof_pos - s.default_pose) ** 2, axis=1)


@reward_term
def feet_stumble(s: StepState) -> np.ndarray:
    """1 if any foot's horizontal contact force exceeds 4x its vertical force."""
    horizontal = np.linalg.norm(s.feet_force[..., :2], axis=-1)
    return np.any(horizontal > 4.0 * np.abs(s.feet_force[..., 2]), axis=1).astype(np.float64)


@reward_term
def feet_edge(s: StepState) -> np.ndarray:
    """(level > 3) * number of feet in contact on a terrain edge."""
    return (s.level > 3) * np.sum(s.feet_on_edge, axis=1).astype(np.float64)


@reward_term
def feet_air_time(s: StepState) -> np.ndarray:
    """sum (T_air - 0.5) * first_contact: long steps rewarded at touch-down."""
    return np.sum((s.air_time - s.air_time_target) * s.first_contact, axis=1)


@reward_term
def base_height(s: StepState) -> np.ndarray:
    """(h_base - h_target)^2, height above the ground under the base."""
    return (s.base_height - s.target_height) ** 2


@reward_term
def pn_distance(s: StepState) -> np.ndarray:
    """1 within the reach radius of the terminus, else -0.75 ||p_rel|| (unified stage)."""
    dist = np.linalg.norm(s.terminus_xy - s.base_xy, axis=1)
    return np.where(dist < s.reach_radius, 1.0, -0.75 * dist)


@reward_term
def dof_pos_limits(s: StepState) -> np.ndarray:
    """sum of how far joints are outside their range (rad)."""
    low, high = s.joint_range[:, 0], s.joint_range[:, 1]
    return np.sum(np.maximum(low - s.dof_pos, 0.0) + np.maximum(s.dof_pos - high, 0.0), axis=1)


@reward_term
def tracking_lin_vel(s: StepState) -> np.ndarray:
    """exp(-|v_cmd - v_xy|^2 / sigma), velocity in the yaw frame, command (speed, 0)."""
    c, sn = np.cos(s.yaw), np.sin(s.yaw)
    vx = c * s.lin_vel_world[:, 0] + sn * s.lin_vel_world[:, 1]
    vy = -sn * s.lin_vel_world[:, 0] + c * s.lin_vel_world[:, 1]
    return np.exp(-((vx - s.command[:, 0]) ** 2 + vy**2) / s.tracking_sigma)


@reward_term
def tracking_ang_vel(s: StepState) -> np.ndarray:
    """exp(-(w_cmd - w_z)^2 / sigma): the yaw rate that steers toward the next goal."""
    return np.exp(-((s.ang_vel_body[:, 2] - s.command[:, 1]) ** 2) / s.tracking_sigma)


@reward_term
def alive(s: StepState) -> np.ndarray:
    """1 per step not fallen (unitree_rl_gym's H1: 0.15)."""
    return np.ones(len(s.yaw))


@reward_term
def dof_vel(s: StepState) -> np.ndarray:
    """sum qd^2."""
    return np.sum(s.dof_vel**2, axis=1)


@reward_term
def feet_contact_phase(s: StepState) -> np.ndarray:
    """Number of feet whose contact matches the gait clock (stance down, swing up)."""
    return np.sum(s.feet_contact == s.stance, axis=1).astype(np.float64)


@reward_term
def feet_swing_height(s: StepState) -> np.ndarray:
    """sum over airborne feet of (lift - swing height)^2."""
    return np.sum((s.feet_height - s.swing_height) ** 2 * ~s.feet_contact, axis=1)


@reward_term
def feet_phase(s: StepState) -> np.ndarray:
    """exp(-sum (lift - clock's lift)^2 / 0.005): MuJoCo Playground's feet-phase term, a dense
    signal for stepping (the contact match pays only once a foot is off the ground)."""
    return np.exp(-np.sum((s.feet_height - s.swing_target) ** 2, axis=1) / 0.005)


def preset_weights(preset: str, overrides: dict[str, float | None],
                   robot_table6: dict[str, float]) -> dict[str, float]:
    """Weights of a reward preset (``legoh.config.env.REWARD_PRESETS``), the robot's Table 6
    column for ``table6``, then ``overrides`` (``env.rewards``)."""
    from legoh.config.env import REWARD_PRESETS

    if preset not in REWARD_PRESETS:
        raise ValueError(f"env.reward_preset={preset!r}: known presets {sorted(REWARD_PRESETS)}")
    weights = REWARD_PRESETS[preset][0]()
    if preset == "table6":
        weights.update(robot_table6)
    weights.update({k: v for k, v in overrides.items() if v is not None})
    return weights


def active_terms(weights: dict[str, float]) -> dict[str, tuple[RewardTerm, float]]:
    """Non-zero-weight terms; an unknown name is an error naming the known ones."""
    unknown = sorted(set(weights) - set(REWARD_TERMS))
    if unknown:
        raise ValueError(f"unknown reward term(s) {unknown}; known: {sorted(REWARD_TERMS)}")
    return {name: (REWARD_TERMS[name], w) for name, w in weights.items() if w != 0.0}


def compute_rewards(state: StepState, terms: dict[str, tuple[RewardTerm, float]]
                    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Total reward (N,) = dt * sum_k w_k r_k, and each weighted, dt-scaled term (N,)."""
    parts = {name: weight * fn(state) * state.dt for name, (fn, weight) in terms.items()}
    total = np.sum(list(parts.values()), axis=0) if parts else np.zeros(len(state.yaw))
    return total, parts
