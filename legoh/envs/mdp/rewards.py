"""Reward terms of appendix Table 6 and the walking recipe, each a small pure function
``fn(state, **params)`` of one step's ``StepState`` (torch, on the env's device).

Terms are registered by name; weights come from a preset (``env.reward_preset``: ``walk``,
the default, or ``table6``, with the robot's Table 6 column) and ``env.rewards`` on top
(:func:`preset_weights`); zero-weight terms are never computed. Sign convention: every
term returns a non-negative magnitude or a bonus, and its weight carries the sign (Table 6's
weights, negative for penalties). Like legged_gym and Extreme Parkour, the weighted sum is
scaled by the policy period dt, and where a preset clips the step's total at 0 the terms of
``AFTER_CLIP`` (the fall penalty, ``termination``) are added after the clip. Bookkeeping
(air time, contacts, waypoint index) happens in the env step, never here. A term's
parameters come from config (:func:`term_params`) and sit beside its weight in the table
(:func:`active_terms`). Formulas: docs/env.md.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import torch

from legoh.envs.mdp.state import StepState

RewardFn = Callable[..., torch.Tensor]  # fn(state, **params) -> (N,)
REWARD_TERMS: dict[str, RewardFn] = {}
# added to the step's total after its clip at 0 (legged_gym: a fall costs its penalty even
# where every other term is clipped away)
AFTER_CLIP = frozenset({"termination"})


def reward_term(fn: RewardFn) -> RewardFn:
    """Register ``fn`` under its name (add your own the same way)."""
    REWARD_TERMS[fn.__name__] = fn
    return fn


def _to_waypoint(s: StepState) -> tuple[torch.Tensor, torch.Tensor]:
    d = s.waypoint_xy - s.base_xy
    dist = torch.linalg.vector_norm(d, dim=1)
    return d / (dist[:, None] + 1e-5), dist


@reward_term
def tracking_goal_vel(s: StepState, speed: float) -> torch.Tensor:
    """min(v . dir_to_waypoint, v_cmd) / v_cmd: speed toward the next goal, capped."""
    direction, _ = _to_waypoint(s)
    along = (direction * s.lin_vel_world[:, :2]).sum(1)
    return torch.clamp(along, max=speed) / (speed + 1e-5)


@reward_term
def tracking_yaw(s: StepState) -> torch.Tensor:
    """exp(-|yaw_target - yaw|), yaw_target pointing at the next goal."""
    direction, _ = _to_waypoint(s)
    err = torch.atan2(direction[:, 1], direction[:, 0]) - s.yaw
    return torch.exp(-torch.abs(torch.remainder(err + math.pi, 2 * math.pi) - math.pi))


@reward_term
def lin_vel_z(s: StepState) -> torch.Tensor:
    """v_z^2 in the base frame."""
    return s.lin_vel_body[:, 2] ** 2


@reward_term
def ang_vel_xy(s: StepState) -> torch.Tensor:
    """w_x^2 + w_y^2 in the base frame."""
    return (s.ang_vel_body[:, :2] ** 2).sum(1)


@reward_term
def orientation(s: StepState) -> torch.Tensor:
    """g_x^2 + g_y^2 of gravity in the base frame (0 when upright)."""
    return (s.gravity_body[:, :2] ** 2).sum(1)


@reward_term
def dof_acc(s: StepState) -> torch.Tensor:
    """sum ((qd_{t-1} - qd_t) / dt)^2."""
    return (((s.last_dof_vel - s.dof_vel) / s.dt) ** 2).sum(1)


@reward_term
def collision(s: StepState) -> torch.Tensor:
    """Number of non-foot bodies in contact with the world (shins on hurdles, knees on walls)."""
    return s.unsafe_contacts.to(s.yaw.dtype)


@reward_term
def action_rate(s: StepState) -> torch.Tensor:
    """||a_{t-1} - a_t||."""
    return torch.linalg.vector_norm(s.last_action - s.action, dim=1)


@reward_term
def delta_torques(s: StepState) -> torch.Tensor:
    """sum (tau_t - tau_{t-1})^2."""
    return ((s.torques - s.last_torques) ** 2).sum(1)


@reward_term
def torques(s: StepState) -> torch.Tensor:
    """sum tau^2."""
    return (s.torques**2).sum(1)


@reward_term
def hip_pos(s: StepState) -> torch.Tensor:
    """sum (q_hip - q_hip_default)^2 over hip yaw and roll."""
    d = s.dof_pos[:, s.hip_idx] - s.default_pose[s.hip_idx]
    return (d**2).sum(1)


@reward_term
def dof_error(s: StepState) -> torch.Tensor:
    """sum (q - q_default)^2."""
    return ((s.dof_pos - s.default_pose) ** 2).sum(1)


@reward_term
def feet_stumble(s: StepState) -> torch.Tensor:
    """1 if any foot's horizontal contact force exceeds 4x its vertical force."""
    horizontal = torch.linalg.vector_norm(s.feet_force[..., :2], dim=-1)
    return (horizontal > 4.0 * torch.abs(s.feet_force[..., 2])).any(1).to(s.yaw.dtype)


@reward_term
def feet_edge(s: StepState, min_level: int) -> torch.Tensor:
    """(level > min_level) * number of feet in contact on a terrain edge."""
    return (s.level > min_level) * s.feet_on_edge.sum(1).to(s.yaw.dtype)


@reward_term
def feet_air_time(s: StepState, target: float) -> torch.Tensor:
    """sum (T_air - target) * first_contact: long steps rewarded at touch-down."""
    return ((s.air_time - target) * s.first_contact).sum(1)


@reward_term
def leap_air_time(s: StepState, target: float) -> torch.Tensor:
    """feet_air_time where the gait clock yields (times 1 - clock weight): long steps pay
    at touch-down near edges, pits and obstacles. Ungated, Table 6's 0.5 s target charged
    every step of the clock's gait (0.36 s of swing) and its walkers fell more (docs/oracle.md,
    "Recipe v2")."""
    return ((s.air_time - target) * s.first_contact).sum(1) * (1.0 - s.clock_weight)


@reward_term
def base_height(s: StepState, target: float) -> torch.Tensor:
    """(h_base - h_target)^2, height above the ground under the base."""
    return (s.base_height - target) ** 2


@reward_term
def pn_distance(s: StepState, radius: float) -> torch.Tensor:
    """1 within the reach radius of the terminus, else -0.75 ||p_rel|| (unified stage)."""
    dist = torch.linalg.vector_norm(s.terminus_xy - s.base_xy, dim=1)
    return torch.where(dist < radius, 1.0, -0.75 * dist)


@reward_term
def pn_progress(s: StepState) -> torch.Tensor:
    """m/s by which the remaining expert path to the terminus shrank this step (unified
    stage): the gain of the potential -(path left), so a run's sum is the path it covered."""
    return s.path_progress


@reward_term
def pn_line_progress(s: StepState) -> torch.Tensor:
    """m/s by which the straight-line distance to the terminus shrank this step."""
    return s.line_progress


@reward_term
def pn_reach(s: StepState, radius: float) -> torch.Tensor:
    """1 within the reach radius of the terminus, else 0: Table 6's point-navigation bonus
    without its distance penalty (the reach ends the episode, so it is paid once)."""
    dist = torch.linalg.vector_norm(s.terminus_xy - s.base_xy, dim=1)
    return (dist < radius).to(s.yaw.dtype)


@reward_term
def dof_pos_limits(s: StepState) -> torch.Tensor:
    """sum of how far joints are outside their range (rad)."""
    low, high = s.joint_range[:, 0], s.joint_range[:, 1]
    return (torch.clamp(low - s.dof_pos, min=0.0) + torch.clamp(s.dof_pos - high, min=0.0)
            ).sum(1)


@reward_term
def tracking_lin_vel(s: StepState, sigma: float) -> torch.Tensor:
    """exp(-|v_cmd - v_xy|^2 / sigma), velocity in the yaw frame, command (speed, 0)."""
    c, sn = torch.cos(s.yaw), torch.sin(s.yaw)
    vx = c * s.lin_vel_world[:, 0] + sn * s.lin_vel_world[:, 1]
    vy = -sn * s.lin_vel_world[:, 0] + c * s.lin_vel_world[:, 1]
    return torch.exp(-((vx - s.command[:, 0]) ** 2 + vy**2) / sigma)


@reward_term
def tracking_waypoint_vel(s: StepState, sigma: float) -> torch.Tensor:
    """exp(-|v_xy - v_cmd * dir_to_waypoint|^2 / sigma), world frame: the commanded speed
    toward the next expert waypoint. tracking_lin_vel asks for the speed along the robot's
    own heading, which a robot walking in circles earns too (the first hiking run learned
    that: safe from ditches and gaps, paid for walking; docs/oracle.md)."""
    direction, _ = _to_waypoint(s)
    err = s.lin_vel_world[:, :2] - s.command[:, :1] * direction
    return torch.exp(-(err**2).sum(1) / sigma)


@reward_term
def tracking_ang_vel(s: StepState, sigma: float) -> torch.Tensor:
    """exp(-(w_cmd - w_z)^2 / sigma): the yaw rate that steers toward the next goal."""
    return torch.exp(-((s.ang_vel_body[:, 2] - s.command[:, 1]) ** 2) / sigma)


@reward_term
def alive(s: StepState) -> torch.Tensor:
    """1 per step not fallen (unitree_rl_gym's H1: 0.15)."""
    return torch.ones_like(s.yaw)


@reward_term
def dof_vel(s: StepState) -> torch.Tensor:
    """sum qd^2."""
    return (s.dof_vel**2).sum(1)


@reward_term
def feet_contact_phase(s: StepState, yield_pay: float) -> torch.Tensor:
    """Number of feet whose contact matches the gait clock (stance down, swing up), times
    the clock's weight here (it yields near edges, pits and obstacles); where it yields,
    ``yield_pay`` of its best (every foot matching) instead."""
    matched = (s.feet_contact == s.stance).sum(1).to(s.yaw.dtype)
    return yielded(matched, s.clock_weight, yield_pay * s.feet_contact.shape[1])


@reward_term
def feet_swing_height(s: StepState, height: float) -> torch.Tensor:
    """sum over airborne feet of (lift - swing height)^2, times the clock's weight."""
    return ((s.feet_height - height) ** 2 * ~s.feet_contact).sum(1) * s.clock_weight


@reward_term
def feet_phase(s: StepState, sigma: float, yield_pay: float) -> torch.Tensor:
    """exp(-sum (lift - clock's lift)^2 / sigma): MuJoCo Playground's feet-phase term, a
    dense signal for stepping (the contact match pays only once a foot is off the ground);
    times the clock's weight, and ``yield_pay`` where it yields."""
    phase = torch.exp(-((s.feet_height - s.swing_target) ** 2).sum(1) / sigma)
    return yielded(phase, s.clock_weight, yield_pay)


def yielded(term: torch.Tensor, clock_weight: torch.Tensor, pay: float) -> torch.Tensor:
    """A clock term where the clock weighs ``clock_weight``, and ``pay`` where it yields (a
    zone where the clock pays nothing is a tax on being near an obstacle)."""
    return term * clock_weight + pay * (1.0 - clock_weight)


@reward_term
def termination(s: StepState) -> torch.Tensor:
    """1 on the step an episode ends in a failure (a fall: ``mdp.terminations``), else 0;
    legged_gym's termination term, in ``AFTER_CLIP``."""
    return s.failed.to(s.yaw.dtype)


def preset_weights(preset: str, overrides: dict[str, float | None],
                   robot_table6: dict[str, float],
                   robot_scales: dict[str, float] | None = None) -> dict[str, float]:
    """Weights of a reward preset (``legoh.config.env.REWARD_PRESETS``), the robot's Table 6
    column for ``table6``, times the robot's ``reward_scales``, then ``overrides``
    (``env.rewards``: absolute weights, the user's last word)."""
    from legoh.config.env import REWARD_PRESETS

    if preset not in REWARD_PRESETS:
        raise ValueError(f"env.reward_preset={preset!r}: known presets {sorted(REWARD_PRESETS)}")
    weights = REWARD_PRESETS[preset][0]()
    if preset == "table6":
        weights.update(robot_table6)
    for name, scale in (robot_scales or {}).items():
        if name not in weights:
            raise ValueError(f"robot.reward_scales.{name}: unknown reward term; known: "
                             f"{sorted(weights)}")
        weights[name] *= scale
    weights.update({k: v for k, v in overrides.items() if v is not None})
    return weights


def term_params(cfg, target_height: float, reach_radius: float) -> dict[str, dict]:
    """Each parametrised term's parameters, from the env config (``cfg``: EnvConfig) and the
    robot's nominal base height; terms not listed take none."""
    return {
        "tracking_goal_vel": {"speed": cfg.goal_speed},
        "tracking_lin_vel": {"sigma": cfg.tracking_sigma},
        "tracking_waypoint_vel": {"sigma": cfg.tracking_sigma},
        "tracking_ang_vel": {"sigma": cfg.tracking_sigma},
        "feet_air_time": {"target": cfg.air_time_target},
        "leap_air_time": {"target": cfg.air_time_target},
        "feet_swing_height": {"height": cfg.gait.swing_height},
        "feet_phase": {"sigma": cfg.gait.phase_sigma, "yield_pay": cfg.gait.yield_pay},
        "feet_contact_phase": {"yield_pay": cfg.gait.yield_pay},
        "feet_edge": {"min_level": cfg.edge_min_level},
        "base_height": {"target": target_height},
        "pn_distance": {"radius": reach_radius},
        "pn_reach": {"radius": reach_radius},
    }


class RewardTerm(NamedTuple):
    """One row of the reward table: the function, its weight, its parameters."""

    fn: RewardFn
    weight: float
    params: dict


def active_terms(weights: dict[str, float], params: dict[str, dict] | None = None
                 ) -> dict[str, RewardTerm]:
    """The reward table: non-zero-weight terms with their parameters; an unknown name is an
    error naming the known ones."""
    unknown = sorted(set(weights) - set(REWARD_TERMS))
    if unknown:
        raise ValueError(f"unknown reward term(s) {unknown}; known: {sorted(REWARD_TERMS)}")
    params = params or {}
    return {name: RewardTerm(REWARD_TERMS[name], w, params.get(name, {}))
            for name, w in weights.items() if w != 0.0}


def reward_table(cfg, robot_cfg, target_height: float, reach_radius: float
                 ) -> tuple[dict[str, RewardTerm], bool]:
    """The env's reward table (``cfg``: EnvConfig, ``robot_cfg``: RobotConfig) and whether
    the step's total is clipped at 0."""
    from legoh.config.env import REWARD_PRESETS

    weights = preset_weights(cfg.reward_preset, dict(cfg.rewards),
                             dict(robot_cfg.table6_weights), dict(robot_cfg.reward_scales))
    table = active_terms(weights, term_params(cfg, target_height, reach_radius))
    _, clip_total = REWARD_PRESETS[cfg.reward_preset]
    clip = clip_total if cfg.only_positive_rewards is None else bool(cfg.only_positive_rewards)
    return table, clip


def compute_rewards(state: StepState, terms: dict[str, RewardTerm], clip: bool = False
                    ) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Total reward (N,) = dt * sum_k w_k r_k, clipped at 0 when ``clip`` (the terms of
    ``AFTER_CLIP`` added after the clip), and each weighted, dt-scaled term (N,)."""
    parts = {name: t.fn(state, **t.params) * (t.weight * state.dt)
             for name, t in terms.items()}
    def summed(names: list[str]) -> torch.Tensor:
        return (torch.stack([parts[k] for k in names]).sum(0) if names
                else torch.zeros_like(state.yaw))

    total = summed([k for k in parts if k not in AFTER_CLIP])
    if clip:
        total = torch.clamp(total, min=0.0)
    after = [k for k in parts if k in AFTER_CLIP]
    return (total + summed(after) if after else total), parts
