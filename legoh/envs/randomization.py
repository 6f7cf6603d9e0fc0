"""Domain randomisation (appendix Table 5) with one shared terrain.

Per-env physical parameters (friction, base mass and CoM offsets, motor strength) live in the
MjModel, and all envs step against models of one size signature. So we build a pool of K
model copies, each with its own draw, and give each env a random pool member at every reset.
Memory is K models (the height field included); K = 8 by default. Pushes and action delays
are per env and need no model.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import mujoco
import numpy as np

from legoh.config.env import RandomizationConfig


@dataclass(frozen=True)
class PhysicsDraw:
    """One pool member's parameters: (K,) or (K, 3) arrays across the pool."""

    friction: np.ndarray  # (K,) robot geom sliding friction (robot geoms win contact pairs)
    mass_offset: np.ndarray  # (K,) kg added to the base body
    com_offset: np.ndarray  # (K, 3) m added to the base body's centre of mass
    motor_strength: np.ndarray  # (K,) scales kp and kd of every actuator

    def as_features(self) -> np.ndarray:
        """(K, 6) privileged features: friction, mass offset, CoM offset xyz, strength."""
        return np.column_stack([self.friction, self.mass_offset, self.com_offset,
                                self.motor_strength]).astype(np.float32)


def draw_physics(cfg: RandomizationConfig, size: int, rng: np.random.Generator) -> PhysicsDraw:
    """The nominal set first, then (randomisation on) ``size`` sampled sets: envs step the
    nominal model until the schedule (``start_after_steps``) lets the others in."""
    nominal = PhysicsDraw(np.ones(1), np.zeros(1), np.zeros((1, 3)), np.ones(1))
    if not cfg.enabled:
        return nominal
    return PhysicsDraw(
        friction=np.concatenate([nominal.friction, rng.uniform(*cfg.friction, size)]),
        mass_offset=np.concatenate([nominal.mass_offset,
                                    rng.uniform(*cfg.base_mass_offset, size)]),
        com_offset=np.concatenate([nominal.com_offset, rng.uniform(
            -cfg.base_com_offset, cfg.base_com_offset, (size, 3))]),
        motor_strength=np.concatenate([nominal.motor_strength,
                                       rng.uniform(*cfg.motor_strength, size)]),
    )


def build_model_pool(model: mujoco.MjModel, base_body: str, draw: PhysicsDraw
                     ) -> list[mujoco.MjModel]:
    """One model copy per draw, with the parameters written in."""
    base = model.body(base_body).id
    robot_geoms = model.geom_priority > 0  # robot colliders (see scene.build_scene)
    pool = []
    for k in range(len(draw.friction)):
        m = copy.deepcopy(model)
        m.geom_friction[robot_geoms, 0] = draw.friction[k]
        m.body_mass[base] += draw.mass_offset[k]
        m.body_ipos[base] += draw.com_offset[k]
        m.actuator_gainprm[:, 0] *= draw.motor_strength[k]
        m.actuator_biasprm[:, 1:3] *= draw.motor_strength[k]
        mujoco.mj_setConst(m, mujoco.MjData(m))  # subtree masses follow the new base mass
        pool.append(m)
    return pool
