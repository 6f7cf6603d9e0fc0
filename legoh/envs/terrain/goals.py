"""Expert navigation goals (appendix 5.2), in the tile frame of ``trails.py``.

1. Anchors: start, the waypoints each primitive asks for (stone centres, both lips of a
   ditch, both sides of a hurdle, platform tops), terminus.
2. Between two anchors the expert walks straight unless the chord passes within
   ``clearance`` of a trunk; then it takes the cheapest path on an 8-connected occupancy
   grid (``scipy.sparse.csgraph.dijkstra``), whose cell cost grows near trunks and carries
   smooth random noise, so detours keep their distance and differ between variants.
3. Each stretch is cut into evenly spaced waypoints (``spacing``); where a chord between two
   of them would cut within ``clearance`` of a trunk, the path point between them is added.
   Filler waypoints on keep-out cells (pits) or too close to a box are dropped; anchors stay.
"""

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from legoh.envs.terrain.primitives import Grid, smooth_noise

NEAR_COST = 2.0  # extra cost per metre right at the clearance limit
NEAR_DECAY = 0.5  # m over which the near-trunk cost fades
MIN_GAP = 0.3  # m: a filler closer than this to an anchor is dropped


def trunk_clearance(xy: np.ndarray, cylinders: np.ndarray, width: float) -> np.ndarray:
    """(...,) distance (m) from points ``xy`` (..., 2) to the nearest trunk surface or the
    tile's long side (a detour must stay inside its tile); inf-free."""
    side = np.minimum(xy[..., 1], width - xy[..., 1])
    if len(cylinders) == 0:
        return side
    diff = xy[..., None, :] - cylinders[:, :2]
    trunk = np.linalg.norm(diff, axis=-1) - cylinders[:, 3]
    return np.minimum(trunk.min(axis=-1), side)


def box_clearance(xy: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """(...,) distance (m) from points ``xy`` (..., 2) to the nearest box footprint."""
    if len(boxes) == 0:
        return np.full(xy.shape[:-1], np.inf)
    rel = xy[..., None, :] - boxes[:, :2]
    c, s = np.cos(boxes[:, 6]), np.sin(boxes[:, 6])
    local = np.stack([rel[..., 0] * c + rel[..., 1] * s, -rel[..., 0] * s + rel[..., 1] * c], -1)
    out = np.clip(np.abs(local) - boxes[:, 3:5], 0.0, None)
    return np.linalg.norm(out, axis=-1).min(axis=-1)


def _chord_clear(a: np.ndarray, b: np.ndarray, cylinders: np.ndarray, width: float,
                 clearance: float, step: float) -> bool:
    n = max(2, int(np.linalg.norm(b - a) / step) + 2)
    pts = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
    return bool(trunk_clearance(pts, cylinders, width).min() >= clearance)


def grid_path(cost: np.ndarray, free: np.ndarray, start: tuple[int, int],
              goal: tuple[int, int]) -> np.ndarray:
    """Cheapest 8-connected path of cells (P, 2) from ``start`` to ``goal`` over ``free``.

    ``cost`` (nx, ny) is the price of one cell-length step through a cell. Raises
    RuntimeError when ``goal`` cannot be reached (an impossible trail is a bug).
    """
    nx, ny = cost.shape
    idx = np.arange(nx * ny).reshape(nx, ny)
    src, dst, w = [], [], []
    for di, dj in ((1, 0), (0, 1), (1, 1), (1, -1)):
        a = idx[max(0, -di):nx - max(0, di), max(0, -dj):ny - max(0, dj)]
        b = idx[max(0, di):nx - max(0, -di) or None, max(0, dj):ny - max(0, -dj) or None]
        ok = free.ravel()[a] & free.ravel()[b]
        a, b = a[ok], b[ok]
        step = np.hypot(di, dj) * 0.5 * (cost.ravel()[a] + cost.ravel()[b])
        src += [a, b]
        dst += [b, a]
        w += [step, step]
    graph = csr_matrix((np.concatenate(w), (np.concatenate(src), np.concatenate(dst))),
                       shape=(nx * ny, nx * ny))
    s, g = idx[start], idx[goal]
    dist, pred = dijkstra(graph, indices=s, return_predecessors=True)
    if not np.isfinite(dist[g]):
        raise RuntimeError(f"no free path between cells {start} and {goal}")
    cells = [g]
    while cells[-1] != s:
        cells.append(pred[cells[-1]])
    return np.stack(np.unravel_index(np.array(cells[::-1]), (nx, ny)), axis=-1)


def detour(a: np.ndarray, b: np.ndarray, cylinders: np.ndarray, length: float, width: float,
           clearance: float, res: float, noise: float, rng: np.random.Generator) -> np.ndarray:
    """(P, 2) tile xy of a path from ``a`` to ``b`` that keeps ``clearance`` from trunks."""
    grid = Grid(length, width, res)
    xs, ys = grid.mesh()
    dist = trunk_clearance(np.stack([xs, ys], -1), cylinders, width)
    free = dist >= clearance + res  # one cell of margin for the rasterisation
    cost = 1.0 + NEAR_COST * np.exp(-np.clip(dist - clearance, 0, None) / NEAR_DECAY)
    cost += noise * 0.5 * (1.0 + smooth_noise(rng, grid, 1.0))

    def cell(p: np.ndarray) -> tuple[int, int]:
        ij = np.clip(np.round(p / res).astype(int), 0, [grid.nx - 1, grid.ny - 1])
        if not free[tuple(ij)]:  # an anchor right beside a trunk: start from the nearest free
            cand = np.argwhere(free)
            ij = cand[np.argmin(np.abs(cand - ij).sum(axis=1))]
        return int(ij[0]), int(ij[1])

    cells = grid_path(cost, free, cell(a), cell(b))
    return np.concatenate([a[None], cells[1:-1] * res, b[None]])


def _resample(path: np.ndarray, spacing: float) -> np.ndarray:
    """Indices of path points about every ``spacing`` m of arc (ends excluded)."""
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
    n = int(np.ceil(arc[-1] / spacing - 1e-6))
    if n <= 1:
        return np.zeros(0, dtype=int)
    targets = arc[-1] * np.arange(1, n) / n
    return np.unique(np.searchsorted(arc, targets))


def _fill(path: np.ndarray, spacing: float, cylinders: np.ndarray, width: float,
          clearance: float, step: float) -> list[int]:
    """Evenly spaced path indices, refined until every chord keeps ``clearance``."""
    picks = [0, *_resample(path, spacing).tolist(), len(path) - 1]
    k = 0
    while k < len(picks) - 1:
        i, j = picks[k], picks[k + 1]
        if j - i > 1 and not _chord_clear(path[i], path[j], cylinders, width, clearance, step):
            picks.insert(k + 1, (i + j) // 2)
            continue
        k += 1
    return picks[1:-1]


def expert_goals(anchors: np.ndarray, cylinders: np.ndarray, boxes: np.ndarray,
                 keepout: np.ndarray, length: float, width: float, res: float, spacing: float,
                 clearance: float, plan_res: float, noise: float,
                 rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Waypoints (W, 2) after the start, terminus last, and the dense path (P, 2), tile xy.

    keepout: (nx, ny) cells at ``res`` m where no filler waypoint may go.
    """
    waypoints, pieces = [], [anchors[:1]]
    for a, b in zip(anchors[:-1], anchors[1:], strict=True):
        straight = _chord_clear(a, b, cylinders, width, clearance, plan_res)
        if straight:
            n = max(2, int(np.linalg.norm(b - a) / plan_res) + 1)
            path = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
        else:
            path = detour(a, b, cylinders, length, width, clearance, plan_res, noise, rng)
        fill = path[_fill(path, spacing, cylinders, width, clearance, plan_res)]
        ij = np.clip(np.round(fill / res).astype(int), 0, np.array(keepout.shape) - 1)
        ok = ~keepout[ij[:, 0], ij[:, 1]] & (box_clearance(fill, boxes) >= clearance)
        ok &= (np.linalg.norm(fill - a, axis=1) > MIN_GAP) & (np.linalg.norm(fill - b, axis=1)
                                                               > MIN_GAP)
        waypoints += [fill[ok], b[None]]
        pieces.append(path[1:])
    return np.concatenate(waypoints), np.concatenate(pieces)


def middle_index(start: np.ndarray, waypoints: np.ndarray) -> tuple[int, float]:
    """Index of the waypoint nearest half-way along start -> waypoints, and the total length
    (m) of that polyline. Works on xy or xyz rows."""
    pts = np.concatenate([start[None], waypoints])
    arc = np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))
    return int(np.argmin(np.abs(arc - arc[-1] / 2))), float(arc[-1])
