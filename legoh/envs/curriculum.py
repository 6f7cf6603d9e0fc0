"""Terrain curriculum (appendix 6.2.1, with its typo corrected)."""

import torch


def update_levels(levels: torch.Tensor, covered: torch.Tensor, expected: torch.Tensor,
                  reached: torch.Tensor, num_levels: int, gen: torch.Generator,
                  up: float = 0.8, down: float = 0.4) -> torch.Tensor:
    """New terrain levels for envs whose episode just ended.

    A robot moves up a level when it covered more than ``up`` of the expected distance (or
    reached the terminus), down when it covered less than ``down``; past the top level it is
    sent to a random level, which keeps every level in the training mix.

    Args:
        levels: (E,) int64 current levels. covered, expected: (E,) metres along the trail.
        reached: (E,) bool. num_levels: levels are 0..num_levels-1. gen: the env's generator.
    """
    ratio = covered / torch.clamp(expected, min=1e-6)
    move_up = (ratio > up) | reached
    move_down = (ratio < down) & ~move_up
    new = levels + move_up.long() - move_down.long()
    anywhere = torch.randint(0, num_levels, new.shape, generator=gen, device=new.device)
    new = torch.where(new >= num_levels, anywhere, new)
    return torch.clamp(new, 0, num_levels - 1)
