"""Distillation losses of the unified stage: the student imitates the oracle (DAgger labels).

Each term is a plain function of tensors; :func:`distillation_loss` weighs them with the
Table 7 weights (the mapping is in :class:`legoh.config.algo.LossWeights` and
docs/unified.md) and returns a TensorDict in torchrl's convention: ``loss_*`` entries are
summed by the caller, zero-weight terms are skipped (not computed).
"""

from __future__ import annotations

import torch
from tensordict import TensorDict, TensorDictBase

from legoh import keys


def goal_correction_target(goal: torch.Tensor, expert_goals: torch.Tensor) -> torch.Tensor:
    """delta_g0's target: the unit direction to the next expert waypoint minus the unit
    direction to the terminus, both in the robot yaw frame. (..., 4), (..., G, 2) -> (..., 2).

    The terminus direction is what the robot is told; the correction turns it toward where
    the trail actually goes next (around an obstacle, along a detour)."""
    def unit(xy: torch.Tensor) -> torch.Tensor:
        return xy / xy.norm(dim=-1, keepdim=True).clamp_min(1e-6)

    return unit(expert_goals[..., 0, :]) - unit(goal[..., :2])


def distillation_loss(student_out: TensorDictBase, student_loc: torch.Tensor,
                      batch: TensorDictBase, weights, hlm=None) -> TensorDict:
    """Imitation terms on a (N, T) batch labelled by the oracle.

    Args:
        student_out: the navigation module's outputs, re-run with gradients (``unroll``).
        student_loc: the locomotion module's mean action on those outputs (N, T, A).
        batch: the collected batch with ``TEACHER_ACTION`` (N, T, A), ``TEACHER_LATENT``
            (N, T, 32), ``EXPERT_GOALS`` (N, T, 3, 2) and ``GOAL`` (N, T, 4); and
            ``TEACHER_PRIV_LATENT`` (N, T, 20) when ``student_out`` has ``HISTORY_LATENT``.
        weights: :class:`legoh.config.algo.LossWeights` (or the same fields).
        hlm: a callable ``(teacher_action, student_action) -> TensorDict`` of ``loss_*``
            terms (HLM's plug-in loss), or None for no action prior.
    """
    out = TensorDict({}, batch_size=[])
    teacher = batch.get(keys.TEACHER_ACTION)
    if weights.w2:
        out["loss_action"] = weights.w2 * torch.mean((student_loc - teacher) ** 2)
    if weights.w7:
        latent = student_out.get(keys.STUDENT_LATENT)
        out["loss_latent"] = weights.w7 * torch.mean(
            (latent - batch.get(keys.TEACHER_LATENT)) ** 2)
    history = student_out.get(keys.HISTORY_LATENT, None)
    if history is not None and weights.w_priv:
        out["loss_priv_latent"] = weights.w_priv * torch.mean(
            (history - batch.get(keys.TEACHER_PRIV_LATENT)) ** 2)
    expert = batch.get(keys.EXPERT_GOALS)
    if weights.w3:
        target = goal_correction_target(batch.get(keys.GOAL), expert)
        out["loss_goal_correction"] = weights.w3 * torch.mean(
            (student_out.get(keys.GOAL_CORRECTION) - target) ** 2)
    near = student_out.get(keys.NEAR_GOALS)
    if weights.w4 and near.shape[-2] > 0:
        k = near.shape[-2]
        out["loss_near_goals"] = weights.w4 * torch.mean((near - expert[..., :k, :]) ** 2)
    if hlm is not None and weights.w8:
        flat = student_loc.reshape(-1, student_loc.shape[-1])
        terms = hlm(teacher.reshape(-1, teacher.shape[-1]), flat)
        for name, value in terms.items():
            out[name] = weights.w8 * value if name.startswith("loss_") else value
    return out
