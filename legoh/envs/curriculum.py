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


def lagging_categories(category: torch.Tensor, levels: torch.Tensor, ended: torch.Tensor,
                       num_categories: int, num_levels: int, mix: float,
                       gen: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """New categories (and levels) for the envs ``ended``, weighted toward lagging ones.

    A share ``mix`` of the ended episodes draws its next category with weight
    ``num_levels - mean level`` of the category's robots (a category whose robots sit at
    level 0 weighs ``num_levels``, one at the top 1), the rest keep theirs; so robots flow
    to the categories the policy has not learned yet while every category stays in the
    mix. An env that changes category takes the level of a random robot of its new
    category, which keeps each category's level distribution its own (the levels are
    earned there). 0 keeps the categories fixed (``env % categories``, the paper's split).

    Args:
        category, levels: (E,) int64 of every env. ended: (K,) int64 ids of the ended
        episodes. Returns the new (K,) categories and levels of ``ended``.
    """
    cat, lev = category[ended].clone(), levels[ended].clone()
    if mix <= 0 or len(ended) == 0:
        return cat, lev
    dev = category.device
    counts = torch.bincount(category, minlength=num_categories).float()
    sums = torch.bincount(category, weights=levels.float(), minlength=num_categories)
    mean = torch.where(counts > 0, sums / counts.clamp(min=1), torch.zeros_like(sums))
    weight = (num_levels - mean).clamp(min=1.0)
    draw = torch.rand(len(ended), generator=gen, device=dev) < mix
    if not draw.any():
        return cat, lev
    new = torch.multinomial(weight, int(draw.sum()), replacement=True, generator=gen)
    moved = draw.clone()
    moved[draw] = new != cat[draw]
    cat[draw] = new
    for c in cat[moved].unique().tolist():
        into = moved & (cat == c)
        pool = levels[category == c]
        if len(pool) == 0:
            lev[into] = 0
            continue
        pick = torch.randint(0, len(pool), (int(into.sum()),), generator=gen, device=dev)
        lev[into] = pool[pick]
    return cat, lev
