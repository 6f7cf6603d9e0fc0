"""Observation terms: ``fn(env, obs) -> tensor`` over ``env.state`` (the step's
``StepState``); ``obs`` holds the terms computed before it, in table order (the history
reads the proprioception). :func:`observation_table` chooses the terms of an env config;
the env's observation spec is built from what the table produces. Stateful terms
(``ProprioHistory``, ``DepthFrames``) own their buffers and a ``reset(ids)``.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Categorical, Composite, Unbounded

from legoh import keys
from legoh.envs import math3d

# Scandots: Extreme Parkour's 12 x 11 grid in the robot's yaw frame.
SCAN_SHAPE = (12, 11)
SCAN_X, SCAN_Y = (-0.45, 1.2), (-0.75, 0.75)  # m, forward and left extents
NUM_EXPERT_GOALS = 3
ANG_VEL_SCALE, DOF_VEL_SCALE = 0.25, 0.05  # observation scales (legged_gym)
GOAL_DIST_CAP = 20.0  # m: the terminus distance input saturates here

ObsFn = Callable[..., torch.Tensor]


def scan_points(device: torch.device, dtype: torch.dtype) -> torch.Tensor:
    """(132, 2) scandot offsets in the yaw frame, x-major."""
    x = torch.linspace(*SCAN_X, SCAN_SHAPE[0], device=device, dtype=dtype)
    y = torch.linspace(*SCAN_Y, SCAN_SHAPE[1], device=device, dtype=dtype)
    return torch.stack(torch.meshgrid(x, y, indexing="ij"), -1).reshape(-1, 2)


def scan_rotor(points: torch.Tensor) -> torch.Tensor:
    """(2, 2K) matrix M with (cos yaw, sin yaw) @ M = the K points (K, 2) rotated by yaw,
    flattened: one matrix product turns every env's heading into its scan offsets."""
    px, py = points[:, 0], points[:, 1]
    return torch.stack([torch.stack([px, py], 1), torch.stack([-py, px], 1)]).reshape(2, -1)


# ------------------------------------------------------------------ proprioception
def base_ang_vel(env) -> torch.Tensor:
    return env.state.ang_vel_body * ANG_VEL_SCALE


def gravity(env) -> torch.Tensor:
    return env.state.gravity_body


def joint_pos(env) -> torch.Tensor:
    return (env.state.dof_pos - env.default_pose)[:, :env.num_actions]


def joint_vel(env) -> torch.Tensor:
    return env.state.dof_vel[:, :env.num_actions] * DOF_VEL_SCALE


def last_action(env) -> torch.Tensor:
    return env.state.action


def terminus_direction(env) -> torch.Tensor:
    """Unit direction (2) to the terminus, then its distance / 20 m capped at 1 (1)."""
    t = env.state.terminus_local
    dist = torch.linalg.vector_norm(t, dim=1, keepdim=True)
    return torch.cat([t / torch.clamp(dist, min=1e-6),
                      torch.clamp(dist, max=GOAL_DIST_CAP) / GOAL_DIST_CAP], 1)


def gait_clock(env) -> torch.Tensor:
    """sin and cos of the left leg's gait phase: a deployable input, students too."""
    clock = 2 * math.pi * env.state.phase[:, :1]
    return torch.cat([torch.sin(clock), torch.cos(clock)], 1)


PER_JOINT = -1  # a proprio term's width: one value per actuated joint (A)
# the order of ("obs", "proprio") and each term's width; P = 3 + 3 + 3A + 3 + 2
PROPRIO_TERMS: list[tuple[str, ObsFn, int]] = [
    ("base_ang_vel", base_ang_vel, 3), ("gravity", gravity, 3),
    ("joint_pos", joint_pos, PER_JOINT), ("joint_vel", joint_vel, PER_JOINT),
    ("last_action", last_action, PER_JOINT),
    ("terminus", terminus_direction, 3), ("gait_clock", gait_clock, 2),
]


def proprio(env, obs: dict) -> torch.Tensor:
    return torch.cat([fn(env) for _, fn, _ in PROPRIO_TERMS], 1)


def proprio_slice(name: str, num_actions: int) -> slice:
    """Where term ``name`` sits in ``("obs", "proprio")`` of a robot with ``num_actions``
    actuated joints: readers take a term by name, not by a hard-coded offset."""
    start = 0
    for term, _, width in PROPRIO_TERMS:
        width = num_actions if width == PER_JOINT else width
        if term == name:
            return slice(start, start + width)
        start += width
    raise KeyError(f"no proprio term {name!r}; the terms: {[t for t, _, _ in PROPRIO_TERMS]}")


class ProprioHistory:
    """The last ``length`` proprio vectors (N, length, P), oldest first; rows whose
    ``state.advance`` is set take the new one."""

    def __init__(self, n: int, length: int, dim: int, device: torch.device) -> None:
        self.buf = torch.zeros(n, length, dim, device=device)

    def __call__(self, env, obs: dict) -> torch.Tensor:
        shifted = torch.cat([self.buf[:, 1:], obs[keys.PROPRIO][:, None].float()], 1)
        self.buf = torch.where(env.state.advance[:, None, None], shifted, self.buf)
        return self.buf

    def reset(self, ids: torch.Tensor) -> None:
        self.buf[ids] = 0.0


# ------------------------------------------------------------------ exteroception, goals
def scandots(env, obs: dict) -> torch.Tensor:
    """clip(base z - nominal base height - ground, +-1 m) at the scan points, yaw frame."""
    s, grid = env.state, env.scan_grid
    heading = torch.stack([torch.cos(s.yaw), torch.sin(s.yaw)], 1)  # (N, 2)
    offsets = (heading @ env.scan_rotor).reshape(s.num_envs, -1, 2)  # R(yaw) p, cells
    heights = grid.bilinear_cells(grid.cells(s.base_xy)[:, None] + offsets)
    return torch.clamp(s.base_pos[:, 2:3] - env.robot.nominal_base_height - heights, -1.0, 1.0)


# physics draw features (6), base linear velocity (3). No trail-category one-hot (older
# checkpoints had one): the scandots show the terrain, and a one-hot would tie an oracle to
# the trail list it trained on (a hill trail mixes categories).
PRIVILEGED_WIDTH = 9


def privileged(env, obs: dict) -> torch.Tensor:
    """Physics draw features (6) and base linear velocity (base frame, 3)."""
    return torch.cat([env.physics_features[env.sim.model_of_env],
                      env.state.lin_vel_body.float()], 1)


def goal(env, obs: dict) -> torch.Tensor:
    """Terminus xy and middle waypoint xy, yaw frame."""
    return torch.cat([env.state.terminus_local, env.state.middle_local], 1)


def command(env, obs: dict) -> torch.Tensor:
    return env.state.command


def expert_goals(env, obs: dict) -> torch.Tensor:
    """The next three expert waypoints (N, 3, 2), yaw frame."""
    ahead = env.goals.ahead(env.goal_offsets)
    return math3d.to_yaw_frame(ahead, env.state.base_xy, env.state.yaw)


class DepthFrames:
    """The last ``cfg.history`` depth images (N, history, H, W), normalised to [-0.5, 0.5]
    (0.5: far), whether a new one arrived on this step (N,), and the frames observed:
    ``depth_window(cfg)`` of them (N, T, H, W), oldest first (the paper's 16 frames
    sub-sampled to 4, 0.5 s apart at 10 Hz)."""

    def __init__(self, n: int, cfg, device: torch.device) -> None:
        from legoh.config.env import depth_window

        self.far = cfg.far
        self.buf = torch.zeros(n, cfg.history, cfg.height, cfg.width, device=device)
        self.window = torch.tensor(depth_window(cfg), device=device)
        self.fresh = torch.zeros(n, dtype=torch.bool, device=device)

    def render(self, env, ids: torch.Tensor | None = None) -> torch.Tensor:
        """Normalised frames (k, H, W) from each env's camera sensor pose."""
        sd, sl = env.sim.sensordata[:, -1], env.scene.sensors
        sd = sd if ids is None else sd[ids]
        depth = env.depth_cam.render(sd[:, sl.camera_pos],
                                     math3d.quat_to_mat(sd[:, sl.camera_quat]))
        return (depth / self.far - 0.5).float()

    def push(self, frame: torch.Tensor | None) -> None:
        """A frame for every env (N, H, W), or none on this step."""
        if frame is None:
            self.fresh[:] = False
            return
        self.buf = torch.cat([self.buf[:, 1:], frame[:, None]], 1)
        self.fresh[:] = True

    def reset(self, ids: torch.Tensor, env) -> None:
        self.buf[ids] = self.render(env, ids)[:, None]
        self.fresh[ids] = True

    def __call__(self, env, obs: dict) -> torch.Tensor:
        return self.buf[:, self.window]


def depth_fresh(env, obs: dict) -> torch.Tensor:
    return env.depth.fresh[:, None]


# ------------------------------------------------------------------ info signals
def info_terms() -> dict[tuple[str, str], ObsFn]:
    """Signals for metrics and logs (the termination flags are added by the env)."""
    def state_of(name: str) -> ObsFn:
        return lambda env, obs: getattr(env.state, name)

    return {
        keys.WAYPOINT: lambda env, obs: env.goals.index,
        keys.PROGRESS: lambda env, obs: env.goals.progress(env.state.base_xy),
        keys.EPISODE_STEPS: lambda env, obs: env.steps,
        keys.EPISODE_METRES: lambda env, obs: env.episode_metres,
        keys.EDGE_CONTACTS: lambda env, obs: env.state.feet_on_edge.sum(1),
        keys.FOOT_CONTACTS: lambda env, obs: env.state.feet_contact.sum(1),
        keys.UNSAFE_COLLISIONS: state_of("unsafe_contacts"),
        keys.LEVEL: lambda env, obs: env.level,
        keys.RANDOMIZATION: lambda env, obs: torch.tensor(
            [env.randomization.strength(env.global_steps), env.randomization.alive,
             env.randomization.ended], device=env.device).expand(env.num_envs, 3),
        keys.CATEGORY: lambda env, obs: env.category,
        keys.TILE: lambda env, obs: env.goals.tile,
        keys.WAYPOINT_COUNT: lambda env, obs: env.trails_t.count[env.goals.tile],
        keys.BASE_POS: state_of("base_pos"), keys.BASE_QUAT: state_of("base_quat"),
        keys.REWARD_TERMS: lambda env, obs: TensorDict(
            {k: v.float() for k, v in env.reward_parts.items()}, batch_size=[env.num_envs]),
    }


# Terms computed after the state's (the env's ``state_terms`` are the others, in one
# compiled graph under ``env.compile``): depth frames come from the step's render, the
# randomisation signal reads Python counters, the reward terms are a nested TensorDict.
AFTER_STATE_TERMS = frozenset({keys.DEPTH, keys.DEPTH_FRESH, keys.RANDOMIZATION,
                               keys.REWARD_TERMS})


def observation_table(env) -> dict[tuple[str, str], ObsFn]:
    """The observation terms of ``env``'s config, in evaluation order."""
    table: dict[tuple[str, str], ObsFn] = {
        keys.PROPRIO: proprio, keys.PROPRIO_HISTORY: env.history,
        keys.SCANDOTS: scandots, keys.PRIVILEGED: privileged, keys.GOAL: goal,
        keys.COMMAND: command,
    }
    if env.cfg.depth.enabled:
        table[keys.DEPTH] = env.depth
        table[keys.DEPTH_FRESH] = depth_fresh
    table[keys.EXPERT_GOALS] = expert_goals
    table.update(info_terms())
    return table


def observed(value):
    """A term's value as observed: a float32 (or its own integer/bool dtype) copy, since
    the env's buffers change in place; a nested TensorDict as it is."""
    if isinstance(value, TensorDictBase):
        return value
    return value.to(torch.float32 if value.is_floating_point() else value.dtype, copy=True)


def state_terms(env) -> dict:
    """The terms of ``env.state`` alone (``env.state_terms``), as observed."""
    out: dict = {}
    for key in env.state_terms:
        out[key] = observed(env.observation_terms[key](env, out))
    return out


def observe(env, flags: dict[str, torch.Tensor], terms: dict | None = None) -> TensorDict:
    """Every term of ``env``'s table on ``env.state`` (those in ``terms`` already computed),
    plus the termination ``flags`` as info signals, as one TensorDict of copies."""
    out: dict = {}
    for key, fn in env.observation_terms.items():
        out[key] = terms[key] if terms and key in terms else observed(fn(env, out))
    nested: dict[str, dict] = {}
    for (group, name), value in out.items():
        nested.setdefault(group, {})[name] = value
    nested[keys.INFO].update({name: flag.clone() for name, flag in flags.items()})
    # built without tensordict's per-leaf checks (~1 ms a step at N = 64): every value
    # is the env's own, on its device, batch first (the spec test checks the shapes)
    batch, dev = torch.Size([env.num_envs]), env.device
    return TensorDict._new_unsafe(
        {group: TensorDict._new_unsafe(values, batch_size=batch, device=dev)
         for group, values in nested.items()}, batch_size=batch, device=dev)


def spec_of(sample: TensorDictBase, key: tuple[str, ...] = ()) -> Composite:
    """The spec of one observation the table produced: booleans are flags, depth frames
    are bounded to [-0.5, 0.5], everything else is unbounded of its dtype."""
    def leaf(k: tuple[str, ...], x: torch.Tensor):
        if x.dtype == torch.bool:
            return Categorical(2, shape=x.shape, dtype=torch.bool, device=x.device)
        if k == keys.DEPTH:
            return Bounded(-0.5, 0.5, shape=x.shape, dtype=x.dtype, device=x.device)
        return Unbounded(shape=x.shape, dtype=x.dtype, device=x.device)

    return Composite({k: spec_of(v, (*key, k)) if isinstance(v, TensorDictBase)
                      else leaf((*key, k), v) for k, v in sample.items()},
                     shape=sample.batch_size, device=sample.device)
