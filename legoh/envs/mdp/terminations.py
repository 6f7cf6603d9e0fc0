"""Termination terms: ``fn(env, state) -> (N,) bool``. ``TERMINATIONS`` maps each name to
``(fn, time_out)``: a time-out truncates the episode, any other term terminates it. Each
term's flag is also reported as ``("info", name)`` unless it is a time-out."""

from __future__ import annotations

import torch

from legoh.envs.mdp.state import StepState


def reached(env, s: StepState) -> torch.Tensor:
    """Within the reach radius of the terminus."""
    return torch.linalg.vector_norm(s.terminus_xy - s.base_xy, dim=1) < env.reach_radius


def fell(env, s: StepState) -> torch.Tensor:
    """The pose check: rolled or pitched past its limit, or the base too low."""
    c = env.cfg
    low = s.base_height < c.min_base_height * env.robot.nominal_base_height
    return (torch.abs(s.roll) > c.max_roll) | (torch.abs(s.pitch) > c.max_pitch) | low


def time_out(env, s: StepState) -> torch.Tensor:
    """The episode ran its length."""
    return env.steps >= env.max_steps


TERMINATIONS = {"reached": (reached, False), "fell": (fell, False),
                "timeout": (time_out, True)}
