"""Egocentric depth by ray-marching the terrain map in torch, vectorised over envs and rays.

The images of :class:`legoh.envs.sensors.DepthRaycaster` (``mj_multiRay``, the exact
reference this camera is tested against: ``tests/test_depth_raymarch.py``) at a fraction of
its cost, on the device the env keeps its state on, so the same code serves the GPU backend.

The world is read off the compiled model, so this camera sees the static geoms the ray
caster sees, and nothing else (the robot's colliders and visual meshes are in groups the
caster skips; the map holds no robot, which is the same):

* the height-field chunks, assembled into one grid of vertex heights. MuJoCo's height field
  is two triangles per cell, split along the diagonal from vertex (i, j) to (i + 1, j + 1)
  (``mj_rayHfield``): that piecewise-planar surface is marched, not a bilinear patch;
* boxes (any orientation) and cylinders (vertical axis), intersected analytically (slab
  test; side, then flat ends). They are not rasterised into the grid: yawed box edges and
  round trunks do not fall on cell lines, and a rasterised wall leans over a cell.

Terrain, per ray: nothing the camera can see rises above the top of its disc of reach or
sinks below its bottom, so the search runs from where the ray sinks below that top to where
it passes that bottom. It skips segments of two blocks (``block`` cells a side) while they
stay above the highest surface within a block of them, and marches a segment that dips
below it in ``samples`` fixed steps; the first step under the surface is refined by
bisection and a secant step (exact inside one triangle). Rays still searching go another
round; each round is a few batched tensor ops over all of them. A fixed step can step over
a sliver thinner than itself (a ray grazing the far edge of a stepping stone): those pixels
read the surface behind it (docs/env.md gives how often).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import mujoco
import numpy as np
import torch
from scipy.ndimage import maximum_filter, minimum_filter

from legoh.envs.sensors import WORLD_GROUPS, camera_ray_directions
from legoh.threads import torch_threads

NO_GROUND = -1.0e4  # m: the height of "no ground" (outside the map): rays pass over it
MIN_CHUNK = 64  # cameras a thread marches at least (fewer: Python and the GIL dominate)
T, END = 6, 7  # columns of a searching ray (origin 0:3, direction 3:6): t so far, end (m)
Geom = mujoco.mjtGeom


@dataclass
class StaticWorld:
    """The static geoms rays can hit, in the world frame (m).

    Attributes:
        heights: (nx, ny) vertex heights, vertex [i, j] at origin + (i, j) * res; NaN where
            no height field covers the vertex.
        origin: (2,) world xy of vertex [0, 0]. res: m between vertices.
        boxes: (M, 15) centre xyz, rotation (box to world, row-major 3 x 3), half sizes xyz.
        cylinders: (K, 5) centre xyz, radius, half-height; axes along world z.
    """

    heights: np.ndarray
    origin: np.ndarray
    res: float
    boxes: np.ndarray
    cylinders: np.ndarray


def _seen(model: mujoco.MjModel, g: int) -> bool:
    """Whether ``mj_multiRay`` with the ray casters' groups can hit geom ``g``."""
    group = min(max(int(model.geom_group[g]), 0), len(WORLD_GROUPS) - 1)
    mat = model.geom_matid[g]
    alpha = model.mat_rgba[mat, 3] if mat >= 0 else model.geom_rgba[g, 3]
    return bool(WORLD_GROUPS[group]) and alpha != 0


def static_world(model: mujoco.MjModel) -> StaticWorld:
    """Height fields, boxes and cylinders of ``model``'s static world.

    Raises:
        ValueError: a visible geom the heightmap camera cannot draw (a moving one, another
            shape, a tilted cylinder or height field, height fields of different spacing).
    """
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    fields, boxes, cylinders = [], [], []
    for g in range(model.ngeom):
        if not _seen(model, g):
            continue
        name = model.geom(g).name or f"geom {g}"
        kind = Geom(model.geom_type[g])
        if model.body_weldid[model.geom_bodyid[g]] != 0:
            raise ValueError(f"{name}: a moving geom ({kind.name}) in a ray-cast group; the "
                             "heightmap camera draws the static world only")
        pos, mat = data.geom_xpos[g].copy(), data.geom_xmat[g].reshape(3, 3).copy()
        size = model.geom_size[g]
        if kind == Geom.mjGEOM_HFIELD:
            if not np.allclose(mat, np.eye(3), atol=1e-9):
                raise ValueError(f"{name}: a rotated height field")
            fields.append((model, g, pos))
        elif kind == Geom.mjGEOM_BOX:
            boxes.append(np.concatenate([pos, mat.ravel(), size]))
        elif kind == Geom.mjGEOM_CYLINDER:
            if abs(mat[2, 2]) < 1.0 - 1e-9:
                raise ValueError(f"{name}: a cylinder whose axis is not vertical")
            cylinders.append(np.array([*pos, size[0], size[1]]))
        else:
            raise ValueError(f"{name}: geom type {kind.name} is not drawn by the heightmap "
                             "camera (height fields, boxes, vertical cylinders)")
    if not fields:
        raise ValueError("no height field in the model: nothing to march")
    heights, origin, res = _assemble(fields)
    return StaticWorld(heights, origin, res, np.array(boxes).reshape(-1, 15),
                       np.array(cylinders).reshape(-1, 5))


def _assemble(fields: list) -> tuple[np.ndarray, np.ndarray, float]:
    """One grid of vertex heights from height-field geoms of the same spacing."""
    blocks = []
    for model, g, pos in fields:
        h = model.geom_dataid[g]
        nrow, ncol = int(model.hfield_nrow[h]), int(model.hfield_ncol[h])
        sx, sy, top, _ = model.hfield_size[h]
        data = model.hfield_data[model.hfield_adr[h]:model.hfield_adr[h] + nrow * ncol]
        # rows run along y, columns along x; height = geom z + normalised data * top
        z = pos[2] + data.astype(np.float64).reshape(nrow, ncol).T * top
        blocks.append((pos[0] - sx, pos[1] - sy, 2 * sx / (ncol - 1), 2 * sy / (nrow - 1), z))
    res = blocks[0][2]
    if any(not np.isclose(b[2], res) or not np.isclose(b[3], res) for b in blocks):
        raise ValueError("height fields of different or non-square spacing")
    x0, y0 = min(b[0] for b in blocks), min(b[1] for b in blocks)
    corners = [(int(round((b[0] - x0) / res)), int(round((b[1] - y0) / res))) for b in blocks]
    nx = max(i + b[4].shape[0] for (i, _), b in zip(corners, blocks, strict=True))
    ny = max(j + b[4].shape[1] for (_, j), b in zip(corners, blocks, strict=True))
    heights = np.full((nx, ny), np.nan)
    for (i, j), b in zip(corners, blocks, strict=True):
        heights[i:i + b[4].shape[0], j:j + b[4].shape[1]] = b[4]  # shared borders agree
    return heights, np.array([x0, y0]), float(res)


class HeightmapDepthCamera:
    """Planar depth (k, H, W) in metres along the optical axis, clipped to ``far``: the
    interface and conventions of :class:`legoh.envs.batched_sim.RaycastCamera`.

    Args:
        model: the compiled scene (its static world is read once; memory: 16 bytes a cell).
        fovy_deg, width, height, far: the camera, as the ray caster's.
        device: where rays are marched (the env's device).
        threads: CPU threads marching cameras in parallel (the physics backend's).
        block: cells a side of the blocks whose tops let a ray skip ahead.
        samples: march steps through a segment of two blocks (step = 2 block / samples
            cells: 1 cell, 0.05 m, by default).
        window: segments a skipping ray looks ahead per round.
        bisections: halvings of a bracket before its secant step.
    """

    PAD = 2  # cells of no ground around the map: clamped lookups off the map land there

    def __init__(self, model: mujoco.MjModel, fovy_deg: float, width: int, height: int,
                 far: float, device: torch.device | str = "cpu", threads: int = 1,
                 block: int = 2, samples: int = 4, window: int = 4, bisections: int = 2
                 ) -> None:
        self.width, self.height, self.far = width, height, far
        self.device = dev = torch.device(device)
        self.threads = threads if dev.type == "cpu" else 1
        self._pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None
        self.samples, self.bisections, self.block, self.window = samples, bisections, block, window
        world = static_world(model)
        self.res = world.res
        f32 = torch.float32
        dirs = camera_ray_directions(fovy_deg, width, height).reshape(-1, 3)
        self._dirs = torch.as_tensor(dirs, dtype=f32, device=dev)
        self._cos = self._dirs[:, 2].neg()
        self._tmax = far / self._cos  # (R,) ray length at which planar depth reaches far
        self._reach = float(self._tmax.max())
        half_h = np.tan(np.deg2rad(fovy_deg) / 2.0)
        half_w = half_h * width / height
        planes = np.array([[1, 0, half_w], [-1, 0, half_w], [0, 1, half_h], [0, -1, half_h]])
        self._planes = torch.as_tensor(planes / np.linalg.norm(planes, axis=1, keepdims=True),
                                       dtype=f32, device=dev)  # outward normals, camera frame
        h = np.pad(np.nan_to_num(world.heights, nan=NO_GROUND), self.PAD,
                   constant_values=NO_GROUND)
        self._origin = torch.as_tensor(world.origin - self.PAD * world.res, device=dev)
        self._nx, self._ny = h.shape  # vertices
        # per cell: h(fu, fv) = h00 + a fu + b fv + c min(fu, fv) is MuJoCo's pair of triangles
        h00, h10, h01, h11 = h[:-1, :-1], h[1:, :-1], h[:-1, 1:], h[1:, 1:]
        planes = np.stack([h00, h10 - h00, h01 - h00, h11 - h10 - h01 + h00], -1)
        self._cells = torch.as_tensor(planes.reshape(-1, 4), dtype=f32, device=dev)
        top, bottom = self._block_bounds(h, block)
        self._nbx, self._nby = top.shape
        self._tops = torch.as_tensor(top.reshape(-1), dtype=f32, device=dev)
        # highest and lowest surface a camera in a block can see (+1 block: anywhere in it)
        w = 2 * (int(np.ceil(self._reach / (block * world.res))) + 1) + 1
        disc = np.stack([maximum_filter(top, size=w, mode="nearest"),
                         minimum_filter(bottom, size=w, mode="nearest")], -1)
        self._disc = torch.as_tensor(disc.reshape(-1, 2), dtype=f32, device=dev)
        self._boxes = torch.as_tensor(world.boxes, dtype=f32, device=dev)
        self._cyls = torch.as_tensor(world.cylinders, dtype=f32, device=dev)
        self._to_cells = torch.tensor([world.res, world.res, 1.0], dtype=f32, device=dev)

    @staticmethod
    def _block_bounds(h: np.ndarray, b: int) -> tuple[np.ndarray, np.ndarray]:
        """(bx, by) top and bottom of the surface over each block of b x b cells; the tops
        also over the 8 neighbours, so every point within b cells of a block lies under
        its top."""
        nx, ny = h.shape
        bx, by = -(-(nx - 1) // b), -(-(ny - 1) // b)
        pad = np.full((bx * b + 1, by * b + 1), NO_GROUND)
        pad[:nx, :ny] = h
        top = np.full((bx, by), NO_GROUND)
        bottom = np.full((bx, by), -NO_GROUND)
        for di in range(b + 1):
            for dj in range(b + 1):
                top = np.maximum(top, pad[di::b, dj::b][:bx, :by])
                bottom = np.minimum(bottom, pad[di::b, dj::b][:bx, :by])
        return maximum_filter(top, size=3, mode="nearest"), bottom

    # ----------------------------------------------------------------- rendering
    def render(self, cam_pos: torch.Tensor, cam_mat: torch.Tensor) -> torch.Tensor:
        """Depth (k, height, width) for camera positions (k, 3) and rotations (k, 3, 3).

        On the CPU the cameras are split over ``threads`` Python threads, each running torch
        on one thread (torch releases the GIL inside an op): two torch threads per op spin at
        every op's end when the cores are shared, and were measured up to 70x slower."""
        pos = torch.as_tensor(cam_pos, device=self.device)
        mat = torch.as_tensor(cam_mat, device=self.device).to(torch.float32)
        k = len(pos)
        if self._pool is None or k < 2 * MIN_CHUNK:
            if self.device.type != "cpu":
                return self._render(pos, mat)
            with torch_threads(1):
                return self._render(pos, mat)
        parts = min(self.threads, k // MIN_CHUNK)
        cuts = [k * i // parts for i in range(parts + 1)]
        with torch_threads(1):
            return torch.cat(list(self._pool.map(
                lambda a, b: self._render(pos[a:b], mat[a:b]), cuts[:-1], cuts[1:])))

    def _render(self, pos: torch.Tensor, mat: torch.Tensor) -> torch.Tensor:
        """Depth (k, height, width) of the cameras at ``pos`` (k, 3), ``mat`` (k, 3, 3)."""
        k = len(pos)
        if k == 0:
            return torch.zeros(0, self.height, self.width, device=self.device)
        vec = torch.einsum("rj,kij->kri", self._dirs, mat).contiguous()  # (k, R, 3) world
        # the map frame: xy in cells from vertex [0, 0] (float32 keeps 0.1 mm over 1 km)
        grid = torch.cat([(pos[:, :2].double() - self._origin) / self.res, pos[:, 2:]], 1)
        dist = self._terrain(grid.float(), vec)
        if len(self._boxes) or len(self._cyls):
            self._obstacles(pos.float(), mat, vec, dist)
        depth = torch.clamp(dist * self._cos, max=self.far)
        return depth.view(k, self.height, self.width)

    def _ground(self, u: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
        """Surface height (m) at map points (u, v) in cells: MuJoCo's height-field triangles
        (fu >= fv: vertices 00, 10, 11; else 00, 01, 11); NO_GROUND off the map."""
        u = torch.clamp(u, 0.0, self._nx - 1.001)
        v = torch.clamp(v, 0.0, self._ny - 1.001)
        fi, fj = torch.floor(u), torch.floor(v)
        fu, fv = u - fi, v - fj
        cell = fi.int() * (self._ny - 1) + fj.int()
        h00, a, b, c = self._cells.index_select(0, cell.view(-1)).view(*u.shape, 4).unbind(-1)
        return torch.addcmul(torch.addcmul(torch.addcmul(h00, a, fu), b, fv), c,
                             torch.minimum(fu, fv))

    def _gap(self, rays: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        """Height (m) of the points at ``t`` (A, ...) along ``rays`` (A, 6+) above the
        surface; negative under it."""
        shape = (-1,) + (1,) * (t.dim() - 1)
        x, y, z, dx, dy, dz = (rays[:, c].view(shape) for c in range(6))
        return torch.addcmul(z, dz, t) - self._ground(torch.addcmul(x, dx, t),
                                                      torch.addcmul(y, dy, t))

    def _terrain(self, o: torch.Tensor, vec: torch.Tensor) -> torch.Tensor:
        """(k, R) distance (m) along each ray to the surface; inf: none within reach.

        ``o`` (k, 3): cameras in the map frame (xy in cells); ``vec`` (k, R, 3) unit rays.
        Nothing a camera can see rises above its disc's top or sinks below its bottom, so a
        ray is searched from where it sinks below the top to where it passes the bottom (or
        its reach). The search alternates, per ray, between segments of 2 blocks (skipped
        while they stay above their block's top) and a march of ``samples`` steps through a
        segment that dips below it, in rounds over the rays still searching.
        """
        b, res = self.block, self.res
        k, nray = vec.shape[:2]
        bi = torch.clamp(o[:, 0] / b, 0.0, self._nbx - 0.001).int()
        bj = torch.clamp(o[:, 1] / b, 0.0, self._nby - 0.001).int()
        roof, floor = self._disc.index_select(0, bi * self._nby + bj).unbind(1)  # (k,) m
        z0, dz = o[:, 2:3], vec[..., 2]
        above = z0 - roof[:, None]  # (k, 1)
        sink = torch.where(above > 0, torch.where(dz < 0, above / -dz, torch.inf), 0.0)
        end = torch.where(dz < 0, (z0 - floor[:, None]) / -dz, torch.inf)
        end = torch.minimum(end, self._tmax)
        ids = (sink <= end).view(-1).nonzero().squeeze(1)  # rays that may meet the surface
        # per ray: origin, direction (xy in cells a metre), t searched up to, end (m)
        rays = torch.cat([o.index_select(0, ids // nray),
                          vec.view(-1, 3).index_select(0, ids) / self._to_cells,
                          sink.view(-1, 1).index_select(0, ids),
                          end.view(-1, 1).index_select(0, ids)], 1)
        seg = 2.0 * b * res  # m: a segment's midpoint is within a block of all of it
        fine_t = torch.arange(1, self.samples + 1, device=self.device) * (seg / self.samples)
        coarse, fine = rays, rays[:0]
        coarse_ids, fine_ids = ids, ids[:0]
        hits = []
        while len(coarse) or len(fine):
            if len(coarse):  # skip the segments that stay above their block's top
                dip, first = self._dips(coarse, seg)
                coarse[:, T] += torch.where(dip, first * seg, self.window * seg)
                alive = coarse[:, T] <= coarse[:, END]
                go = (dip & alive).nonzero().squeeze(1)  # (fine is empty here)
                fine, fine_ids = coarse.index_select(0, go), coarse_ids.index_select(0, go)
                stay = (~dip & alive).nonzero().squeeze(1)
                coarse, coarse_ids = coarse.index_select(0, stay), coarse_ids.index_select(0, stay)
            if len(fine):  # march the dipping segments; t itself is above the surface
                ts = fine[:, T:T + 1] + fine_t  # (F, S)
                f = self._gap(fine, ts)
                under = (f <= 0).view(torch.uint8)
                hit = under.any(1).bool()
                h = hit.nonzero().squeeze(1)
                if len(h):
                    fi = under.index_select(0, h).argmax(1, keepdim=True)
                    prev = torch.clamp(fi - 1, min=0)
                    tsh, fh = ts.index_select(0, h), f.index_select(0, h)
                    ta = torch.where(fi > 0, tsh.gather(1, prev), fine[h, T:T + 1])
                    fa = torch.where(fi > 0, fh.gather(1, prev), torch.nan)  # nan: not known
                    hits.append((fine_ids[h], fine.index_select(0, h), ta[:, 0],
                                 tsh.gather(1, fi)[:, 0], fa[:, 0], fh.gather(1, fi)[:, 0]))
                fine[:, T] += seg
                back = (~hit & (fine[:, T] <= fine[:, END])).nonzero().squeeze(1)
                coarse = torch.cat([coarse, fine.index_select(0, back)])
                coarse_ids = torch.cat([coarse_ids, fine_ids.index_select(0, back)])
                fine, fine_ids = fine[:0], fine_ids[:0]
        dist = torch.full((k * nray,), torch.inf, device=self.device)
        if hits:
            hit_ids, *bracket = (torch.cat(x) for x in zip(*hits, strict=True))
            dist[hit_ids] = self._refine(*bracket)
        return dist.view(k, nray)

    def _dips(self, rays: torch.Tensor, seg: float) -> tuple[torch.Tensor, torch.Tensor]:
        """Whether any of the next ``window`` segments of ``rays`` (A, 8) dips below its
        block's top, and the first that does (A,)."""
        b = self.block
        x, y, z, dx, dy, dz, t = (rays[:, c:c + 1] for c in range(7))
        ts = t + torch.arange(self.window, device=self.device) * seg  # (A, W)
        # a segment's lowest point: z0 + dz t + min(dz, 0) seg; its midpoint in blocks
        zlo = torch.addcmul(z + torch.clamp(dz, max=0.0) * seg, dz, ts)
        mu = torch.addcmul((x + dx * (seg / 2)) / b, dx / b, ts)
        mv = torch.addcmul((y + dy * (seg / 2)) / b, dy / b, ts)
        bi = torch.clamp(mu, 0.0, self._nbx - 0.001).int()
        bj = torch.clamp(mv, 0.0, self._nby - 0.001).int()
        top = self._tops.index_select(0, (bi * self._nby + bj).view(-1)).view(zlo.shape)
        dips = (zlo <= top).view(torch.uint8)
        return dips.any(1).bool(), dips.argmax(1)

    def _refine(self, rays: torch.Tensor, ta: torch.Tensor, tb: torch.Tensor,
                fa: torch.Tensor, fb: torch.Tensor) -> torch.Tensor:
        """The meeting point in each bracket [ta (above), tb (under)] of ``rays``: bisection,
        then a secant step, exact when the bracket ends lie on one triangle. ``fa`` NaN: the
        gap at ta is not known yet (evaluated if still needed)."""
        for _ in range(self.bisections):
            tm = (ta + tb) / 2
            fm = self._gap(rays, tm)
            up = fm > 0
            ta, fa = torch.where(up, tm, ta), torch.where(up, fm, fa)
            tb, fb = torch.where(up, tb, tm), torch.where(up, fb, fm)
        todo = fa.isnan().nonzero().squeeze(1)
        if len(todo):
            fa[todo] = self._gap(rays.index_select(0, todo), ta.index_select(0, todo))
        frac = torch.where(fa > 0, fa / (fa - fb), 0.0)  # fa <= 0: under at the camera
        return ta + (tb - ta) * torch.clamp(frac, 0.0, 1.0)

    # ----------------------------------------------------------------- obstacles
    def _obstacles(self, pos: torch.Tensor, mat: torch.Tensor, vec: torch.Tensor,
                   dist: torch.Tensor) -> None:
        """Lower ``dist`` (k, R) to the nearest box or cylinder along each ray."""
        normals = torch.einsum("pj,kij->kpi", self._planes, mat)  # (k, 4, 3) world frame
        if len(self._boxes):
            self._hit_boxes(pos, normals, vec, dist)
        if len(self._cyls):
            self._hit_cylinders(pos, normals, vec, dist)

    def _in_view(self, centres: torch.Tensor, radius: torch.Tensor, pos: torch.Tensor,
                 normals: torch.Tensor, support) -> tuple[torch.Tensor, torch.Tensor]:
        """(env, obstacle) pairs that may show in the camera: within reach of the camera
        and not wholly outside a side of its frustum. ``support(normals (P, 4, 3), ids (P,))``
        gives each obstacle's half-extent (P, 4) along the normals; ``radius`` (M,) bounds
        it."""
        rel = centres[None] - pos[:, None]  # (k, M, 3)
        env, ids = ((rel * rel).sum(-1) <= (self._reach + radius) ** 2).nonzero().unbind(1)
        n = normals[env]
        out = (torch.einsum("pi,pqi->pq", rel[env, ids], n) > support(n, ids)).any(1)
        keep = (~out).nonzero().squeeze(1)
        return env[keep], ids[keep]

    def _hit_boxes(self, pos: torch.Tensor, normals: torch.Tensor, vec: torch.Tensor,
                   dist: torch.Tensor) -> None:
        centre, rot, half = self._boxes[:, :3], self._boxes[:, 3:12].view(-1, 3, 3), \
            self._boxes[:, 12:]

        def support(n: torch.Tensor, ids: torch.Tensor) -> torch.Tensor:  # sum |n.axis| half
            return (torch.einsum("pqi,pia->pqa", n, rot[ids]).abs() * half[ids, None]).sum(-1)

        env, ids = self._in_view(centre, half.norm(dim=1), pos, normals, support)
        if len(env) == 0:
            return
        r, h = rot[ids], half[ids][:, None]  # (P, 3, 3), (P, 1, 3)
        lp = torch.einsum("pia,pi->pa", r, pos[env] - centre[ids])[:, None]  # box frame
        lv = torch.einsum("pia,pri->pra", r, vec[env])  # (P, R, 3)
        inv = 1.0 / lv
        a, b = (-h - lp) * inv, (h - lp) * inv
        near = torch.minimum(a, b).nan_to_num(-torch.inf).amax(-1)
        far = torch.maximum(a, b).nan_to_num(torch.inf).amin(-1)
        t = torch.where(near >= 0, near, far)  # from inside: the exit face, as MuJoCo
        t = torch.where((near <= far) & (far >= 0), t, torch.inf)
        dist.scatter_reduce_(0, env[:, None].expand_as(t), t, "amin")

    def _hit_cylinders(self, pos: torch.Tensor, normals: torch.Tensor, vec: torch.Tensor,
                       dist: torch.Tensor) -> None:
        cyl = self._cyls
        radius, half = cyl[:, 3], cyl[:, 4]

        def support(n: torch.Tensor, ids: torch.Tensor) -> torch.Tensor:
            return n[..., :2].norm(dim=-1) * radius[ids, None] + n[..., 2].abs() * half[ids,
                                                                                      None]

        env, ids = self._in_view(cyl[:, :3], torch.hypot(radius, half), pos, normals, support)
        if len(env) == 0:
            return
        p = pos[env] - cyl[ids, :3]  # (P, 3) camera from the centre
        r2, hz = (radius[ids] ** 2)[:, None], half[ids]  # (P, 1), (P,)
        d = vec[env]  # (P, R, 3)
        px, py, pz = (p[:, i:i + 1] for i in range(3))
        c = px * px + py * py - r2  # > 0: the camera is outside the round side
        a = torch.addcmul(d[..., 0] ** 2, d[..., 1], d[..., 1])
        b = torch.addcmul(d[..., 0] * px, d[..., 1], py)
        det = torch.addcmul(b * b, a, c, value=-1.0)
        root = torch.sqrt(torch.clamp(det, min=0.0))
        # the entry from outside, the exit from inside
        t = (torch.where(c > 0, -root, root) - b) / a
        z = torch.addcmul(pz, t, d[..., 2])
        t = torch.where((det > 0) & (t >= 0) & (z.abs() <= hz[:, None]), t, torch.inf)
        # a flat end comes first only from beyond its plane or from inside
        ends = ((pz[:, 0].abs() > hz) | (c[:, 0] <= 0)).nonzero().squeeze(1)
        if len(ends):
            de, pe, r2e = d[ends], p[ends], r2[ends]
            plane = torch.where(pe[:, 2:3] > 0, hz[ends, None], -hz[ends, None])
            t_end = (plane - pe[:, 2:3]) / de[..., 2]
            qx = torch.addcmul(pe[:, 0:1], t_end, de[..., 0])
            qy = torch.addcmul(pe[:, 1:2], t_end, de[..., 1])
            t_end = torch.where((t_end >= 0) & (qx * qx + qy * qy <= r2e), t_end, torch.inf)
            if (c[ends, 0] <= 0).any():  # inside: the other end too
                t_far = (-plane - pe[:, 2:3]) / de[..., 2]
                qx = torch.addcmul(pe[:, 0:1], t_far, de[..., 0])
                qy = torch.addcmul(pe[:, 1:2], t_far, de[..., 1])
                t_end = torch.minimum(t_end, torch.where(
                    (t_far >= 0) & (qx * qx + qy * qy <= r2e), t_far, torch.inf))
            t[ends] = torch.minimum(t[ends], t_end)
        dist.scatter_reduce_(0, env[:, None].expand_as(t), t, "amin")
