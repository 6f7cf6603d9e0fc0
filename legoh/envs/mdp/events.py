"""Events: what happens to envs at a reset (curriculum, spawn, physics draw, delay,
command) and during the step (pushes, the action delay). ``RESET_EVENTS`` run in order on
the envs being reset; ``STEP_EVENTS`` before each physics step. Randomness comes from the
env's ``torch.Generator`` (``env.gen``), on the env's device.
"""

from __future__ import annotations

from collections.abc import Callable

import torch

from legoh.config.env import LevelRule
from legoh.envs.curriculum import lagging_categories, update_levels
from legoh.envs.math3d import wrap_angle
from legoh.envs.mdp.spawns import (  # noqa: F401 (spawn_waypoint: re-exported for callers)
    SPAWN_LIFT,
    SPAWN_YAW_NOISE,
    spawn_waypoint,
    trail_spawn,
    uniform,
)

# m of expert path a training robot spawned along the trail has left at least: room to
# cross what lies ahead before the terminus
ALONG_MIN_LEFT = 2.0


def randomizing(env) -> bool:
    """Physics draws and pushes are on (the randomisation strength is above 0)."""
    return env.randomization.strength(env.global_steps) > 0.0


class RandomizationSchedule:
    """The randomisation strength s in [0, 1] and the gate that raises it
    (``RandomizationConfig``): state the env owns and checkpoints carry.

    ``survival``: the share of training episodes ended within about the last
    ``gate_window`` vectorised steps that were not falls (exponentially weighted counts, so
    the burst of time-outs when a synchronised first episode ends weighs by its share, not
    by its order). ``ramp``: s under the gate schedule, raised by :meth:`step` while
    ``survival >= gate``, never lowered.
    """

    def __init__(self, cfg, num_draws: int) -> None:
        self.cfg = cfg
        self.active = cfg.enabled and num_draws > 1
        self.ramp = 0.0
        self.alive = 0.0  # weighted count of recent ended episodes that were not falls
        self.ended = 0.0  # weighted count of recent ended episodes

    @property
    def survival(self) -> float:
        return self.alive / self.ended if self.ended > 0 else 0.0

    def strength(self, global_steps: int) -> float:
        """s at vectorised step ``global_steps``."""
        if not self.active:
            return 0.0
        if self.cfg.schedule == "steps":
            return float(global_steps >= self.cfg.start_after_steps)
        return self.ramp

    def delay_on(self, global_steps: int) -> float:
        """Probability that a reset env gets an action delay."""
        if not self.active:
            return 0.0
        if self.cfg.schedule == "steps":
            return float(global_steps >= self.cfg.delay_after_steps)
        return self.ramp

    def episodes_ended(self, fell: torch.Tensor) -> None:
        """Count ended training episodes (``fell``: (k,) bool)."""
        self.ended += float(fell.numel())
        self.alive += float((~fell).sum())

    def step(self) -> None:
        """One vectorised step: the counts decay; the ramp advances while the gate is open."""
        keep = 1.0 - 1.0 / self.cfg.gate_window
        self.alive, self.ended = self.alive * keep, self.ended * keep
        if self.active and self.cfg.schedule == "gate" and self.survival >= self.cfg.gate:
            self.ramp = min(1.0, self.ramp + 1.0 / self.cfg.ramp_steps)

    def state(self) -> dict[str, float]:
        return {"ramp": self.ramp, "alive": self.alive, "ended": self.ended}

    def load_state(self, state: dict) -> None:
        self.ramp = float(state["ramp"])
        self.alive, self.ended = float(state.get("alive", 0.0)), float(state.get("ended", 0.0))


def chance(env, p: float, k: int) -> torch.Tensor:
    """(k,) bool, each True with probability ``p`` (from the env's generator)."""
    if p <= 0.0:
        return torch.zeros(k, dtype=torch.bool, device=env.device)
    return uniform(env, 0.0, 1.0, k) < p


# ------------------------------------------------------------------ reset events
def gate(env, ids: torch.Tensor) -> None:
    """Ended training episodes (falls or not) feed the randomisation gate."""
    if env.evaluation:
        return
    done = ids[env.steps[ids] > 0]
    env.randomization.episodes_ended(env.fell_last[done])


def curriculum(env, ids: torch.Tensor) -> None:
    """Appendix 6.2.1: finished episodes move their env's level up or down. The expected
    distance is the episode's commanded speed times the episode length (capped at the
    trail's length), as the appendix says; an episode told to stand keeps its level. Under
    ``rule=uniform`` every finished episode draws its next level uniformly instead. With
    ``curriculum.lagging_mix`` a share of finished episodes moves to a lagging category
    (``curriculum.lagging_categories``)."""
    cur = env.cfg.curriculum
    if not cur.enabled:
        return
    if cur.rule == LevelRule.uniform:
        done = ids[env.steps[ids] > 0]
        env.level[done] = torch.randint(0, env.terrain.levels, (len(done),), generator=env.gen,
                                        device=env.device)
        return
    done = ids[(env.steps[ids] > 0) & (env.command.speed[ids] > 0)]
    if len(done):
        levels_from_distance(env, done, cur)
    if cur.lagging_mix > 0 and env.num_categories > 1 and not env.evaluation:
        ended = ids[env.steps[ids] > 0]
        env.category[ended], env.level[ended] = lagging_categories(
            env.category, env.level, ended, env.num_categories, env.terrain.levels,
            cur.lagging_mix, env.gen)


def levels_from_distance(env, done: torch.Tensor, cur) -> None:
    """Appendix 6.2.1's rule for the ended episodes ``done``: up or down by the distance
    covered from the spawn point against the commanded speed's."""
    t = env.trails_t
    tile = env.goals.tile[done]
    start = env.spawned_at[done]  # m of path behind the spawn point
    covered = env.goals.progress(env.sim.qpos[:, 0:2])[done] * t.length[tile] - start
    expected = torch.clamp(env.command.speed[done] * env.cfg.episode_length_s,
                           max=t.length[tile] - start)
    reached = torch.linalg.vector_norm(t.terminus[tile] - env.sim.qpos[done, 0:2], dim=1) < (
        env.reach_radius)
    env.level[done] = update_levels(env.level[done], covered, expected, reached,
                                    env.terrain.levels, env.gen, cur.up, cur.down)


def spawn(env, ids: torch.Tensor) -> None:
    """A new tile of the env's category and level, a jittered start pose on it, the
    default joint pose, and the physics draw (nominal until the schedule starts).

    The start pose: the trail start, facing along the trail, jittered; with
    ``env.spawn_remaining`` a safe spawn along the trail (``spawns.trail_spawn``: on its
    support, the category's obstacle ahead, the height of that support) facing the next
    waypoint, whose index the goals term starts from.
    """
    k, tm, t = len(ids), env.terrain, env.trails_t
    variant = torch.randint(0, tm.variants, (k,), generator=env.gen, device=env.device)
    tiles = (env.category[ids] * tm.levels + env.level[ids]) * tm.variants + variant
    env.goals.tile[ids] = tiles
    if env.cfg.spawn_remaining is not None:
        pose = trail_spawn(env, tiles, env.cfg.spawn_remaining, env.cfg.spawn_noise)
        start, yaw, first = pose.xyz, pose.yaw, pose.first
    else:  # the flat start pad: any jitter stands on it
        start, first = t.start[tiles].clone(), torch.zeros(k, dtype=torch.int64,
                                                           device=env.device)
        start[:, :2] += uniform(env, -1.0, 1.0, k, 2) * env.cfg.spawn_noise
        start[:, 2] = env.ground.bilinear(start[:, :2]) + env.scene.stand_height + SPAWN_LIFT
        yaw = t.start_yaw[tiles] + uniform(env, -SPAWN_YAW_NOISE, SPAWN_YAW_NOISE, k)
        # training: a share of robots along the trail, so the far half is seen too
        along = chance(env, env.cfg.spawn_along, k)
        if along.any():
            pose = trail_spawn(env, tiles[along], [ALONG_MIN_LEFT, float("inf")],
                               env.cfg.spawn_noise)
            start[along], yaw[along], first[along] = pose.xyz, pose.yaw, pose.first
    # m of expert path behind the spawn point: the curriculum counts from here
    env.spawned_at[ids] = t.cum_length[tiles, (first - 1).clamp(min=0)] * (first > 0)
    env.goals.start[ids] = first
    qpos = env.qpos0.expand(k, -1).clone()
    qpos[:, 0:3] = start
    qpos[:, 3], qpos[:, 6] = torch.cos(yaw / 2), torch.sin(yaw / 2)
    qpos[:, 4:6] = 0.0
    qpos[:, env.qpos_adr] = env.default_pose
    env.ctrl[ids] = env.default_pose
    # draw 0 is the nominal one; a randomised one 1.. with the schedule's probability
    drawn = torch.randint(1, max(env.sim.num_draws, 2), (k,), generator=env.gen,
                          device=env.device)
    drawn = torch.where(chance(env, env.randomization.strength(env.global_steps), k), drawn, 0)
    env.sim.set_models(ids, drawn)
    env.sim.reset_envs(ids, qpos, torch.zeros(k, env.sim.nv, device=env.device,
                                              dtype=env.dtype), env.ctrl[ids])


def draw_delay(env, ids: torch.Tensor) -> None:
    """Appendix Table 5: an action delay per episode, once the schedule allows it."""
    on = chance(env, env.randomization.delay_on(env.global_steps), len(ids))
    env.action_delay.draw(env, ids, env.cfg.randomization.max_action_delay, on)


def draw_command(env, ids: torch.Tensor) -> None:
    """The episode's forward speed: drawn (or zero: stand still) in training, the goal
    speed in evaluation."""
    env.command.resample(env, ids)


RESET_EVENTS: list[Callable] = [gate, curriculum, spawn, draw_delay, draw_command]


# ------------------------------------------------------------------ step events
def push(env) -> None:
    """Appendix Table 5: every push interval, a random base xy velocity kick."""
    top = env.cfg.randomization.push_max_vel * env.randomization.strength(env.global_steps)
    if top <= 0:
        return
    due = (env.steps > 0) & (env.steps % env.push_every == 0)
    kick = uniform(env, -top, top, env.num_envs, 2)
    env.sim.qvel[:, 0:2] += kick * due[:, None]


STEP_EVENTS: list[Callable] = [push]


# ------------------------------------------------------------------ stateful event terms
class ActionDelay:
    """The last ``max_delay + 1`` actions (N, D + 1, A), newest first; each env applies the
    one ``delay`` (N,) steps old."""

    def __init__(self, n: int, max_delay: int, actions: int, device: torch.device,
                 dtype: torch.dtype) -> None:
        self.buf = torch.zeros(n, max_delay + 1, actions, device=device, dtype=dtype)
        self.delay = torch.zeros(n, dtype=torch.int64, device=device)
        self._rows = torch.arange(n, device=device)

    def __call__(self, action: torch.Tensor) -> torch.Tensor:
        """Push ``action`` (N, A); the action each env applies now (N, A)."""
        self.buf = torch.cat([action[:, None], self.buf[:, :-1]], 1)
        return self.buf[self._rows, self.delay]

    def draw(self, env, ids: torch.Tensor, max_delay: int, on: torch.Tensor) -> None:
        """A delay in 0..max_delay for the envs ``ids`` whose ``on`` (k,) is set, else 0."""
        delay = torch.randint(0, max_delay + 1, (len(ids),), generator=env.gen,
                              device=env.device)
        self.delay[ids] = torch.where(on, delay, 0)

    def reset(self, ids: torch.Tensor) -> None:
        self.buf[ids] = 0.0


class Command:
    """The velocity command the walking rewards track: forward speed (N,) drawn per
    episode, yaw rate steering toward the current waypoint, as (N, 2)."""

    def __init__(self, n: int, cfg, goal_speed: float, evaluation: bool,
                 device: torch.device, dtype: torch.dtype) -> None:
        self.cfg, self.goal_speed, self.evaluation = cfg, goal_speed, evaluation
        self.speed = torch.zeros(n, device=device, dtype=dtype)  # m/s
        self.value = torch.zeros(n, 2, device=device, dtype=dtype)

    def resample(self, env, ids: torch.Tensor) -> None:
        if self.evaluation:
            self.speed[ids] = self.goal_speed
            return
        k = len(ids)
        speed = uniform(env, self.cfg.speed[0], self.cfg.speed[1], k)
        stand = uniform(env, 0.0, 1.0, k) < self.cfg.zero_prob
        self.speed[ids] = torch.where(stand, 0.0, speed)

    def update(self, waypoint_xy: torch.Tensor, pos: torch.Tensor, yaw: torch.Tensor
               ) -> torch.Tensor:
        """The command (N, 2) for base positions (N, 3) and yaws (N,)."""
        d = waypoint_xy - pos[:, :2]
        err = wrap_angle(torch.atan2(d[:, 1], d[:, 0]) - yaw)
        c = self.cfg
        rate = torch.clamp(c.heading_gain * err, -c.max_yaw_rate, c.max_yaw_rate)
        self.value = torch.stack([self.speed, torch.where(self.speed > 0, rate, 0.0)], 1)
        return self.value

    def reset(self, ids: torch.Tensor) -> None:
        """The command is redrawn by ``draw_command``; nothing to clear."""
