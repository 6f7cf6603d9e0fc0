"""HikingEnv: N humanoids hiking the trails of one terrain map, as a TorchRL environment.

The interface (keys in ``legoh.keys``; docs/env.md has shapes, frames and units):

* action (N, A): joint offsets; target = default + action_scale * clip(action).
* observations: proprioception and its history, scandots, privileged state, goal inputs,
  expert near goals, optional depth frames; ``("info", ...)`` signals for metrics and logs.
* ``terminated``: a success or failure term of ``mdp.terminations`` fired (fell);
  ``truncated``: a goal or time-out term fired (reached the terminus, under
  ``env.reach_truncates``; the episode length), or the simulation diverged and was reset.
  ``done`` = either.

The env is orchestration: physics from ``legoh.envs.physics`` (its device is the env's),
one ``StepState`` per step (``mdp.state``), then the term tables of ``mdp.events``,
``mdp.rewards``, ``mdp.terminations`` and ``mdp.observations``, all torch on the device;
its fixed tensors from ``constants``, whether it compiles from ``compilation``.
"""

from __future__ import annotations

import numpy as np
import torch
from tensordict import TensorDictBase
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from legoh import keys
from legoh.config import EnvConfig, RobotConfig, SimConfig, TrailConfig
from legoh.config.env import LevelRule
from legoh.envs.compilation import derivations
from legoh.envs.constants import set_constants
from legoh.envs.mdp import events, observations, rewards
from legoh.envs.mdp.state import AirTime, Goals, Memory, NavProgress, compute_state
from legoh.envs.mdp.terminations import (
    check_terminations,
    diverged_envs,
    no_flags,
    termination_table,
)
from legoh.envs.physics import make_physics, physics_device, sim_options
from legoh.envs.randomization import draw_physics
from legoh.envs.scene import Scene, build_scene
from legoh.envs.terrain import build_terrain_map


class HikingEnv(EnvBase):
    """Batched humanoid hiking; see the module docstring for the interface.

    Args:
        robot: robot config. trail: trail config (which tiles the map holds).
        env: env config. sim: physics timing and backend. num_envs: robots (the batch).
        seed: terrain and env randomness.
        scene: reuse an already built scene (tests and benchmarks build it once).
        evaluation: the benchmark's commands (``make_env`` also sets its reach radius).
    """

    def __init__(self, robot: RobotConfig, trail: TrailConfig, env: EnvConfig,
                 sim: SimConfig, num_envs: int, seed: int = 0, scene: Scene | None = None,
                 evaluation: bool = False) -> None:
        self.scene = scene or build_scene(robot, build_terrain_map(trail, seed), sim.dt,
                                            hfield_chunk=sim.hfield_chunk)
        self.robot, self.terrain = self.scene.robot, self.scene.terrain
        self.physics = draw_physics(env.randomization, env.randomization.pool_size,
                                    np.random.default_rng(seed + 1))
        self.sim = make_physics(sim.backend, self.scene.model, self.robot.base_body,
                                self.physics, num_envs, sim.decimation, sim.threads,
                                physics_device(sim), **sim_options(sim))
        super().__init__(device=self.sim.device, batch_size=torch.Size([num_envs]))
        self.cfg, self.sim_cfg, self.evaluation = env, sim, evaluation
        self.num_envs, self.dtype = num_envs, self.sim.dtype
        self.dt = sim.dt * sim.decimation
        self.max_steps = int(round(env.episode_length_s / self.dt))
        self.num_actions = self.robot.num_actions
        self.num_feet = len(self.robot.feet_bodies)
        self.num_categories = len(self.terrain.categories)
        self.reach_radius = env.reach_radius
        self.gen = torch.Generator(device=self.device).manual_seed(seed)
        self.reward_terms, self.only_positive = rewards.reward_table(
            env, robot, self.robot.nominal_base_height, self.reach_radius)
        self.terminations = termination_table(env.reach_truncates)
        self.depth_cam = (self.sim.make_depth_camera(robot.camera.fovy_deg, env.depth.width,
                                                     env.depth.height, env.depth.far,
                                                     env.depth.backend)
                          if env.depth.enabled else None)
        set_constants(self, robot)
        self._terms()
        self.global_steps = 0  # vectorised steps: the randomisation schedule reads it
        self.randomization = events.RandomizationSchedule(env.randomization,
                                                          self.sim.num_draws)
        self.frame_clock = 0  # one depth clock for all envs
        self.diverged_count = 0
        # envs reset in place by this step's divergence check: torchrl's reset of the
        # truncated envs skips them (one reset per diverged episode, not two)
        self._diverged = torch.zeros(self.num_envs, dtype=torch.bool, device=self.device)
        self._make_specs()
        # what a step and a reset derive from the physics: eager, or one compiled graph each
        self._after_step, self._after_reset = derivations(
            self._derive_step, self._derive_reset, env.compile, self.device, num_envs)

    # ----------------------------------------------------------------- set-up
    def _terms(self) -> None:
        """Per-env bookkeeping and the stateful terms; then the observation table."""
        n, dev, dt, c = self.num_envs, self.device, self.dtype, self.cfg
        self.category = torch.arange(n, device=dev) % self.num_categories
        top = (self.terrain.levels - 1 if c.curriculum.rule == LevelRule.uniform
               else c.curriculum.start_level)
        self.level = (torch.randint(0, top + 1, (n,), generator=self.gen, device=dev)
                      if c.curriculum.enabled else torch.zeros(n, dtype=torch.int64, device=dev))
        self.steps = torch.zeros(n, dtype=torch.int64, device=dev)
        # policy steps until this episode times out; episodes_ended counts each robot's
        # finished episodes (its first ones staggered: env.stagger_timeouts)
        self.horizon = torch.full((n,), self.max_steps, dtype=torch.int64, device=dev)
        self.episodes_ended = torch.zeros(n, dtype=torch.int64, device=dev)
        self.episode_metres = torch.zeros(n, dtype=dt, device=dev)  # keys.EPISODE_METRES
        self.spawned_at = torch.zeros(n, dtype=dt, device=dev)  # m of path behind the spawn
        # the last step's failures (falls): the randomisation gate counts them
        self.fell_last = torch.zeros(n, dtype=torch.bool, device=dev)
        self.ctrl = self.default_pose.expand(n, -1).clone()
        joints = len(self.robot.actuated_joints)
        self.action_delay = events.ActionDelay(n, c.randomization.max_action_delay,
                                               self.num_actions, dev, dt)
        self.memory = Memory(n, self.num_actions, joints, dev, dt)
        self.air_time = AirTime(n, self.num_feet, self.dt, dev, dt)
        self.goals = Goals(n, self.trails_t, c.waypoint_radius, dev, c.waypoint_pass)
        self.nav_progress = NavProgress(n, dev, dt)
        self.command = events.Command(n, c.command, c.goal_speed, self.evaluation, dev, dt)
        self.proprio_dim = 3 + 3 + 3 * self.num_actions + 3 + 2
        self.history = observations.ProprioHistory(n, c.history, self.proprio_dim, dev)
        self.depth = observations.DepthFrames(n, c.depth, dev)
        self.stateful = [self.action_delay, self.memory, self.air_time, self.goals,
                         self.nav_progress, self.command, self.history]
        self.observation_terms = observations.observation_table(self)
        # the terms of the state alone, computed with it by _derive_step and _derive_reset
        self.state_terms = [k for k in self.observation_terms
                            if k not in observations.AFTER_STATE_TERMS]
        self.reward_parts = {k: torch.zeros(n, device=dev) for k in self.reward_terms}

    def _make_specs(self) -> None:
        """Specs from what the tables produce (one dry observation of the initial state)."""
        n, f32, none = self.num_envs, torch.float32, self._diverged
        history = self.history.buf.clone()
        self.state = compute_state(self)
        sample = observations.observe(self, no_flags(self.terminations, none))
        self.history.buf = history
        self.observation_spec = observations.spec_of(sample)
        clip = self.cfg.action_clip
        self.action_spec = Bounded(-clip, clip, shape=(n, self.num_actions), dtype=f32,
                                   device=self.device)
        self.reward_spec = Unbounded(shape=(n, 1), dtype=f32, device=self.device)
        flag = Categorical(2, shape=(n, 1), dtype=torch.bool, device=self.device)
        self.done_spec = Composite(done=flag, terminated=flag.clone(), truncated=flag.clone(),
                                   shape=(n,), device=self.device)

    def _set_seed(self, seed: int | None) -> None:
        self.gen = torch.Generator(device=self.device).manual_seed(seed or 0)

    # ----------------------------------------------------------------- reset
    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        mask = None if tensordict is None else tensordict.get("_reset", None)
        fresh = (torch.ones(self.num_envs, dtype=torch.bool, device=self.device) if mask is None
                 else mask.reshape(self.num_envs).to(self.device) & ~self._diverged)
        self._diverged = torch.zeros_like(fresh)  # those were reset in place by their step
        ids = fresh.nonzero().squeeze(1)
        if len(ids):
            self._reset_envs(ids)
        terms = self._after_reset(fresh)
        return observations.observe(self, no_flags(self.terminations, torch.zeros_like(fresh)),
                                    terms)

    def _derive_reset(self, fresh: torch.Tensor) -> dict:
        """The state after a reset (``fresh`` (N,) bool: the envs reset) and the
        observation terms of the state alone."""
        self.state = compute_state(self)
        self.state.advance = fresh  # only reset envs get a new history entry
        return observations.state_terms(self)

    def _reset_envs(self, ids: torch.Tensor) -> None:
        """The reset events (curriculum, spawn, delay, command), then the stateful terms."""
        for event in events.RESET_EVENTS:
            event(self, ids)
        self.episodes_ended[ids] += (self.steps[ids] > 0).long()
        self.horizon[ids] = self.max_steps
        if self.cfg.stagger_timeouts and not self.evaluation:
            first = ids[self.episodes_ended[ids] == 0]
            self.horizon[first] = torch.randint(1, self.max_steps + 1, (len(first),),
                                                generator=self.gen, device=self.device)
        self.steps[ids] = 0
        self.episode_metres[ids] = 0.0
        for term in self.stateful:
            term.reset(ids)
        if self.depth_cam is not None:
            self.depth.reset(ids, self)

    # ----------------------------------------------------------------- step
    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        action = tensordict.get(keys.ACTION).to(self.device, self.dtype)
        bad = ~torch.isfinite(action).all(1)
        if bad.any():
            raise ValueError(f"non-finite action (NaN or inf) for env indices "
                             f"{bad.nonzero().squeeze(1).tolist()}")
        action = torch.clamp(action, -self.cfg.action_clip, self.cfg.action_clip)
        a = self.num_actions
        self.ctrl[:, :a] = self.default_pose[:a] + self.action_scale * self.action_delay(action)
        for event in events.STEP_EVENTS:
            event(self)
        time_before = self.sim.time.clone()
        self.sim.step(self.ctrl)
        self.steps += 1
        self.global_steps += 1
        self.randomization.step()
        bad = self._diverged = diverged_envs(self, time_before)
        if bad.any():  # reset in place and counted; no curriculum credit for the episode
            ids = bad.nonzero().squeeze(1)
            self.diverged_count += len(ids)
            self.steps[ids] = 0
            self._reset_envs(ids)
        ends, reward, self.reward_parts, terms = self._after_step(action, bad)
        self.fell_last = ends.failed
        self.frame_clock += 1
        due = self.depth_cam is not None and self.frame_clock % self.cfg.depth.every == 0
        self.depth.push(self.depth.render(self) if due else None)
        out = observations.observe(self, {**ends.flags, "diverged": bad}, terms)
        out.set(keys.REWARD, reward.float().unsqueeze(-1))
        out.set(keys.TERMINATED, ends.terminated.unsqueeze(-1))
        out.set(keys.TRUNCATED, ends.truncated.unsqueeze(-1))
        out.set(keys.DONE, (ends.terminated | ends.truncated).unsqueeze(-1))
        return out

    def _derive_step(self, action: torch.Tensor, diverged: torch.Tensor) -> tuple:
        """What a step derives from the physics, pure torch on the env's tensors (one graph
        under ``env.compile``): the state, the termination table, the rewards, the
        bookkeeping, the observation terms of the state alone. Returns (ends, reward, reward parts,
        terms)."""
        s = self.state = compute_state(self, action)
        self.episode_metres += s.path_progress * self.dt
        ends = check_terminations(self.terminations, self, s, diverged)
        s.failed = ends.failed
        reward, parts = rewards.compute_rewards(s, self.reward_terms, self.only_positive)
        self.memory.update(s)
        return ends, reward, parts, observations.state_terms(self)

    # ----------------------------------------------------------------- curriculum state
    def curriculum_state(self) -> dict:
        """What a checkpoint keeps of the env's training schedule: terrain levels and
        categories, the vectorised step counter and the randomisation gate (plain values)."""
        return {"level": self.level.tolist(), "category": self.category.tolist(),
                "global_steps": int(self.global_steps),
                "randomization": self.randomization.state()}

    def set_level(self, level: int | torch.Tensor) -> None:
        """Put every robot (an int) or each robot (an (N,) tensor) on terrain ``level``
        from its next reset: how the benchmark and ``mode=play`` pick the difficulty."""
        self.level[:] = torch.as_tensor(level, device=self.device)

    def load_curriculum_state(self, state: dict) -> None:
        """Set the schedule back to :meth:`curriculum_state`'s ``state`` (a checkpoint
        from before the gate has no ``randomization``: the gate starts closed). A state
        of another number of robots is refused: a run's frame count is iterations x robots
        x steps, so a resumed run keeps its ``algo.num_envs``."""
        if len(state["level"]) != self.num_envs:
            raise ValueError(f"the checkpoint's curriculum holds {len(state['level'])} robots, "
                             f"this env {self.num_envs}: resume with algo.num_envs="
                             f"{len(state['level'])} (a run keeps its number of robots; "
                             "init=<checkpoint> starts a new run from its weights)")
        self.level[:] = torch.as_tensor(state["level"], device=self.device)
        if "category" in state:  # older checkpoints: each robot kept its category
            self.category[:] = torch.as_tensor(state["category"], device=self.device)
        self.global_steps = int(state["global_steps"])
        if "randomization" in state:
            self.randomization.load_state(state["randomization"])

    def close(self, **kwargs) -> None:
        """Stop the physics."""
        self.sim.close()
        super().close(**kwargs)


def make_env(cfg, num_envs: int, evaluation: bool = False, **overrides) -> HikingEnv:
    """HikingEnv of ``num_envs`` robots from a composed run config (``conf/config.yaml``);
    ``evaluation``: the benchmark's commands and reach radius (``eval.reach_radius``);
    overrides go to ``env``."""
    from omegaconf import OmegaConf

    env_cfg: EnvConfig = OmegaConf.to_object(cfg.env)
    if evaluation:
        env_cfg.reach_radius = float(cfg.eval.reach_radius)
    known = set(env_cfg.__dataclass_fields__)  # a typo would otherwise set a dead attribute
    if unknown := sorted(set(overrides) - known):
        raise TypeError(f"make_env: unknown env setting(s) {unknown}; EnvConfig has "
                        f"{sorted(known)}")
    for key, value in overrides.items():
        setattr(env_cfg, key, value)
    return HikingEnv(OmegaConf.to_object(cfg.robot), OmegaConf.to_object(cfg.trail), env_cfg,
                     OmegaConf.to_object(cfg.sim), num_envs, seed=cfg.seed,
                     evaluation=evaluation)
