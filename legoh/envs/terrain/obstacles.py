"""Where a robot may start and what lies ahead of it: the masks behind the benchmark's
spawn rules (protocol v2, docs/metrics.md) and any spawn along a trail.

Tile frame and cells as in ``trails.py`` (cell [i, j] at x = i * res, y = j * res).

* **footing**: cells a foot may start on: not a pit floor or a ditch's inside (the
  primitives' keep-out), not under a hurdle, not inside a trunk.
* **obstacle**: the cells of a category's own obstacle (:data:`CATEGORY_OBSTACLES`): the
  pits of Gap's stones and gaps, Ditch's ditches, Hurdle's hurdles, Forest's trunks (grown
  by :data:`TRUNK_REACH`: the expert path keeps its clearance from them), every segment of
  RandomMix's mix.
* **ahead**: per expert waypoint, whether the path from it to the terminus (through the
  later waypoints) crosses the obstacle at least :data:`AHEAD_MIN` m on.
"""

import numpy as np

from legoh.envs.terrain.trails import CATEGORIES, OPEN_MIX, TileLayout

# The primitives that are each category's obstacle ("a gap on Gap, a hurdle on Hurdle");
# a category without one (flat) has nothing to put ahead. Hill: any of its stretches'.
CATEGORY_OBSTACLES: dict[str, tuple[str, ...]] = {
    "flat": (),
    "randommix": OPEN_MIX,
    "ditch": ("ditch",),
    "hurdle": ("hurdles",),
    "gap": ("stones", "stones_staggered", "gaps"),
    "forest": ("trees",),
}
CATEGORY_OBSTACLES["hill"] = tuple(dict.fromkeys(
    p for c in CATEGORIES for p in CATEGORY_OBSTACLES[c]))
TRUNK_REACH = 1.5  # m from a trunk surface: the path "meets" the tree (corridors keep 1.05 m)
AHEAD_MIN = 0.3  # m of path beyond the waypoint: the obstacle is ahead of the robot's toes
PATH_STEP = 0.5  # sample the path every PATH_STEP cells: a 1-cell gap is never skipped


def _in_boxes(xs: np.ndarray, ys: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """Bool mask of the points (xs, ys) inside any box footprint (rows as Patch.boxes)."""
    out = np.zeros(xs.shape, dtype=bool)
    for b in boxes:
        c, s = np.cos(b[6]), np.sin(b[6])
        dx, dy = xs - b[0], ys - b[1]
        out |= (np.abs(dx * c + dy * s) <= b[3]) & (np.abs(-dx * s + dy * c) <= b[4])
    return out


def _in_discs(xs: np.ndarray, ys: np.ndarray, cylinders: np.ndarray,
              grow: float = 0.0) -> np.ndarray:
    """Bool mask of the points inside any trunk disc grown by ``grow`` m."""
    out = np.zeros(xs.shape, dtype=bool)
    for k in cylinders:
        out |= (xs - k[0]) ** 2 + (ys - k[1]) ** 2 <= (k[3] + grow) ** 2
    return out


def footing_mask(lay: TileLayout, res: float) -> np.ndarray:
    """(nx, ny) bool, True where a foot may start (module docstring)."""
    xs, ys = np.meshgrid(np.arange(lay.heights.shape[0]) * res,
                         np.arange(lay.heights.shape[1]) * res, indexing="ij")
    return ~(lay.keepout | _in_boxes(xs, ys, lay.boxes) | _in_discs(xs, ys, lay.cylinders))


def obstacle_mask(lay: TileLayout, category: str, res: float, start_pad: float) -> np.ndarray:
    """(nx, ny) bool: the cells of ``category``'s obstacle in the tile (module docstring).

    Segment by segment (``lay.plan``, from ``start_pad``): a segment of an obstacle
    primitive contributes its keep-out cells (pits, a ditch's inside), its hurdles and its
    grown trunks; one with none of those (a slope, stairs: RandomMix) all its cells."""
    kinds = CATEGORY_OBSTACLES[category]
    nx, ny = lay.heights.shape
    out = np.zeros((nx, ny), dtype=bool)
    i0 = int(round(start_pad / res))
    for name, length in lay.plan:
        i1 = i0 + int(round(length / res))
        if name in kinds:
            xs, ys = np.meshgrid(np.arange(i0, i1) * res, np.arange(ny) * res, indexing="ij")
            inside = (lay.boxes[:, 0] >= i0 * res) & (lay.boxes[:, 0] < i1 * res)
            near = (lay.cylinders[:, 0] >= i0 * res) & (lay.cylinders[:, 0] < i1 * res)
            seg = (lay.keepout[i0:i1] | _in_boxes(xs, ys, lay.boxes[inside])
                   | _in_discs(xs, ys, lay.cylinders[near], TRUNK_REACH))
            out[i0:i1] = seg if seg.any() else True
        i0 = i1
    return out


def obstacle_ahead(waypoints: np.ndarray, obstacle: np.ndarray, res: float) -> np.ndarray:
    """(W,) bool: does the path waypoint w -> w + 1 -> ... -> the last one (tile xy (W, 2))
    cross an ``obstacle`` cell at least :data:`AHEAD_MIN` m beyond waypoint w?"""
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(waypoints, axis=0), axis=1))])
    if not obstacle.any() or len(waypoints) < 2:
        return np.zeros(len(waypoints), dtype=bool)
    s = np.arange(0.0, arc[-1], PATH_STEP * res)
    pts = np.stack([np.interp(s, arc, waypoints[:, 0]), np.interp(s, arc, waypoints[:, 1])], -1)
    ij = np.clip(np.round(pts / res).astype(int), 0, np.array(obstacle.shape) - 1)
    hits = s[obstacle[ij[:, 0], ij[:, 1]]]
    last = hits.max() if len(hits) else -np.inf  # the farthest crossing decides "ahead"
    return last >= arc + AHEAD_MIN
