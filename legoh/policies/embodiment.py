"""The body a checkpoint learned in: a policy acts on the feet it trained on.

The feet's colliders (``robot.feet_collider``) changed on 2026-12-05 (``source`` ->
``spheres``, docs/robots.md). A checkpoint stores its config; one that stored no
``robot.feet_collider`` trained on ``source``. Evaluating, filming or resuming a checkpoint,
and distilling from a teacher, use the checkpoint's own feet; a new run (``init=`` takes
weights only) trains on the config's.
"""

from __future__ import annotations

from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from legoh.checkpoint import load_checkpoint

FEET_KEY = "robot.feet_collider"
LEGACY_FEET = "source"  # what a checkpoint that stored no feet_collider trained on


def checkpoint_feet(path: str | Path) -> str:
    """The feet collider checkpoint ``path`` trained on (its stored config's, else
    :data:`LEGACY_FEET`)."""
    stored = OmegaConf.create(load_checkpoint(path).get("config", {}))
    return str(OmegaConf.select(stored, FEET_KEY, default=LEGACY_FEET)).split(".")[-1]


def with_checkpoint_body(cfg: DictConfig, path: str | Path) -> DictConfig:
    """``cfg`` with the feet checkpoint ``path`` trained on; says so when they differ."""
    feet = checkpoint_feet(path)
    have = str(OmegaConf.select(cfg, FEET_KEY)).split(".")[-1]
    if feet == have:
        return cfg
    cfg = cfg.copy()
    OmegaConf.update(cfg, FEET_KEY, feet, merge=False)
    print(f"[legoh] {path}: its own feet, {FEET_KEY}={feet} (this config: {have})")
    return cfg
