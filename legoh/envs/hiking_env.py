"""HikingEnv: N humanoids hiking the trails of one terrain map, as a TorchRL environment.

The interface (keys in ``legoh.keys``; docs/env.md has shapes, frames and units):

* action (N, A): joint offsets; target = default + action_scale * clip(action).
* observations: proprioception and its history, scandots, privileged state, goal inputs,
  expert near goals, optional depth frames; ``("info", ...)`` signals for metrics and logs.
* ``terminated``: fell (pose check) or reached the terminus; ``truncated``: timeout or a
  diverged simulation that was reset. ``done`` = either.

Physics runs in ``BatchedSim`` (all envs in one MuJoCo thread-pool call per step);
everything after it is numpy over the whole batch: no per-env Python loop on the step path.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from legoh import keys
from legoh.config import EnvConfig, RobotConfig, SimConfig, TrailConfig
from legoh.config.env import REWARD_PRESETS
from legoh.envs import math3d
from legoh.envs.batched_sim import BatchedSim
from legoh.envs.curriculum import update_levels
from legoh.envs.randomization import build_model_pool, draw_physics
from legoh.envs.rewards import StepState, active_terms, compute_rewards, preset_weights
from legoh.envs.scene import Scene, build_scene
from legoh.envs.sensors import DepthRaycaster
from legoh.envs.terrain import TerrainMap, build_terrain_map
from legoh.envs.terrain.terrain_map import bilinear

# Scandots: Extreme Parkour's 12 x 11 grid in the robot's yaw frame.
SCAN_X = np.linspace(-0.45, 1.2, 12)
SCAN_Y = np.linspace(-0.75, 0.75, 11)
SCAN_XY = np.stack(np.meshgrid(SCAN_X, SCAN_Y, indexing="ij"), -1).reshape(-1, 2)  # (132, 2)
NUM_EXPERT_GOALS = 3
ANG_VEL_SCALE, DOF_VEL_SCALE = 0.25, 0.05  # observation scales (legged_gym)


@dataclass(frozen=True)
class TrailTable:
    """Per-tile trail data as padded arrays, so goals are gathered for all envs at once."""

    waypoints: np.ndarray  # (T, W, 2) world xy, padded with the terminus
    count: np.ndarray  # (T,) real waypoints per tile
    cum_length: np.ndarray  # (T, W) path length from the start to each waypoint, m
    length: np.ndarray  # (T,) m
    start: np.ndarray  # (T, 3)
    start_yaw: np.ndarray  # (T,)
    terminus: np.ndarray  # (T, 2)
    middle: np.ndarray  # (T, 2)
    category: np.ndarray  # (T,) index into the map's categories
    level: np.ndarray  # (T,)
    variant: np.ndarray  # (T,)

    @classmethod
    def from_map(cls, tm: TerrainMap) -> TrailTable:
        width = max(len(t.waypoints) for t in tm.tiles)
        wp = np.zeros((len(tm.tiles), width, 2))
        cum = np.zeros((len(tm.tiles), width))
        for k, t in enumerate(tm.tiles):
            pts = t.waypoints[:, :2]
            wp[k, : len(pts)], wp[k, len(pts):] = pts, pts[-1]
            seg = np.linalg.norm(np.diff(np.vstack([t.start[:2], pts]), axis=0), axis=1)
            cum[k, : len(pts)] = np.cumsum(seg)
            cum[k, len(pts):] = cum[k, len(pts) - 1]
        return cls(
            waypoints=wp, count=np.array([len(t.waypoints) for t in tm.tiles]),
            cum_length=cum, length=cum[np.arange(len(tm.tiles)),
                                       [len(t.waypoints) - 1 for t in tm.tiles]],
            start=np.array([t.start for t in tm.tiles]),
            start_yaw=np.array([t.start_yaw for t in tm.tiles]),
            terminus=np.array([t.terminus[:2] for t in tm.tiles]),
            middle=np.array([t.middle[:2] for t in tm.tiles]),
            category=np.array([tm.categories.index(t.category) for t in tm.tiles]),
            level=np.array([t.level for t in tm.tiles]),
            variant=np.array([t.variant for t in tm.tiles]),
        )


class HikingEnv(EnvBase):
    """Batched humanoid hiking over MuJoCo; see the module docstring for the interface.

    Args:
        robot: robot config. trail: trail config (which tiles the map holds).
        env: env config. sim: physics timing. seed: terrain and env randomness.
        scene: reuse an already built scene (tests and benchmarks build it once).
    """

    def __init__(self, robot: RobotConfig, trail: TrailConfig, env: EnvConfig,
                 sim: SimConfig, seed: int = 0, scene: Scene | None = None,
                 evaluation: bool = False) -> None:
        super().__init__(device="cpu", batch_size=torch.Size([env.num_envs]))
        self.cfg, self.sim_cfg, self.evaluation = env, sim, evaluation
        self.num_envs = n = env.num_envs
        self.dt = sim.dt * sim.decimation
        self.max_steps = int(round(env.episode_length_s / self.dt))
        self.scene = scene or build_scene(robot, build_terrain_map(trail, seed), sim.dt,
                                            hfield_chunk=sim.hfield_chunk)
        self.robot = self.scene.robot
        self.terrain = self.scene.terrain
        self.trails = TrailTable.from_map(self.terrain)
        self.num_actions = self.robot.num_actions
        self.num_categories = len(self.terrain.categories)
        self.rng = np.random.default_rng(seed)

        self.reward_terms = active_terms(preset_weights(env.reward_preset, dict(env.rewards),
                                                        dict(robot.table6_weights)))
        _, clip_total, penalty = REWARD_PRESETS[env.reward_preset]
        self.only_positive = clip_total if env.only_positive_rewards is None else bool(
            env.only_positive_rewards)
        self.termination_penalty = penalty if env.termination_penalty is None else float(
            env.termination_penalty)
        joints = list(self.robot.actuated_joints)
        self.hip_idx = np.array([joints.index(j) for j in robot.hip_joints], dtype=np.int64)

        rcfg = env.randomization
        self.physics = draw_physics(rcfg, rcfg.pool_size, np.random.default_rng(seed + 1))
        self.physics_features = self.physics.as_features()
        pool = build_model_pool(self.scene.model, self.robot.base_body, self.physics)
        self.sim = BatchedSim(pool, n, sim.decimation, sim.threads)
        self.depth_cam = None
        if env.depth.enabled:
            import mujoco

            self._world_data = mujoco.MjData(self.scene.model)
            mujoco.mj_forward(self.scene.model, self._world_data)
            self.depth_cam = DepthRaycaster(self.scene.model, robot.camera.fovy_deg,
                                            env.depth.width, env.depth.height, env.depth.far,
                                            sim.threads)
        self._alloc_buffers()
        self._make_specs()
        self.feet_rest_height = self._feet_rest_height()
        # vectorised steps (one per step of the whole batch, legged_gym's common_step_counter):
        # the randomisation schedule reads it, checkpoints keep it
        self.global_steps = 0
        self.frame_clock = 0
        self.diverged_count = 0
        # envs reset in place by this step's divergence check: torchrl's reset of the
        # truncated envs skips them (one reset per diverged episode, not two)
        self._diverged = np.zeros(self.num_envs, dtype=bool)

    # ----------------------------------------------------------------- set-up
    def _alloc_buffers(self) -> None:
        n, a, j = self.num_envs, self.num_actions, len(self.robot.actuated_joints)
        nf = len(self.robot.feet_bodies)
        self.category = np.arange(n) % self.num_categories
        cur = self.cfg.curriculum
        self.level = (self.rng.integers(0, cur.start_level + 1, n) if cur.enabled
                      else np.zeros(n, dtype=np.int64))
        self.tile = np.zeros(n, dtype=np.int64)
        self.waypoint = np.zeros(n, dtype=np.int64)
        self.steps = np.zeros(n, dtype=np.int64)
        self.action_buf = np.zeros((n, self.cfg.randomization.max_action_delay + 1, a))
        self.delay = np.zeros(n, dtype=np.int64)
        self.last_action = np.zeros((n, a))
        self.last_dof_vel = np.zeros((n, j))
        self.last_torques = np.zeros((n, j))
        self.air_time = np.zeros((n, nf))
        self.ctrl = np.tile(self.robot.default_pose, (n, 1))
        self.proprio_dim = 3 + 3 + 3 * a + 3 + 2
        self.history = np.zeros((n, self.cfg.history, self.proprio_dim), dtype=np.float32)
        d = self.cfg.depth
        self.depth = np.zeros((n, d.frames, d.height, d.width), dtype=np.float32)
        self.depth_fresh = np.zeros(n, dtype=bool)  # a frame was rendered on this step
        self.command_speed = np.zeros(n)  # m/s, drawn per episode
        self.command = np.zeros((n, 2))  # forward speed, yaw rate toward the next waypoint
        self.push_every = max(1, int(round(self.cfg.randomization.push_interval_s / self.dt)))

    def _make_specs(self) -> None:
        n, a = self.num_envs, self.num_actions
        f32 = torch.float32

        def vec(*shape: int) -> Unbounded:
            return Unbounded(shape=(n, *shape), dtype=f32)

        def flag(dtype: torch.dtype = torch.bool) -> Categorical:
            return Categorical(2, shape=(n,), dtype=dtype)

        obs = {
            "proprio": vec(self.proprio_dim),
            "proprio_history": vec(self.cfg.history, self.proprio_dim),
            "scandots": vec(len(SCAN_X) * len(SCAN_Y)),
            "privileged": vec(self.physics_features.shape[1] + 3 + self.num_categories),
            "goal": vec(4),
            "command": vec(2),
        }
        if self.cfg.depth.enabled:
            d = self.cfg.depth
            obs["depth"] = Bounded(-0.5, 0.5, shape=(n, d.frames, d.height, d.width), dtype=f32)
            obs["depth_fresh"] = Categorical(2, shape=(n, 1), dtype=torch.bool)
        info = {
            "reached": flag(), "fell": flag(),
            "diverged": flag(),  # keys.DIVERGED, set by _step and _reset
            "waypoint": Unbounded(shape=(n,), dtype=torch.int64),
            "episode_steps": Unbounded(shape=(n,), dtype=torch.int64),
            "progress": Unbounded(shape=(n,), dtype=f32),
            "edge_contacts": Unbounded(shape=(n,), dtype=torch.int64),
            "foot_contacts": Unbounded(shape=(n,), dtype=torch.int64),
            "unsafe_collisions": Unbounded(shape=(n,), dtype=torch.int64),
            "level": Unbounded(shape=(n,), dtype=torch.int64),
            "category": Unbounded(shape=(n,), dtype=torch.int64),
            "tile": Unbounded(shape=(n,), dtype=torch.int64),
            "waypoint_count": Unbounded(shape=(n,), dtype=torch.int64),
            "base_pos": Unbounded(shape=(n, 3), dtype=f32),
            "base_quat": Unbounded(shape=(n, 4), dtype=f32),
            "reward_terms": Composite({k: Unbounded(shape=(n,), dtype=f32)
                                       for k in self.reward_terms}, shape=(n,)),
        }
        self.observation_spec = Composite(
            obs=Composite(obs, shape=(n,)),
            expert=Composite(goals=vec(NUM_EXPERT_GOALS, 2), shape=(n,)),
            info=Composite(info, shape=(n,)),
            shape=(n,),
        )
        clip = self.cfg.action_clip
        self.action_spec = Bounded(-clip, clip, shape=(n, a), dtype=f32)
        self.reward_spec = Unbounded(shape=(n, 1), dtype=f32)
        self.done_spec = Composite(
            done=Categorical(2, shape=(n, 1), dtype=torch.bool),
            terminated=Categorical(2, shape=(n, 1), dtype=torch.bool),
            truncated=Categorical(2, shape=(n, 1), dtype=torch.bool),
            shape=(n,),
        )

    def _set_seed(self, seed: int | None) -> None:
        self.rng = np.random.default_rng(seed)

    # ----------------------------------------------------------------- reset
    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        mask = None if tensordict is None else tensordict.get("_reset", None)
        ids = (np.arange(self.num_envs) if mask is None
               else np.flatnonzero(mask.reshape(self.num_envs).numpy()))
        if mask is not None:
            ids = ids[~self._diverged[ids]]  # already reset in place by their step
        self._diverged = np.zeros(self.num_envs, dtype=bool)
        if len(ids):
            self._reset_envs(ids)
        none = np.zeros(self.num_envs, dtype=bool)
        fresh = none.copy()
        fresh[ids] = True  # only reset envs get a new history entry; the others keep theirs
        self._update_base()
        self._update_command()
        out = self._observe(none, none, fresh)
        out.set(keys.DIVERGED, torch.as_tensor(none))
        return out

    def _reset_envs(self, ids: np.ndarray) -> None:
        """Curriculum update for finished episodes, then a new tile, pose and model."""
        if self.cfg.curriculum.enabled and self.steps[ids].any():
            done = ids[self.steps[ids] > 0]
            covered = self._progress(done) * self.trails.length[self.tile[done]]
            expected = np.minimum(self.trails.length[self.tile[done]],
                                  self.cfg.goal_speed * self.cfg.episode_length_s)
            self.level[done] = update_levels(
                self.level[done], covered, expected, self._reached(done),
                self.terrain.levels, self.rng, self.cfg.curriculum.up, self.cfg.curriculum.down)
        k = len(ids)
        variant = self.rng.integers(0, self.terrain.variants, k)
        self.tile[ids] = ((self.category[ids] * self.terrain.levels + self.level[ids])
                          * self.terrain.variants + variant)
        tiles = self.tile[ids]
        start = self.trails.start[tiles].copy()
        start[:, :2] += self.rng.uniform(-1, 1, (k, 2)) * self.cfg.spawn_noise
        start[:, 2] = self.terrain.height_at(start[:, :2]) + self.scene.stand_height + 0.02
        yaw = self.trails.start_yaw[tiles] + self.rng.uniform(-0.3, 0.3, k)

        model = self.scene.model
        qpos = np.tile(model.qpos0, (k, 1))
        qpos[:, 0:3] = start
        qpos[:, 3:7] = np.column_stack([np.cos(yaw / 2), np.zeros(k), np.zeros(k),
                                        np.sin(yaw / 2)])
        qpos[:, self.scene.qpos_adr] = self.robot.default_pose
        self.ctrl[ids] = self.robot.default_pose
        # pool model 0 is the nominal one; the randomised ones 1.. join on schedule
        drawn = (self.rng.integers(1, len(self.sim.models), k) if self._randomizing()
                 else np.zeros(k, dtype=np.int64))
        self.sim.set_models(ids, drawn)
        self.sim.reset_envs(ids, qpos, np.zeros((k, model.nv)), self.ctrl[ids])

        rc = self.cfg.randomization
        max_delay = (rc.max_action_delay if rc.enabled
                     and self.global_steps >= rc.delay_after_steps else 0)
        self.delay[ids] = self.rng.integers(0, max_delay + 1, k)
        cmd = self.cfg.command
        if self.evaluation:
            self.command_speed[ids] = self.cfg.goal_speed
        else:
            speed = self.rng.uniform(cmd.speed[0], cmd.speed[1], k)
            self.command_speed[ids] = np.where(self.rng.random(k) < cmd.zero_prob, 0.0, speed)
        self.waypoint[ids] = 0
        self.steps[ids] = 0
        for buf in (self.action_buf, self.last_action, self.last_dof_vel, self.last_torques,
                    self.air_time, self.history):
            buf[ids] = 0
        if self.depth_cam is not None:
            self.depth[ids] = self._render_depth(ids)[:, None]
            self.depth_fresh[ids] = True

    def _randomizing(self) -> bool:
        """Physics draws and pushes are on: randomisation enabled and its start passed."""
        rc = self.cfg.randomization
        return rc.enabled and len(self.sim.models) > 1 and (
            self.global_steps >= rc.start_after_steps)

    def _feet_rest_height(self) -> np.ndarray:
        """(F,) height of each foot body's origin above flat ground in the default pose: the
        zero of the swing-height term's foot lift."""
        import mujoco

        model, d = self.scene.model, mujoco.MjData(self.scene.model)
        d.qpos[:] = model.qpos0
        d.qpos[0:3] = [0.0, 0.0, self.scene.stand_height]
        d.qpos[3:7] = [1.0, 0.0, 0.0, 0.0]
        d.qpos[self.scene.qpos_adr] = self.robot.default_pose
        mujoco.mj_kinematics(model, d)
        ids = [model.body(b).id for b in self.robot.feet_bodies]
        return d.xpos[ids, 2].copy()

    def _update_command(self) -> None:
        """Forward speed of the episode; yaw rate steering toward the current waypoint."""
        pos, _, yaw = self._base()
        d = self._waypoint_xy(0) - pos[:, :2]
        err = (np.arctan2(d[:, 1], d[:, 0]) - yaw + np.pi) % (2 * np.pi) - np.pi
        cmd = self.cfg.command
        rate = np.clip(cmd.heading_gain * err, -cmd.max_yaw_rate, cmd.max_yaw_rate)
        self.command[:, 0] = self.command_speed
        self.command[:, 1] = np.where(self.command_speed > 0, rate, 0.0)

    def _gait_phase(self) -> np.ndarray:
        """(N, F) phase in [0, 1) of each leg's cycle, legs half a period apart."""
        t = self.steps * self.dt / self.cfg.gait.period
        offsets = np.arange(len(self.robot.feet_bodies)) / len(self.robot.feet_bodies)
        return (t[:, None] + offsets[None]) % 1.0

    # ----------------------------------------------------------------- step
    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        action = tensordict.get(keys.ACTION).detach().cpu().numpy().astype(np.float64)
        bad = ~np.isfinite(action).all(axis=1)
        if bad.any():
            raise ValueError(f"non-finite action (NaN or inf) for env indices "
                             f"{np.flatnonzero(bad).tolist()}")
        clip = self.cfg.action_clip
        action = np.clip(action, -clip, clip)
        self.action_buf = np.roll(self.action_buf, 1, axis=1)
        self.action_buf[:, 0] = action
        applied = self.action_buf[np.arange(self.num_envs), self.delay]
        a = self.num_actions
        self.ctrl[:, :a] = self.robot.default_pose[:a] + self.robot.action_scale * applied

        self._maybe_push()
        time_before = self.sim.state[:, 0].copy()
        self.sim.step(self.ctrl)
        self.steps += 1
        self.global_steps += 1

        diverged = self._handle_divergence(time_before)
        self._update_base()
        state = self._step_state(action)
        reward, parts = compute_rewards(state, self.reward_terms)
        if self.only_positive:
            reward = np.maximum(reward, 0.0)
        self._last_parts = parts
        reached = self._reached()
        fell = self._fell(state) & ~diverged
        timeout = self.steps >= self.max_steps
        terminated = (reached | fell) & ~diverged
        reward = reward + self.termination_penalty * self.dt * (fell & ~reached)
        truncated = (timeout | diverged) & ~terminated

        self.last_action = action
        self.last_dof_vel = state.dof_vel
        self.last_torques = state.torques.copy()  # sensordata is overwritten in place
        self.frame_clock += 1  # one clock for all envs: every env gets a frame on the same step
        self.depth_fresh[:] = False
        if self.depth_cam is not None and self.frame_clock % self.cfg.depth.every == 0:
            frame = self._render_depth(np.arange(self.num_envs))
            self.depth = np.concatenate([self.depth[:, 1:], frame[:, None]], axis=1)
            self.depth_fresh[:] = True
        out = self._observe(reached, fell)
        out.set(keys.DIVERGED, torch.as_tensor(diverged))
        out.set(keys.EPISODE_STEPS, torch.as_tensor(self.steps.copy()))
        out.set(keys.REWARD, torch.as_tensor(reward, dtype=torch.float32).unsqueeze(-1))
        out.set(keys.TERMINATED, torch.as_tensor(terminated).unsqueeze(-1))
        out.set(keys.TRUNCATED, torch.as_tensor(truncated).unsqueeze(-1))
        out.set(keys.DONE, torch.as_tensor(terminated | truncated).unsqueeze(-1))
        return out

    def _maybe_push(self) -> None:
        """Appendix Table 5: every push interval, a random base xy velocity kick."""
        rc = self.cfg.randomization
        if self._randomizing() and rc.push_max_vel > 0:
            due = (self.steps > 0) & (self.steps % self.push_every == 0)
            if due.any():
                kick = self.rng.uniform(-rc.push_max_vel, rc.push_max_vel, (int(due.sum()), 2))
                self.sim.qvel[due, 0:2] += kick

    def _handle_divergence(self, time_before: np.ndarray) -> np.ndarray:
        """Envs whose state went non-finite or exploded are reset and counted. MuJoCo itself
        resets an MjData whose qpos/qvel/qacc went bad (time restarts at 0, the robot jumps
        to qpos0), so a step that did not advance time counts as diverged too."""
        qvel = self.sim.qvel
        mujoco_reset = self.sim.state[:, 0] < time_before + 0.5 * self.dt
        bad = mujoco_reset | ~np.isfinite(self.sim.state).all(axis=1) | (
            np.abs(np.nan_to_num(qvel, nan=np.inf)) > self.cfg.divergence_qvel).any(axis=1)
        if bad.any():
            ids = np.flatnonzero(bad)
            self.diverged_count += len(ids)
            self.steps[ids] = 0  # no curriculum credit for a diverged episode
            self._reset_envs(ids)
        self._diverged = bad
        return bad

    # ----------------------------------------------------------------- state
    def _update_base(self) -> None:
        """Base position (N, 3), rotation (N, 3, 3) and yaw (N,) of the current physics
        state, computed once after each step or reset and read by everything after it."""
        qpos = self.sim.qpos
        rot = math3d.quat_to_mat(qpos[:, 3:7])
        self._kin = (qpos[:, 0:3].copy(), rot, math3d.roll_pitch_yaw(rot)[2])

    def _base(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self._kin

    def _step_state(self, action: np.ndarray) -> StepState:
        """Derived quantities for rewards, plus the step's bookkeeping (air time, waypoints)."""
        sd, sl = self.sim.sensordata, self.scene.sensors
        pos, rot, yaw = self._base()
        qvel = self.sim.qvel
        nf = len(self.robot.feet_bodies)
        contact = sd[:, :, sl.feet_contact].reshape(self.num_envs, -1, nf, 4)
        force_all = contact[..., 1:4]
        strongest = np.argmax(np.linalg.norm(force_all, axis=-1), axis=1)  # (N, F) substep
        force = np.take_along_axis(force_all, strongest[:, None, :, None], axis=1)[:, 0]
        in_contact = (contact[..., 0] > 0).any(axis=1)
        first = in_contact & (self.air_time > 0)
        air = np.where(first, self.air_time + self.dt, 0.0)
        self.air_time = np.where(in_contact, 0.0, self.air_time + self.dt)
        feet_xy = sd[:, -1, sl.feet_pos].reshape(self.num_envs, nf, 3)[..., :2]
        on_edge = in_contact & self._edge_at(feet_xy)
        self._advance_waypoints(pos[:, :2])
        self._update_command()
        ground = self.terrain.height_at(pos[:, :2])
        feet_z = sd[:, -1, sl.feet_pos].reshape(self.num_envs, nf, 3)[..., 2]
        lift = feet_z - self.terrain.height_at(feet_xy.reshape(-1, 2)).reshape(
            self.num_envs, nf) - self.feet_rest_height
        standing = self.command_speed[:, None] == 0
        gait = self.cfg.gait
        phase = self._gait_phase()
        stance = (phase < gait.stance) | standing
        swing = np.clip((phase - gait.stance) / (1.0 - gait.stance), 0.0, 1.0)
        target = np.where(stance, 0.0, gait.swing_height * np.sin(np.pi * swing))
        return StepState(
            dt=self.dt,
            lin_vel_body=math3d.world_to_body(rot, qvel[:, 0:3]),
            ang_vel_body=qvel[:, 3:6].copy(),
            gravity_body=math3d.world_to_body(rot, np.tile([0.0, 0.0, -1.0],
                                                           (self.num_envs, 1))),
            lin_vel_world=qvel[:, 0:3].copy(),
            base_xy=pos[:, :2].copy(), yaw=yaw, base_height=pos[:, 2] - ground,
            target_height=self.robot.nominal_base_height,
            dof_pos=self.sim.qpos[:, self.scene.qpos_adr],
            dof_vel=qvel[:, self.scene.dof_adr],
            last_dof_vel=self.last_dof_vel, default_pose=self.robot.default_pose,
            joint_range=self.robot.joint_range, hip_idx=self.hip_idx,
            torques=sd[:, -1, sl.torques], last_torques=self.last_torques,
            action=action, last_action=self.last_action,
            waypoint_xy=self._waypoint_xy(0), terminus_xy=self.trails.terminus[self.tile],
            goal_speed=self.cfg.goal_speed, reach_radius=self._reach_radius(),
            feet_force=force, feet_contact=in_contact, first_contact=first, air_time=air,
            air_time_target=self.cfg.air_time_target, feet_on_edge=on_edge,
            unsafe_contacts=(sd[:, :, sl.unsafe_found] > 0).any(axis=1).sum(axis=1),
            level=self.level, command=self.command.copy(),
            tracking_sigma=self.cfg.tracking_sigma, stance=stance, feet_height=lift,
            swing_height=gait.swing_height, swing_target=target,
        )

    def _edge_at(self, xy: np.ndarray) -> np.ndarray:
        tm = self.terrain
        ij = np.rint((xy - tm.origin) / tm.resolution).astype(np.int64)
        i = np.clip(ij[..., 0], 0, tm.edge_mask.shape[0] - 1)
        j = np.clip(ij[..., 1], 0, tm.edge_mask.shape[1] - 1)
        return tm.edge_mask[i, j]

    def _reach_radius(self) -> float:
        return 0.89 if self.evaluation else self.cfg.reach_radius

    def _waypoint_xy(self, ahead: int) -> np.ndarray:
        """(N, 2) world xy of the expert waypoint ``ahead`` places past the current one."""
        last = self.trails.count[self.tile] - 1
        idx = np.minimum(self.waypoint + ahead, last)
        return self.trails.waypoints[self.tile, idx]

    def _advance_waypoints(self, base_xy: np.ndarray) -> None:
        last = self.trails.count[self.tile] - 1
        near = np.linalg.norm(self._waypoint_xy(0) - base_xy, axis=1) < self.cfg.waypoint_radius
        self.waypoint = np.where(near & (self.waypoint < last), self.waypoint + 1, self.waypoint)

    def _reached(self, ids: np.ndarray | None = None) -> np.ndarray:
        ids = np.arange(self.num_envs) if ids is None else ids
        base = self.sim.qpos[ids, 0:2]
        return np.linalg.norm(self.trails.terminus[self.tile[ids]] - base, axis=1) < (
            self._reach_radius())

    def _progress(self, ids: np.ndarray | None = None) -> np.ndarray:
        """Fraction of the trail covered: path length to the current waypoint minus the
        remaining straight-line distance to it, over the trail length."""
        ids = np.arange(self.num_envs) if ids is None else ids
        tile, wp = self.tile[ids], self.waypoint[ids]
        to_wp = np.linalg.norm(self.trails.waypoints[tile, wp] - self.sim.qpos[ids, 0:2], axis=1)
        done = self.trails.cum_length[tile, wp] - to_wp
        return np.clip(done / np.maximum(self.trails.length[tile], 1e-6), 0.0, 1.0)

    def _fell(self, s: StepState) -> np.ndarray:
        _, rot, _ = self._base()
        roll, pitch, _ = math3d.roll_pitch_yaw(rot)
        low = s.base_height < self.cfg.min_base_height * self.robot.nominal_base_height
        return (np.abs(roll) > self.cfg.max_roll) | (np.abs(pitch) > self.cfg.max_pitch) | low

    def _render_depth(self, ids: np.ndarray) -> np.ndarray:
        """Normalised depth frames (len(ids), H, W) in [-0.5, 0.5] (0.5 = far)."""
        sd, sl = self.sim.sensordata, self.scene.sensors
        cam_pos = sd[ids, -1, sl.camera_pos]
        cam_mat = math3d.quat_to_mat(sd[ids, -1, sl.camera_quat])
        depth = self.depth_cam.render(self._world_data, cam_pos, cam_mat)
        return (depth / self.cfg.depth.far - 0.5).astype(np.float32)

    # ----------------------------------------------------------------- observations
    def _observe(self, reached: np.ndarray, fell: np.ndarray,
                 advance: np.ndarray | None = None) -> TensorDict:
        """Observations of all envs; ``advance`` (N,) bool: whose history takes the new
        proprioception (default all)."""
        n = self.num_envs
        pos, rot, yaw = self._base()
        qvel = self.sim.qvel
        dof_pos = self.sim.qpos[:, self.scene.qpos_adr]
        dof_vel = qvel[:, self.scene.dof_adr]
        a = self.num_actions
        terminus = math3d.to_yaw_frame(self.trails.terminus[self.tile][:, None], pos[:, :2],
                                       yaw)[:, 0]
        middle = math3d.to_yaw_frame(self.trails.middle[self.tile][:, None], pos[:, :2],
                                     yaw)[:, 0]
        dist = np.linalg.norm(terminus, axis=1, keepdims=True)
        clock = 2 * np.pi * self._gait_phase()[:, :1]  # left leg's phase
        gravity = math3d.world_to_body(rot, np.tile([0.0, 0.0, -1.0], (n, 1)))
        proprio = np.concatenate([
            qvel[:, 3:6] * ANG_VEL_SCALE,
            gravity,
            (dof_pos - self.robot.default_pose)[:, :a],
            dof_vel[:, :a] * DOF_VEL_SCALE,
            self.last_action,
            terminus / np.maximum(dist, 1e-6),  # direction to the terminus (yaw frame)
            np.minimum(dist, 20.0) / 20.0,  # distance, normalised and capped at 20 m
            np.sin(clock), np.cos(clock),  # the gait clock: a deployable input, students too
        ], axis=1).astype(np.float32)
        shifted = np.concatenate([self.history[:, 1:], proprio[:, None]], axis=1)
        self.history = shifted if advance is None else np.where(advance[:, None, None],
                                                                shifted, self.history)

        scan_xy = SCAN_XY
        c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
        world = np.stack([pos[:, 0:1] + c * scan_xy[:, 0] - s * scan_xy[:, 1],
                          pos[:, 1:2] + s * scan_xy[:, 0] + c * scan_xy[:, 1]], -1)
        heights = bilinear(self.scene.scan_heights, self.terrain.origin,
                            self.terrain.resolution, world)
        scandots = np.clip(pos[:, 2:3] - self.robot.nominal_base_height - heights, -1.0, 1.0)

        category = np.eye(self.num_categories, dtype=np.float32)[self.category]
        privileged = np.concatenate([
            self.physics_features[self.sim.model_of_env],
            math3d.world_to_body(rot, qvel[:, 0:3]),
            category,
        ], axis=1).astype(np.float32)

        last = self.trails.count[self.tile] - 1
        idx = np.minimum(self.waypoint[:, None] + np.arange(NUM_EXPERT_GOALS), last[:, None])
        ahead = self.trails.waypoints[self.tile[:, None], idx]
        expert = math3d.to_yaw_frame(ahead, pos[:, :2], yaw)
        nf = len(self.robot.feet_bodies)
        sd, sl = self.sim.sensordata, self.scene.sensors
        in_contact = (sd[:, :, sl.feet_contact].reshape(n, -1, nf, 4)[..., 0] > 0).any(axis=1)
        feet_xy = sd[:, -1, sl.feet_pos].reshape(n, nf, 3)[..., :2]
        parts = getattr(self, "_last_parts", {})

        def t(x: np.ndarray, dtype: torch.dtype = torch.float32) -> torch.Tensor:
            return torch.tensor(np.asarray(x), dtype=dtype)  # a copy: buffers change in place

        obs = {"proprio": t(proprio), "proprio_history": t(self.history),
               "scandots": t(scandots), "privileged": t(privileged),
               "goal": t(np.concatenate([terminus, middle], axis=1)),
               "command": t(self.command)}
        if self.depth_cam is not None:
            obs["depth"] = t(self.depth)
            obs["depth_fresh"] = t(self.depth_fresh[:, None], torch.bool)
        i64 = torch.int64
        info = {
            "reached": t(reached, torch.bool), "fell": t(fell, torch.bool),
            "waypoint": t(self.waypoint, i64), "progress": t(self._progress()),
            "episode_steps": t(self.steps, i64),
            "edge_contacts": t((in_contact & self._edge_at(feet_xy)).sum(axis=1), i64),
            "foot_contacts": t(in_contact.sum(axis=1), i64),
            "unsafe_collisions": t((sd[:, :, sl.unsafe_found] > 0).any(axis=1).sum(axis=1), i64),
            "level": t(self.level, i64), "category": t(self.category, i64),
            "tile": t(self.tile, i64), "waypoint_count": t(self.trails.count[self.tile], i64),
            "base_pos": t(pos), "base_quat": t(self.sim.qpos[:, 3:7]),
            "reward_terms": TensorDict({k: t(parts.get(k, np.zeros(n)))
                                        for k in self.reward_terms}, batch_size=[n]),
        }
        return TensorDict({"obs": TensorDict(obs, batch_size=[n]),
                           "expert": TensorDict({"goals": t(expert)}, batch_size=[n]),
                           "info": TensorDict(info, batch_size=[n])}, batch_size=[n])

    def close(self, **kwargs) -> None:
        """Stop the physics thread pool."""
        self.sim.close()
        super().close(**kwargs)


def make_env(cfg, num_envs: int | None = None, evaluation: bool = False, **overrides
             ) -> HikingEnv:
    """HikingEnv from a composed run config (``conf/config.yaml``); overrides go to ``env``."""
    from omegaconf import OmegaConf

    env_cfg: EnvConfig = OmegaConf.to_object(cfg.env)
    if num_envs is not None:
        env_cfg.num_envs = num_envs
    known = set(env_cfg.__dataclass_fields__)  # a typo would otherwise set a dead attribute
    if unknown := sorted(set(overrides) - known):
        raise TypeError(f"make_env: unknown env setting(s) {unknown}; EnvConfig has "
                        f"{sorted(known)}")
    for key, value in overrides.items():
        setattr(env_cfg, key, value)
    return HikingEnv(OmegaConf.to_object(cfg.robot), OmegaConf.to_object(cfg.trail), env_cfg,
                     OmegaConf.to_object(cfg.sim), seed=cfg.seed, evaluation=evaluation)
