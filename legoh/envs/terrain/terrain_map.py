"""The terrain map: every tile a run needs in one height field, plus static obstacles.

World frame: cell [i, j] of ``heights`` is the ground at x = origin[0] + i * resolution,
y = origin[1] + j * resolution (m). Tiles sit on a grid, one row per (category, level) and
one column per variant; a border of ``cfg.border`` m separates them and rings the map. Each
tile's ground ramps down to 0 over the inner three quarters of its half-border (a "skirt"),
so the ground is continuous and a robot that walks off a tile stands on flat ground.
"""

import zlib
from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import distance_transform_edt, map_coordinates

from legoh.envs.terrain.goals import expert_goals, middle_index
from legoh.envs.terrain.obstacles import footing_mask, obstacle_ahead, obstacle_mask
from legoh.envs.terrain.trails import TileLayout, check_category, compose_tile, geometry_name

SKIRT_RAMP = 0.75  # share of the half-border the skirt ramps over; the rest stays flat at 0
BOX_SINK = 0.05  # m boxes reach below the ground at their centre (no floating on slopes)
TRUNK_SINK = 0.2  # m trunks reach below the ground at their centre


def bilinear(grid: np.ndarray, origin: np.ndarray, res: float, xy: np.ndarray) -> np.ndarray:
    """Bilinear lookup of a (nx, ny) grid (cell [i, j] at origin + (i, j) * res) at world
    points ``xy`` (..., 2), clamped at the edges."""
    xy = np.asarray(xy, dtype=np.float64)
    nx, ny = grid.shape
    u = np.clip((xy[..., 0] - origin[0]) / res, 0.0, nx - 1.000001)
    v = np.clip((xy[..., 1] - origin[1]) / res, 0.0, ny - 1.000001)
    i, j = u.astype(np.int64), v.astype(np.int64)
    fu, fv = u - i, v - j
    return ((1 - fu) * (1 - fv) * grid[i, j] + fu * (1 - fv) * grid[i + 1, j]
            + (1 - fu) * fv * grid[i, j + 1] + fu * fv * grid[i + 1, j + 1])


@dataclass
class Tile:
    """One trail tile, world frame (m, rad); the trail runs along +x."""

    category: str
    level: int
    variant: int
    origin: np.ndarray  # (2,) world xy of the tile's corner (tile x = 0, y = 0)
    size: np.ndarray  # (2,) m, length along x and width along y
    start: np.ndarray  # (3,) spawn point on the ground
    start_yaw: float  # rad, 0: facing +x, along the trail
    waypoints: np.ndarray  # (W, 3) expert goals in order; the last one is the terminus
    terminus: np.ndarray  # (3,)
    middle: np.ndarray  # (3,) the waypoint nearest half-way along the trail
    length: float  # m, start -> waypoints -> terminus
    path: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (P, 3) dense path
    plan: list = field(default_factory=list)  # [(primitive, segment length m), ...]
    # (W,) bool: the category's obstacle lies on the path from waypoint w to the terminus
    # (``obstacles.obstacle_ahead``): where protocol v2 may spawn a robot
    ahead: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))


@dataclass
class TerrainMap:
    """All tiles of a run; see the module docstring for frames."""

    heights: np.ndarray  # (nx, ny) float32, m, ground only
    resolution: float  # m per cell
    origin: np.ndarray  # (2,) world xy of cell [0, 0]
    boxes: np.ndarray  # (M, 7) float32: centre xyz, half sizes xyz, yaw
    cylinders: np.ndarray  # (K, 5) float32: centre xyz, radius, half-height
    tiles: list[Tile]
    edge_mask: np.ndarray  # (nx, ny) bool, True on step and gap borders
    categories: list[str]
    levels: int
    variants: int
    # (nx, ny) bool, True where a foot may start: not over a pit or inside a ditch, not
    # under a hurdle or in a trunk (``obstacles.footing_mask``); the borders are flat ground
    footing: np.ndarray | None = None

    def height_at(self, xy: np.ndarray) -> np.ndarray:
        """Bilinear ground height (m) at world points ``xy`` (..., 2); clamped at the map
        edge. Vectorised: no Python loop over points."""
        return bilinear(self.heights, self.origin, self.resolution, xy)

    def tile_index(self, category: str, level: int, variant: int) -> int:
        """Index into ``tiles``; raises ValueError naming the valid range."""
        if category not in self.categories:
            raise ValueError(f"category {category!r} is not in this map; valid: "
                             f"{self.categories}")
        if not 0 <= level < self.levels:
            raise ValueError(f"level {level} out of range; valid: 0..{self.levels - 1}")
        if not 0 <= variant < self.variants:
            raise ValueError(f"variant {variant} out of range; valid: 0..{self.variants - 1}")
        c = self.categories.index(category)
        return (c * self.levels + level) * self.variants + variant


def difficulty(level: int, levels: int) -> float:
    """Level 0 is difficulty 0, the top level is 1, evenly in between."""
    return level / (levels - 1) if levels > 1 else 0.0


def tile_rng(seed: int, category: str, level: int, variant: int) -> np.random.Generator:
    """Generator of one tile: depends on the seed and the tile's key only, so a tile is the
    same whatever else the map holds."""
    key = (zlib.crc32(category.encode()), level, variant)
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=key))


def edge_mask(heights: np.ndarray, resolution: float, grade: float) -> np.ndarray:
    """(nx, ny) bool: True on both cells of any neighbour pair whose rise over run exceeds
    ``grade``."""
    limit = grade * resolution
    mask = np.zeros(heights.shape, dtype=bool)
    for axis in (0, 1):
        jump = np.abs(np.diff(heights, axis=axis)) > limit
        lo = [slice(None)] * 2
        hi = [slice(None)] * 2
        lo[axis], hi[axis] = slice(None, -1), slice(1, None)
        mask[tuple(lo)] |= jump
        mask[tuple(hi)] |= jump
    return mask


def _skirted(heights: np.ndarray, half: int, ramp: float) -> np.ndarray:
    """The tile padded by ``half`` cells each side, its edge heights fading to 0 over
    ``ramp`` cells."""
    nx, ny = heights.shape
    out = np.zeros((nx + 2 * half, ny + 2 * half))
    out[half:half + nx, half:half + ny] = heights
    outside = np.ones(out.shape, dtype=bool)
    outside[half:half + nx, half:half + ny] = False
    dist, (ii, jj) = distance_transform_edt(outside, return_indices=True)
    fade = np.clip(1.0 - dist / max(ramp, 1.0), 0.0, 1.0)
    return np.where(outside, out[ii, jj] * fade, out)


def _on_ground(local_h: np.ndarray, res: float, xy: np.ndarray) -> np.ndarray:
    """Bilinear tile heights at tile xy (N, 2)."""
    return map_coordinates(local_h, [xy[:, 0] / res, xy[:, 1] / res], order=1, mode="nearest")


def build_terrain_map(cfg, seed: int) -> TerrainMap:
    """Build every (category, level, variant) tile of ``cfg`` (a TrailConfig or a DictConfig
    with its fields) into one map. Same ``seed``, same map, bit for bit."""
    categories = [str(c) for c in cfg.categories]
    if not categories:
        raise ValueError("trail config lists no categories")
    for c in categories:
        check_category(c)
    geometry_name(cfg)  # a bad trail.geometry fails here, before any tile is built
    levels, variants, res = int(cfg.levels), int(cfg.variants), float(cfg.resolution)
    if levels < 1 or variants < 1:
        raise ValueError(f"levels and variants must be >= 1, got {levels}, {variants}")
    ntx, nty = int(round(cfg.tile_length / res)), int(round(cfg.tile_width / res))
    half = int(round(cfg.border / res / 2))
    rows, cols = len(categories) * levels, variants
    heights = np.zeros((cols * (ntx + 2 * half) + 2 * half, rows * (nty + 2 * half) + 2 * half),
                       dtype=np.float32)
    origin = np.zeros(2)
    footing = np.ones(heights.shape, dtype=bool)
    tiles, boxes, cyls = [], [], []
    for c, category in enumerate(categories):
        for level in range(levels):
            for variant in range(variants):
                row, col = c * levels + level, variant
                i0, j0 = 2 * half + col * (ntx + 2 * half), 2 * half + row * (nty + 2 * half)
                rng = tile_rng(seed, category, level, variant)
                lay = compose_tile(category, difficulty(level, levels), rng, cfg)
                heights[i0 - half:i0 + ntx + half, j0 - half:j0 + nty + half] = _skirted(
                    lay.heights, half, SKIRT_RAMP * half)
                footing[i0:i0 + ntx, j0:j0 + nty] = footing_mask(lay, res)
                corner = origin + np.array([i0, j0]) * res
                tile, b, k = _make_tile(lay, cfg, category, level, variant, corner, rng)
                tiles.append(tile)
                boxes.append(b)
                cyls.append(k)
    return TerrainMap(heights, res, origin, np.concatenate(boxes).astype(np.float32),
                      np.concatenate(cyls).astype(np.float32), tiles,
                      edge_mask(heights, res, cfg.edge_grade), categories, levels, variants,
                      footing)


def _make_tile(lay: TileLayout, cfg, category: str, level: int, variant: int,
               corner: np.ndarray, rng: np.random.Generator):
    """Goals, world coordinates and obstacles of one composed tile."""
    res = float(cfg.resolution)
    wps, path = expert_goals(lay.anchors, lay.cylinders, lay.boxes, _dilate(lay.keepout, res),
                             cfg.tile_length, cfg.tile_width, res, cfg.goal_spacing,
                             cfg.clearance, cfg.plan_resolution, cfg.detour_noise, rng)

    def world(xy: np.ndarray) -> np.ndarray:
        return np.concatenate([xy + corner, _on_ground(lay.heights, res, xy)[:, None]], axis=1)

    start = world(lay.anchors[:1])[0]
    waypoints = world(wps)
    mid, length = middle_index(start, waypoints)
    boxes = lay.boxes.copy()
    boxes[:, 2] += _on_ground(lay.heights, res, boxes[:, :2]) - BOX_SINK / 2
    boxes[:, 5] += BOX_SINK / 2
    boxes[:, :2] += corner
    cyl = lay.cylinders.copy()
    cyl[:, 2] += _on_ground(lay.heights, res, cyl[:, :2]) - TRUNK_SINK / 2
    cyl[:, 4] += TRUNK_SINK / 2
    cyl[:, :2] += corner
    rng.random()  # the draw of a per-tile friction no scene ever used: kept, maps stay as they were
    tile = Tile(category, level, variant, corner.copy(),
                np.array([cfg.tile_length, cfg.tile_width]), start, 0.0, waypoints,
                waypoints[-1].copy(), waypoints[mid].copy(), length, world(path), lay.plan,
                obstacle_ahead(wps, obstacle_mask(lay, category, res, cfg.start_pad), res))
    return tile, boxes, cyl


def _dilate(keepout: np.ndarray, res: float, margin: float = 0.1) -> np.ndarray:
    """Keep-out cells grown by ``margin`` m: no waypoint on the lip of a pit."""
    if not keepout.any():
        return keepout
    return distance_transform_edt(~keepout) * res <= margin
