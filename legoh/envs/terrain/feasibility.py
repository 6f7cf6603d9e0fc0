"""Is a tile passable? Connectivity of standing cells under a step and a leap budget.

Two cells are linked when they lie within ``max_leap`` m of each other and their surfaces
differ by at most ``max_step`` m. The surface is the ground raised to the top of any box
(hurdles are stepped over, not walked through); trunks are not standable. A leap may cross
anything lower in between (a gap, a pit); this is the humanoid's budget, not its gait.
"""

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

MAX_STEP = 0.25  # m, largest single step up or down a humanoid is asked to make at level <= 2
MAX_LEAP = 0.5  # m, longest stride across a gap at level <= 2


def surface(tm, tile, res: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tile surface sampled every ``res`` m: (heights (nx, ny), standable (nx, ny), world
    xy (nx, ny, 2)). Heights include box tops; cells inside a trunk are not standable."""
    xs = tile.origin[0] + np.arange(0.0, tile.size[0], res)
    ys = tile.origin[1] + np.arange(0.0, tile.size[1], res)
    xy = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1)
    h = tm.height_at(xy)
    lo, hi = tile.origin - 1.0, tile.origin + tile.size + 1.0  # obstacles of this tile only
    boxes = tm.boxes[((tm.boxes[:, :2] > lo) & (tm.boxes[:, :2] < hi)).all(axis=1)]
    cylinders = tm.cylinders[((tm.cylinders[:, :2] > lo) & (tm.cylinders[:, :2] < hi)).all(1)]
    for b in boxes:
        rel = xy - b[:2]
        c, s = np.cos(b[6]), np.sin(b[6])
        inside = (np.abs(rel[..., 0] * c + rel[..., 1] * s) <= b[3]) & (
            np.abs(-rel[..., 0] * s + rel[..., 1] * c) <= b[4])
        h = np.where(inside, np.maximum(h, b[2] + b[5]), h)
    standable = np.ones(h.shape, dtype=bool)
    for k in cylinders:
        standable &= np.linalg.norm(xy - k[:2], axis=-1) > k[3]
    return h, standable, xy


def components(h: np.ndarray, standable: np.ndarray, res: float, max_step: float = MAX_STEP,
               max_leap: float = MAX_LEAP) -> np.ndarray:
    """(nx, ny) int label of each cell's connected region (-1 where not standable)."""
    nx, ny = h.shape
    idx = np.arange(nx * ny).reshape(nx, ny)
    k = int(np.floor(max_leap / res + 1e-6))  # 0.6 / 0.1 is 5.999...
    src, dst = [], []
    for di in range(0, k + 1):
        for dj in range(-k, k + 1):
            if (di == 0 and dj <= 0) or di * di + dj * dj > k * k:
                continue  # each undirected offset once, inside the leap disc
            a = (slice(0, nx - di), slice(max(0, -dj), ny - max(0, dj)))
            b = (slice(di, nx), slice(max(0, dj), ny - max(0, -dj) or None))
            ok = standable[a] & standable[b] & (np.abs(h[a] - h[b]) <= max_step)
            src.append(idx[a][ok])
            dst.append(idx[b][ok])
    src, dst = np.concatenate(src), np.concatenate(dst)
    graph = coo_matrix((np.ones(len(src), dtype=np.int8), (src, dst)), shape=(nx * ny,) * 2)
    _, labels = connected_components(graph, directed=False)
    return np.where(standable, labels.reshape(nx, ny), -1)


def reachable(tm, tile, res: float = 0.1, max_step: float = MAX_STEP,
              max_leap: float = MAX_LEAP) -> bool:
    """True when start, every waypoint and the terminus share one connected region."""
    h, standable, _ = surface(tm, tile, res)
    labels = components(h, standable, res, max_step, max_leap)
    pts = np.concatenate([tile.start[None, :2], tile.waypoints[:, :2]]) - tile.origin
    ij = np.clip(np.round(pts / res).astype(int), 0, np.array(h.shape) - 1)
    lab = labels[ij[:, 0], ij[:, 1]]
    return bool((lab >= 0).all() and (lab == lab[0]).all())
