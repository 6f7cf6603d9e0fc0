"""Is a tile passable? Two checks.

1. :func:`reachable`: connectivity of standing cells under a step and a leap budget. Two
   cells are linked when they lie within ``max_leap`` m of each other and their surfaces
   differ by at most ``max_step`` m. The surface is the ground raised to the top of any box
   (hurdles are stepped over, not walked through); trunks are not standable. A leap may
   cross anything lower in between (a gap, a pit); this is the humanoid's budget, not its gait.
2. :func:`leg_problems`: what one robot's leg (:data:`LEGS`) meets along the expert's path,
   measured from the geometry (:func:`measure_path`): every pit it must stride over within
   its step reach, every hurdle within its leg lift, every stone or platform at least a
   sole, and each stride's two supports together as wide as its stance.
"""

from dataclasses import dataclass, field

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


# ---- the robot's leg along the expert path ------------------------------------------------

STRIDE_ANGLE = np.radians(35.0)  # each leg this far off vertical: a long stride, no flight
EDGE_GRADE = 1.0  # rise over run: steeper than 45 degrees is a wall, not a slope to walk
GAP_DROP = 0.1  # m: a wall lower than this is a bump in the ground, not a pit's side


@dataclass(frozen=True)
class Legs:
    """One robot's leg, measured on its Menagerie MJCF in the default pose (joint anchors
    and the sole colliders; docs/terrain.md, "Trails that teach")."""

    name: str
    leg: float  # m, hip-pitch axis to sole with the knee straight (thigh + shin + ankle)
    thigh: float  # m, hip-pitch axis to knee axis
    foot_length: float  # m, sole heel to toe
    foot_width: float  # m, sole across
    feet_apart: float  # m, between the two feet's centres, standing

    @property
    def reach(self) -> float:
        """m, foot centre to foot centre in the longest stride without a flight phase."""
        return 2.0 * np.sin(STRIDE_ANGLE) * self.leg

    @property
    def max_gap(self) -> float:
        """m, the widest pit one stride spans, rim to rim: both soles on the rims."""
        return self.reach - self.foot_length

    @property
    def lift(self) -> float:
        """m, the height a swing foot clears with its thigh raised level: the thigh."""
        return self.thigh

    @property
    def stance_width(self) -> float:
        """m, across both soles standing: what a stride's supports offer a natural gait."""
        return self.feet_apart + self.foot_width


LEGS: dict[str, Legs] = {
    "h1": Legs("h1", leg=0.87, thigh=0.40, foot_length=0.20, foot_width=0.09, feet_apart=0.41),
    "g1": Legs("g1", leg=0.69, thigh=0.34, foot_length=0.18, foot_width=0.07, feet_apart=0.24),
}


@dataclass
class PathMeasures:
    """What the expert path asks of a leg, in m (lists in path order).

    pits: (rim-to-rim length, depth) of every pit the path crosses (a steep wall down, then a
    steep wall up). strides: the pits that must be stepped over (a wall beyond the lift or a
    floor shorter than a sole). supports: (length along the path, width across) of the
    ground between two strides (a stone, a platform). spans / overlaps: across the two
    supports of each stride, their joint extent and their shared width. steps: the rise of
    every steep wall outside a pit. hurdles: the height of every box of the tile.
    """

    pits: list[tuple[float, float]] = field(default_factory=list)
    strides: list[tuple[float, float]] = field(default_factory=list)
    supports: list[tuple[float, float]] = field(default_factory=list)
    spans: list[float] = field(default_factory=list)
    overlaps: list[float] = field(default_factory=list)
    steps: list[float] = field(default_factory=list)
    hurdles: list[float] = field(default_factory=list)


def path_profile(tm, tile, res: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The dense expert path resampled every ``res`` m: arc length (P,), world xy (P, 2),
    ground height (P,)."""
    pts = tile.path[:, :2]
    keep = np.concatenate([[True], np.linalg.norm(np.diff(pts, axis=0), axis=1) > 1e-9])
    pts = pts[keep]
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    s = np.arange(0.0, arc[-1], res)
    xy = np.stack([np.interp(s, arc, pts[:, 0]), np.interp(s, arc, pts[:, 1])], axis=-1)
    return s, xy, tm.height_at(xy)


def walls(s: np.ndarray, h: np.ndarray) -> list[tuple[int, int, float, float]]:
    """Steep stretches of a profile, each (first sample, last sample, rise m, edge m): runs
    of samples steeper than :data:`EDGE_GRADE` going one way, rising or falling more than
    GAP_DROP. ``edge`` is the arc length where the wall is GAP_DROP below its top rim (where a
    sole would slip off), interpolated: a rasterised vertical wall measures true to ~1 cm."""
    dh = np.diff(h)
    sign = np.where(np.abs(dh) > EDGE_GRADE * np.diff(s), np.sign(dh), 0.0)
    cuts = np.flatnonzero(np.diff(np.concatenate([[0.0], sign, [0.0]])))  # run boundaries
    out = []
    for a, b in zip(cuts[:-1], cuts[1:], strict=True):
        rise = float(h[b] - h[a])
        if sign[a] != 0 and abs(rise) > GAP_DROP:
            top = max(h[a], h[b]) - GAP_DROP
            seg_s, seg_h = s[a:b + 1], h[a:b + 1]
            if rise > 0:  # np.interp needs increasing heights: walk a rising wall
                edge = np.interp(top, seg_h, seg_s)
            else:
                edge = np.interp(top, seg_h[::-1], seg_s[::-1])
            out.append((int(a), int(b), rise, float(edge)))
    return out


def _across(tm, tile, xy: np.ndarray, res: float) -> tuple[float, float]:
    """(low, high) world y of the ground around ``xy`` across the tile that is no more than
    GAP_DROP below it: the width a support offers the feet there."""
    ys = np.arange(tile.origin[1], tile.origin[1] + tile.size[1], res)
    h = tm.height_at(np.stack([np.full_like(ys, xy[0]), ys], axis=-1))
    ok = h >= tm.height_at(xy[None])[0] - GAP_DROP
    j = int(np.clip(np.round((xy[1] - ys[0]) / res), 0, len(ys) - 1))
    lo = j - int(np.argmin(ok[j::-1])) if not ok[j::-1].all() else 0
    hi = j + int(np.argmin(ok[j:])) if not ok[j:].all() else len(ys)
    return float(ys[0] + lo * res), float(ys[0] + hi * res)


def _hurdles(tm, tile) -> list[float]:
    lo, hi = tile.origin - 1.0, tile.origin + tile.size + 1.0  # obstacles of this tile only
    b = tm.boxes[((tm.boxes[:, :2] > lo) & (tm.boxes[:, :2] < hi)).all(axis=1)]
    return (b[:, 2] + b[:, 5] - tm.height_at(b[:, :2])).tolist()


def measure_path(tm, tile, legs: Legs, res: float | None = None) -> PathMeasures:
    """Everything :class:`PathMeasures` lists, for ``legs`` (which pits are strides depends
    on its lift and sole), sampled every ``res`` m (half a map cell by default)."""
    res = res or tm.resolution / 2
    s, xy, h = path_profile(tm, tile, res)
    out = PathMeasures(hurdles=_hurdles(tm, tile))
    ws, in_pit, rims = walls(s, h), set(), [s[0]]  # rims: arc lengths bounding supports
    for (a, b, down, e0), (c, e, up, e1) in zip(ws[:-1], ws[1:], strict=True):
        if down >= 0 or up <= 0:
            continue
        in_pit |= {a, c}
        depth = min(h[a], h[e]) - h[b:c + 1].min()
        out.pits.append((e1 - e0, float(depth)))
        if max(-down, up) > legs.lift or s[c] - s[b] < legs.foot_length:
            out.strides.append((e1 - e0, float(depth)))
            rims += [e0, e1]
    out.steps = [abs(rise) for a, _, rise, _ in ws if a not in in_pit]
    rims.append(s[-1])
    _supports(tm, tile, s, xy, rims, legs, out)
    return out


def _supports(tm, tile, s: np.ndarray, xy: np.ndarray, rims: list[float], legs: Legs,
              out: PathMeasures) -> None:
    """Fill supports, spans and overlaps; ``rims`` (arc lengths) go in pairs: a support runs
    from one stride's far rim to the next stride's near rim."""
    across = []
    res = float(s[1] - s[0]) if len(s) > 1 else 0.05
    for k in range(0, len(rims), 2):
        a, b = rims[k], rims[k + 1]
        first, last = k == 0, k + 2 >= len(rims)
        # a stone is measured across its middle, the open ground a sole's length from the rim
        at = b - legs.foot_length / 2 if first else a + legs.foot_length / 2 if last else (
            a + b) / 2
        i = int(np.clip(np.searchsorted(s, at), 0, len(s) - 1))
        across.append(_across(tm, tile, xy[i], res))
        if not (first or last):
            out.supports.append((float(b - a), across[-1][1] - across[-1][0]))
    for (lo0, hi0), (lo1, hi1) in zip(across[:-1], across[1:], strict=True):
        out.spans.append(max(hi0, hi1) - min(lo0, lo1))
        out.overlaps.append(min(hi0, hi1) - max(lo0, lo1))


def leg_problems(m: PathMeasures, legs: Legs, slack: float = 0.0) -> list[str]:
    """What ``legs`` cannot do of ``m`` (empty: every step is within the leg). ``slack`` m
    of rasterisation tolerance on lengths and widths (a map cell when measured coarse)."""
    out = [f"stride over a {g:.2f} m pit beyond the {legs.max_gap:.2f} m reach"
           for g, _ in m.strides if g > legs.max_gap + slack]
    out += [f"{h:.2f} m hurdle beyond the {legs.lift:.2f} m lift" for h in m.hurdles
            if h > legs.lift + 1e-6]
    out += [f"{r:.2f} m step beyond the {legs.lift:.2f} m lift" for r in m.steps
            if r > legs.lift + 1e-6]
    out += [f"{n:.2f} x {w:.2f} m support smaller than a {legs.foot_length:.2f} x "
            f"{legs.foot_width:.2f} m sole" for n, w in m.supports
            if n < legs.foot_length - slack or w < legs.foot_width - slack]
    out += [f"stride supports {w:.2f} m across, narrower than the {legs.stance_width:.2f} m "
            f"stance" for w in m.spans if w < legs.stance_width - slack]
    return out
