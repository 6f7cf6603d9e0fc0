"""HikingEnv's fixed tensors on its device: robot facts, the terrain's grids, the trail
table, the scan pattern, the physics draws. Set once at construction; the term tables in
``mdp/`` read them from the env."""

from __future__ import annotations

import numpy as np
import torch

from legoh.config import RobotConfig
from legoh.envs.mdp import observations, support
from legoh.envs.mdp.spawns import SpawnSupport
from legoh.envs.mdp.state import Grid, TrailTable, as_index
from legoh.envs.scene import feet_rest_height


def set_constants(env, robot: RobotConfig) -> None:
    """Give ``env`` (its scene, terrain, physics draws and config already set) its fixed
    tensors, as attributes of the env's device and dtype."""
    dev, dt, r, tm, scene = env.device, env.dtype, env.robot, env.terrain, env.scene

    def t(x, dtype=dt) -> torch.Tensor:
        return torch.as_tensor(np.asarray(x), device=dev).to(dtype)

    joints = list(r.actuated_joints)
    env.hip_idx = t([joints.index(j) for j in robot.hip_joints], torch.int64)
    env.qpos_adr, env.dof_adr = as_index(scene.qpos_adr), as_index(scene.dof_adr)
    env.default_pose, env.joint_range = t(r.default_pose), t(r.joint_range)
    env.action_scale = t(r.action_scale)
    env.qpos0 = t(scene.model.qpos0)
    env.feet_rest_height = t(feet_rest_height(scene))
    env.trails = TrailTable.from_map(tm)  # numpy, for callers; trails_t on the device
    env.trails_t = env.trails.to(dev, dt)
    env.ground = Grid(tm.heights, tm.origin, tm.resolution, dev, dt)
    env.scan_grid = Grid(scene.scan_heights, tm.origin, tm.resolution, dev, dt)
    env.support, env.clock_grid = support.terrain_fields(scene, env.cfg, dev, dt)
    env.edges = Grid(tm.edge_mask, tm.origin, tm.resolution, dev, dt, torch.bool)
    env.scan_rotor = observations.scan_rotor(observations.scan_points(dev, dt)
                                             / env.scan_grid.res)
    env.goal_offsets = torch.arange(observations.NUM_EXPERT_GOALS, device=dev)
    features = env.physics.as_features()
    if not env.cfg.randomization.observe_physics:  # every robot reads the nominal draw
        features = np.repeat(features[:1], len(features), axis=0)
    env.physics_features = t(features, torch.float32)
    env.push_every = max(1, int(round(env.cfg.randomization.push_interval_s / env.dt)))
    env.spawn_support = SpawnSupport(env)  # where a robot may start along a trail
