"""One step's state, derived once from the physics and read by every term.

``compute_state`` runs after each physics step (and each reset); rewards, terminations and
observations read the ``StepState`` it returns and never the physics directly. The step's
bookkeeping (air time, the expert waypoint index, the last action, joint velocities and
torques) lives in small stateful terms here, each with a ``reset(ids)``, and is updated by
the step, never inside a reward. All tensors batch first, on the env's device.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
import torch

from legoh.envs import math3d
from legoh.envs.terrain import TerrainMap


@dataclass
class StepState:
    """Everything a term may read, for N envs (torch, batch first, physics dtype)."""

    dt: float  # s, policy period
    base_pos: torch.Tensor  # (N, 3) m, world
    base_quat: torch.Tensor  # (N, 4) (w, x, y, z), world
    roll: torch.Tensor  # (N,) rad
    pitch: torch.Tensor  # (N,) rad
    yaw: torch.Tensor  # (N,) rad
    lin_vel_body: torch.Tensor  # (N, 3) m/s
    ang_vel_body: torch.Tensor  # (N, 3) rad/s
    gravity_body: torch.Tensor  # (N, 3) unit gravity in the base frame
    lin_vel_world: torch.Tensor  # (N, 3) m/s
    base_xy: torch.Tensor  # (N, 2) m
    base_height: torch.Tensor  # (N,) m above the ground under the base
    dof_pos: torch.Tensor  # (N, J) rad, actuated joints
    dof_vel: torch.Tensor  # (N, J) rad/s
    last_dof_vel: torch.Tensor  # (N, J)
    default_pose: torch.Tensor  # (J,)
    joint_range: torch.Tensor  # (J, 2)
    hip_idx: torch.Tensor  # indices of hip yaw/roll joints in J
    torques: torch.Tensor  # (N, J) N m
    last_torques: torch.Tensor  # (N, J)
    action: torch.Tensor  # (N, A) the latest action (this step's; at a reset the last one)
    last_action: torch.Tensor  # (N, A) the one before
    waypoint_xy: torch.Tensor  # (N, 2) current expert waypoint
    terminus_xy: torch.Tensor  # (N, 2)
    terminus_local: torch.Tensor  # (N, 2) terminus in the yaw frame, m
    middle_local: torch.Tensor  # (N, 2) middle waypoint in the yaw frame, m
    feet_force: torch.Tensor  # (N, F, 3) net contact force with the world, N, world frame
    feet_contact: torch.Tensor  # (N, F) bool
    first_contact: torch.Tensor  # (N, F) bool: touched down this step
    air_time: torch.Tensor  # (N, F) s of the flight that just ended (0 when no touch-down)
    feet_on_edge: torch.Tensor  # (N, F) bool: in contact on a terrain edge
    unsafe_contacts: torch.Tensor  # (N,) number of non-foot bodies touching the world
    level: torch.Tensor  # (N,) terrain level
    command: torch.Tensor  # (N, 2) forward speed m/s (yaw frame), yaw rate rad/s
    phase: torch.Tensor  # (N, F) gait clock phase in [0, 1) of each leg
    stance: torch.Tensor  # (N, F) bool: the gait clock wants this foot on the ground
    feet_height: torch.Tensor  # (N, F) m: foot lift above its standing height
    swing_target: torch.Tensor  # (N, F) m: the lift the gait clock asks for now
    # (N,) weight of the clock's terms here: 0 near edges, pits and obstacles, where the
    # clock yields to the terrain (env.gait.yield_near), else 1
    clock_weight: torch.Tensor
    advance: torch.Tensor  # (N,) bool: whose observation history takes this state
    # (N,) m/s: how fast the remaining expert path / the straight line to the terminus
    # shrank over this step (0 on a reset); ``NavProgress`` keeps the bookkeeping
    path_progress: torch.Tensor
    line_progress: torch.Tensor
    # (N,) bool: the episode ended in a failure on this step; the step sets it from the
    # termination table (mdp.terminations) before the rewards read it
    failed: torch.Tensor

    @property
    def num_envs(self) -> int:
        return self.yaw.shape[0]


class Grid:
    """A (nx, ny) map on the device (cell [i, j] at origin + (i, j) * res): bilinear and
    nearest-cell lookups at world points (..., 2), clamped at the edges."""

    def __init__(self, values: np.ndarray, origin: np.ndarray, res: float,
                 device: torch.device, dtype: torch.dtype,
                 value_dtype: torch.dtype | None = None) -> None:
        """``dtype``: of the query points (the physics'); ``value_dtype``: of the values
        (default ``dtype``)."""
        self.nx, self.ny = values.shape
        self.flat = torch.as_tensor(values, device=device).to(value_dtype or dtype).reshape(-1)
        self.origin = torch.as_tensor(origin, dtype=dtype, device=device)
        self.res = float(res)
        self._top = torch.tensor([self.nx - 1.000001, self.ny - 1.000001], device=device,
                                 dtype=dtype)

    def cells(self, xy: torch.Tensor) -> torch.Tensor:
        """World points (..., 2) in (fractional) cell units."""
        return (xy - self.origin) / self.res

    def bilinear(self, xy: torch.Tensor) -> torch.Tensor:
        """Interpolated values (...) at world points ``xy`` (..., 2)."""
        return self.bilinear_cells(self.cells(xy))

    def bilinear_cells(self, uv: torch.Tensor) -> torch.Tensor:
        """Interpolated values (...) at points ``uv`` (..., 2) in cell units."""
        uv = torch.minimum(torch.clamp(uv, min=0.0), self._top)
        ij = uv.long()
        fu, fv = (uv - ij).unbind(-1)
        k = ij[..., 0] * self.ny + ij[..., 1]
        g00, g10 = torch.take(self.flat, k), torch.take(self.flat, k + self.ny)
        g01, g11 = torch.take(self.flat, k + 1), torch.take(self.flat, k + self.ny + 1)
        return torch.lerp(torch.lerp(g00, g10, fu), torch.lerp(g01, g11, fu), fv)

    def nearest(self, xy: torch.Tensor) -> torch.Tensor:
        """Value (...) of the cell nearest each world point ``xy`` (..., 2)."""
        ij = torch.round((xy - self.origin) / self.res).long()
        i = torch.clamp(ij[..., 0], 0, self.nx - 1)
        j = torch.clamp(ij[..., 1], 0, self.ny - 1)
        return torch.take(self.flat, i * self.ny + j)


@dataclass(frozen=True)
class TrailTable:
    """Per-tile trail data as padded arrays, so goals are gathered for all envs at once
    (numpy from :meth:`from_map`; :meth:`to` gives the same table as device tensors)."""

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
    ahead: np.ndarray  # (T, W) bool: the category's obstacle lies ahead (``Tile.ahead``)

    @classmethod
    def from_map(cls, tm: TerrainMap) -> TrailTable:
        width = max(len(t.waypoints) for t in tm.tiles)
        wp = np.zeros((len(tm.tiles), width, 2))
        cum = np.zeros((len(tm.tiles), width))
        ahead = np.zeros((len(tm.tiles), width), dtype=bool)  # padding: never a spawn point
        for k, t in enumerate(tm.tiles):
            ahead[k, : len(t.ahead)] = t.ahead
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
            variant=np.array([t.variant for t in tm.tiles]), ahead=ahead,
        )

    def to(self, device: torch.device, dtype: torch.dtype) -> TrailTable:
        """The same table as tensors on ``device`` (floats in ``dtype``, counts int64, flags
        bool)."""
        def conv(x: np.ndarray) -> torch.Tensor:
            t = torch.as_tensor(x, device=device)
            if t.dtype == torch.bool:
                return t
            return t.to(dtype) if t.is_floating_point() else t.long()

        return TrailTable(**{f.name: conv(getattr(self, f.name)) for f in fields(self)})


def as_index(adr: np.ndarray) -> slice | torch.Tensor:
    """Addresses as a slice where they are consecutive (a view, no gather), else a tensor."""
    if len(adr) and (np.diff(adr) == 1).all():
        return slice(int(adr[0]), int(adr[-1]) + 1)
    return torch.as_tensor(adr, dtype=torch.int64)


# ------------------------------------------------------------------ stateful bookkeeping
class AirTime:
    """Seconds each foot has been off the ground (N, F)."""

    def __init__(self, n: int, feet: int, dt: float, device: torch.device,
                 dtype: torch.dtype) -> None:
        self.dt = dt
        self.time = torch.zeros(n, feet, device=device, dtype=dtype)

    def update(self, in_contact: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Touch-downs (N, F) bool and the flight times they ended (N, F) s, 0 elsewhere."""
        first = in_contact & (self.time > 0)
        flight = self.time + self.dt
        air = torch.where(first, flight, 0.0)
        self.time = torch.where(in_contact, 0.0, flight)
        return first, air

    def reset(self, ids: torch.Tensor) -> None:
        self.time[ids] = 0.0


class Memory:
    """The previous step's action, joint velocities and torques (for rate terms)."""

    def __init__(self, n: int, actions: int, joints: int, device: torch.device,
                 dtype: torch.dtype) -> None:
        def z(k: int) -> torch.Tensor:
            return torch.zeros(n, k, device=device, dtype=dtype)

        self.action, self.dof_vel, self.torques = z(actions), z(joints), z(joints)

    def update(self, s: StepState) -> None:
        # copies: dof_vel and torques are views of physics buffers overwritten in place
        self.action, self.dof_vel, self.torques = s.action, s.dof_vel.clone(), s.torques.clone()

    def reset(self, ids: torch.Tensor) -> None:
        for buf in (self.action, self.dof_vel, self.torques):
            buf[ids] = 0.0


class Goals:
    """Index of each env's current expert waypoint, advanced when the robot passes it:
    within ``radius`` of it, or (``rule="past"``) also once beyond it along the path, past
    the line through it square to the segment that leads to it (from the previous waypoint,
    or the trail start).

    ``start`` (N,) is the index an episode begins with: 0 at the trail start; the spawn
    event sets it to the next waypoint when it puts a robot on the trail
    (``env.spawn_remaining``), before :meth:`reset` copies it into ``index``.
    """

    def __init__(self, n: int, trails: TrailTable, radius: float, device: torch.device,
                 rule: str = "radius") -> None:
        if str(rule) not in ("radius", "past"):
            raise ValueError(f"env.waypoint_pass={rule!r}: choose radius or past")
        self.trails, self.radius, self.past = trails, radius, str(rule) == "past"
        self.index = torch.zeros(n, dtype=torch.int64, device=device)
        self.start = torch.zeros(n, dtype=torch.int64, device=device)
        self.tile = torch.zeros(n, dtype=torch.int64, device=device)

    def last(self) -> torch.Tensor:
        return self.trails.count[self.tile] - 1

    def ahead(self, k: int | torch.Tensor) -> torch.Tensor:
        """World xy (N, 2) (or (N, K, 2) for a (K,) tensor ``k``) of the waypoints ``k``
        places past the current one, capped at the terminus."""
        if isinstance(k, int):
            return self.trails.waypoints[self.tile, torch.clamp(self.index + k,
                                                                max=self.last())]
        idx = torch.minimum(self.index[:, None] + k, self.last()[:, None])
        return self.trails.waypoints[self.tile[:, None], idx]

    def advance(self, base_xy: torch.Tensor) -> None:
        """Move past the current waypoint those robots (base xy (N, 2)) that passed it."""
        here = self.ahead(0)
        passed = torch.linalg.vector_norm(here - base_xy, dim=1) < self.radius
        if self.past:
            t = self.trails
            before = torch.where((self.index > 0)[:, None],
                                 t.waypoints[self.tile, (self.index - 1).clamp(min=0)],
                                 t.start[self.tile, :2])
            passed |= ((base_xy - here) * (here - before)).sum(1) > 0
        self.index = self.index + (passed & (self.index < self.last())).long()

    def remaining(self, xy: torch.Tensor) -> torch.Tensor:
        """Metres (N,) of expert path from points ``xy`` (N, 2) to the terminus: straight
        to the current waypoint, then along the waypoints."""
        t = self.trails
        to_wp = torch.linalg.vector_norm(t.waypoints[self.tile, self.index] - xy, dim=1)
        return to_wp + t.length[self.tile] - t.cum_length[self.tile, self.index]

    def progress(self, base_xy: torch.Tensor) -> torch.Tensor:
        """Fraction (N,) of the trail covered: path length to the current waypoint minus the
        remaining straight-line distance to it, over the trail length."""
        t = self.trails
        to_wp = torch.linalg.vector_norm(t.waypoints[self.tile, self.index] - base_xy, dim=1)
        done = t.cum_length[self.tile, self.index] - to_wp
        return torch.clamp(done / torch.clamp(t.length[self.tile], min=1e-6), 0.0, 1.0)

    def reset(self, ids: torch.Tensor) -> None:
        self.index[ids] = self.start[ids]


class NavProgress:
    """Where each robot stood on the last step, so the step can say how much nearer the
    terminus it got: along the remaining expert path (both ends measured through the
    *current* waypoint, so passing a waypoint is no jump) and in a straight line."""

    def __init__(self, n: int, device: torch.device, dtype: torch.dtype) -> None:
        self.last_xy = torch.zeros(n, 2, device=device, dtype=dtype)
        self.fresh = torch.ones(n, dtype=torch.bool, device=device)  # no last position yet

    def start(self, xy: torch.Tensor) -> None:
        """After a reset: the fresh rows' spawn positions (N, 2) become their last ones."""
        self.last_xy = torch.where(self.fresh[:, None], xy, self.last_xy)
        self.fresh[:] = False

    def update(self, goals: Goals, terminus_xy: torch.Tensor, xy: torch.Tensor, dt: float
               ) -> tuple[torch.Tensor, torch.Tensor]:
        """(path, line) progress (N,) each, m/s, for base positions ``xy`` (N, 2) after
        ``goals`` advanced; rows reset within this step (a diverged sim) get 0."""
        def line(p: torch.Tensor) -> torch.Tensor:
            return torch.linalg.vector_norm(terminus_xy - p, dim=1)

        path = (goals.remaining(self.last_xy) - goals.remaining(xy)) / dt
        straight = (line(self.last_xy) - line(xy)) / dt
        path, straight = (torch.where(self.fresh, 0.0, v) for v in (path, straight))
        self.last_xy, self.fresh = xy.clone(), torch.zeros_like(self.fresh)
        return path, straight

    def reset(self, ids: torch.Tensor) -> None:
        self.fresh[ids] = True


def gait_phase(steps: torch.Tensor, dt: float, period: float, feet: int) -> torch.Tensor:
    """(N, F) phase in [0, 1) of each leg's cycle, legs ``1 / feet`` of a period apart."""
    offsets = torch.arange(feet, device=steps.device, dtype=torch.float64) / feet
    return torch.remainder((steps.to(torch.float64) * dt / period)[:, None] + offsets, 1.0)


# ------------------------------------------------------------------ the state
def compute_state(env, action: torch.Tensor | None = None) -> StepState:
    """The state of every env after a physics step (``action``: this step's, whose
    bookkeeping runs: air time, waypoints) or after a reset (``action`` None)."""
    sim, sl, n, nf = env.sim, env.scene.sensors, env.num_envs, env.num_feet
    qpos, qvel, sd = sim.qpos, sim.qvel, sim.sensordata
    pos, quat = qpos[:, 0:3].clone(), qpos[:, 3:7].clone()
    rot = math3d.quat_to_mat(quat)
    roll, pitch, yaw = math3d.roll_pitch_yaw(rot)
    contact = sd[:, :, sl.feet_contact].reshape(n, -1, nf, 4)
    in_contact = (contact[..., 0] > 0).any(1)
    forces = contact[..., 1:4]
    strongest = torch.linalg.vector_norm(forces, dim=-1).argmax(1)  # (N, F) substep
    force = forces.gather(1, strongest[:, None, :, None].expand(-1, 1, -1, 3))[:, 0]
    feet = sd[:, -1, sl.feet_pos].reshape(n, nf, 3)
    mem = env.memory
    terminus = env.trails_t.terminus[env.goals.tile]
    if action is None:
        first = torch.zeros_like(in_contact)
        air = torch.zeros_like(env.air_time.time)
        action, last_action = mem.action, mem.action
        env.nav_progress.start(pos[:, :2])
        path_rate = line_rate = torch.zeros_like(pos[:, 0])
    else:
        first, air = env.air_time.update(in_contact)
        env.goals.advance(pos[:, :2])
        path_rate, line_rate = env.nav_progress.update(env.goals, terminus, pos[:, :2], env.dt)
        last_action = mem.action
    command = env.command.update(env.goals.ahead(0), pos, yaw)
    xy = torch.cat([pos[:, None, :2], feet[..., :2]], 1)  # base, then feet
    ground = env.support.bilinear(xy)  # env.height_reference: the support or bare ground
    clock = (torch.ones_like(pos[:, 0]) if env.clock_grid is None
             else env.clock_grid.bilinear(pos[:, :2]))
    gait = env.cfg.gait
    phase = gait_phase(env.steps, env.dt, gait.period, nf)
    stance = (phase < gait.stance) | (env.command.speed[:, None] == 0)
    swing = torch.clamp((phase - gait.stance) / (1.0 - gait.stance), 0.0, 1.0)
    target = torch.where(stance, 0.0, gait.swing_height * torch.sin(math.pi * swing))
    goals = math3d.to_yaw_frame(torch.stack([env.trails_t.terminus[env.goals.tile],
                                             env.trails_t.middle[env.goals.tile]], 1),
                                pos[:, :2], yaw)
    lin_vel = qvel[:, 0:3].clone()
    torques = sd[:, -1, sl.torques]
    return StepState(
        dt=env.dt, base_pos=pos, base_quat=quat, roll=roll, pitch=pitch, yaw=yaw,
        lin_vel_body=math3d.world_to_body(rot, lin_vel), ang_vel_body=qvel[:, 3:6].clone(),
        gravity_body=-rot[:, 2, :], lin_vel_world=lin_vel, base_xy=pos[:, :2],
        base_height=pos[:, 2] - ground[:, 0],
        dof_pos=qpos[:, env.qpos_adr], dof_vel=qvel[:, env.dof_adr],
        last_dof_vel=mem.dof_vel, default_pose=env.default_pose,
        joint_range=env.joint_range, hip_idx=env.hip_idx,
        torques=torques, last_torques=mem.torques, action=action, last_action=last_action,
        waypoint_xy=env.goals.ahead(0), terminus_xy=terminus,
        terminus_local=goals[:, 0], middle_local=goals[:, 1],
        feet_force=force, feet_contact=in_contact, first_contact=first, air_time=air,
        feet_on_edge=in_contact & env.edges.nearest(feet[..., :2]),
        unsafe_contacts=(sd[:, :, sl.unsafe_found] > 0).any(1).sum(1),
        level=env.level, command=command, phase=phase, stance=stance,
        feet_height=feet[..., 2] - ground[:, 1:] - env.feet_rest_height,
        swing_target=target, clock_weight=clock,
        advance=torch.ones(n, dtype=torch.bool, device=pos.device),
        path_progress=path_rate, line_progress=line_rate,
        failed=torch.zeros(n, dtype=torch.bool, device=pos.device),
    )
