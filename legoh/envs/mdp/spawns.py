"""A safe spawn along a trail: on the support the robot stands on, its category's obstacle
ahead (benchmark protocol v2, docs/metrics.md).

:func:`trail_spawn` is the one entry: the evaluation env spawns every robot with it
(``events.spawn`` under ``env.spawn_remaining``), and training can spawn any subset of its
robots with it, e.g. half of them along the trail (issue 44): inside ``events.spawn``, draw
``along = chance(env, 0.5, k)`` and write ``trail_spawn(env, tiles[along], remaining,
env.cfg.spawn_noise)``'s pose and first goal index for ``ids[along]``.

Rules, each checked against the terrain map's masks (``terrain/obstacles.py``):

* a spawn waypoint is usable when the robot, in its default pose facing the next waypoint,
  has every sole point on footing (never partly over a pit, in a ditch, on a hurdle or in a
  trunk) and the category's obstacle lies on the path ahead (a tile with none: any);
* a jittered pose is kept only where every sole point stays on footing, else the waypoint's
  own pose is used;
* the spawn height is read from the ground under the soles (their highest point), not from
  the ground under the base.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from legoh.envs.mdp.state import Grid
from legoh.envs.scene import standing_pose

SPAWN_YAW_NOISE = 0.3  # rad, uniform either side of the heading
SPAWN_LIFT = 0.02  # m above the standing height: no initial ground penetration
SOLE_GRID = 3  # sole points per foot: a SOLE_GRID x SOLE_GRID grid over its footprint


def sole_points(scene) -> np.ndarray:
    """(F * SOLE_GRID**2, 2) base-frame xy (m) covering each foot's collider footprint in the
    default pose, yaw 0 (from MuJoCo's kinematics and the geoms' bounding boxes)."""
    model, data = scene.model, standing_pose(scene)
    out = []
    for body in scene.robot.feet_bodies:
        geoms = np.flatnonzero((model.geom_bodyid == model.body(body).id)
                               & (model.geom_contype > 0))
        if len(geoms) == 0:
            raise ValueError(f"foot body {body!r} has no collider geom: no sole to stand on")
        lo, hi = np.full(2, np.inf), np.full(2, -np.inf)
        for g in geoms:
            rot = data.geom_xmat[g].reshape(3, 3)
            centre = data.geom_xpos[g] + rot @ model.geom_aabb[g, :3]
            half = np.abs(rot) @ model.geom_aabb[g, 3:]
            lo, hi = np.minimum(lo, (centre - half)[:2]), np.maximum(hi, (centre + half)[:2])
        u, v = np.meshgrid(np.linspace(lo[0], hi[0], SOLE_GRID),
                           np.linspace(lo[1], hi[1], SOLE_GRID))
        out.append(np.stack([u.ravel(), v.ravel()], axis=-1))
    return np.concatenate(out)


@dataclass
class Spawn:
    """Start poses of K robots: base xyz (K, 3) world m, yaw (K,) rad, the goal index each
    starts with (K,) (0 at the trail start)."""

    xyz: torch.Tensor
    yaw: torch.Tensor
    first: torch.Tensor


class SpawnSupport:
    """What a safe spawn reads, built once per env: the sole points, the footing mask and
    ``usable`` (T, W) bool, the waypoints a robot may be spawned on (module docstring)."""

    def __init__(self, env) -> None:
        tm, t = env.terrain, env.trails_t
        self.soles = torch.as_tensor(sole_points(env.scene), device=env.device).to(env.dtype)
        footing = tm.footing if tm.footing is not None else np.ones(tm.heights.shape, bool)
        self.footing = Grid(footing, tm.origin, tm.resolution, env.device, env.dtype)
        self.stand = float(env.scene.stand_height)
        width = t.waypoints.shape[1]
        idx = torch.arange(width, device=env.device)
        nxt = t.waypoints[:, (idx + 1).clamp(max=width - 1)] - t.waypoints  # (T, W, 2)
        heading = torch.atan2(nxt[..., 1], nxt[..., 0])
        stands = self.on_support(t.waypoints.reshape(-1, 2), heading.reshape(-1)).reshape(
            heading.shape)
        ahead = t.ahead | ~t.ahead.any(1, keepdim=True)  # no obstacle in the tile: any
        self.usable = stands & ahead & (idx[None] < t.count[:, None] - 1)

    def feet(self, xy: torch.Tensor, yaw: torch.Tensor) -> torch.Tensor:
        """World xy (K, P, 2) of the sole points of robots at base ``xy`` (K, 2), ``yaw``
        (K,), in the default pose."""
        c, s = torch.cos(yaw)[:, None], torch.sin(yaw)[:, None]
        u, v = self.soles[:, 0], self.soles[:, 1]
        return torch.stack([xy[:, None, 0] + c * u - s * v, xy[:, None, 1] + s * u + c * v], -1)

    def on_support(self, xy: torch.Tensor, yaw: torch.Tensor) -> torch.Tensor:
        """(K,) bool: every sole point of each pose on footing: all the cells its bilinear
        ground height reads are footing (the nearest cell alone lets half a cell of pit in)."""
        return (self.footing.bilinear(self.feet(xy, yaw)) > 1.0 - 1e-6).all(1)

    def height(self, ground: Grid, xy: torch.Tensor, yaw: torch.Tensor) -> torch.Tensor:
        """(K,) base height (m) of each pose standing on its support: the highest ground
        under its soles plus the standing height and :data:`SPAWN_LIFT`."""
        return ground.bilinear(self.feet(xy, yaw)).amax(1) + self.stand + SPAWN_LIFT


def uniform(env, low: float, high: float, *shape: int) -> torch.Tensor:
    """U(low, high) draws from the env's generator (``events.uniform``: float64 whatever the
    backend, so the same seed gives the same spawn on both)."""
    u = torch.rand(*shape, generator=env.gen, device=env.device, dtype=torch.float64
                   ).to(env.dtype)
    return low + (high - low) * u


def spawn_waypoint(env, tiles: torch.Tensor, remaining: list[float]) -> torch.Tensor:
    """Index (K,) of the expert waypoint to spawn on for each of ``tiles`` (K,): uniform
    among the tile's usable waypoints (:class:`SpawnSupport`) whose remaining path to the
    terminus (m) lies in ``remaining`` = [lo, hi], else among the usable ones closest to
    that range; never the terminus. -1 for a tile with no usable waypoint (spawn at the
    trail start)."""
    t = env.trails_t
    width = t.waypoints.shape[1]
    left = t.length[tiles, None] - t.cum_length[tiles]  # (K, W) m of path still to walk
    allowed = env.spawn_support.usable[tiles]
    lo, hi = remaining
    miss = torch.where(allowed, torch.clamp(torch.maximum(lo - left, left - hi), min=0.0),
                       torch.inf)  # (K, W) m outside [lo, hi]; inf: not a spawn point
    best = allowed & (miss <= miss.min(1, keepdim=True).values + 1e-6)
    score = uniform(env, 0.0, 1.0, len(tiles), width)
    pick = torch.where(best, score, -1.0).argmax(1)  # uniform among the best
    return torch.where(allowed.any(1), pick, -1)


def trail_spawn(env, tiles: torch.Tensor, remaining: list[float], noise_xy: float,
                noise_yaw: float = SPAWN_YAW_NOISE) -> Spawn:
    """Safe start poses on ``tiles`` (K,): a usable waypoint with ``remaining`` = [lo, hi] m
    of path left (:func:`spawn_waypoint`; the trail start where a tile has none), facing the
    next waypoint, jittered by up to ``noise_xy`` m and ``noise_yaw`` rad where every sole
    stays on footing, at the height of the support under the soles."""
    t, sup = env.trails_t, env.spawn_support
    k = len(tiles)
    at = spawn_waypoint(env, tiles, remaining)
    on, i = at >= 0, at.clamp(min=0)
    here = t.waypoints[tiles, i]
    ahead = t.waypoints[tiles, (i + 1).clamp(max=t.waypoints.shape[1] - 1)] - here
    xy = torch.where(on[:, None], here, t.start[tiles, :2])
    heading = torch.where(on, torch.atan2(ahead[:, 1], ahead[:, 0]), t.start_yaw[tiles])
    moved = xy + uniform(env, -1.0, 1.0, k, 2) * noise_xy
    turned = heading + uniform(env, -noise_yaw, noise_yaw, k)
    keep = sup.on_support(moved, turned)
    xy = torch.where(keep[:, None], moved, xy)
    yaw = torch.where(keep, turned, heading)
    z = sup.height(env.ground, xy, yaw)
    return Spawn(torch.cat([xy, z[:, None]], 1), yaw,
                 torch.where(on, at + 1, torch.zeros_like(at)))
