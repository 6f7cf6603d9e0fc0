"""The 16 terrain primitives: small pure functions of (difficulty, generator, grid).

Every primitive fills one *segment* of a trail tile. Segment frame: x runs along the trail
from the segment's entry (x = 0) to its exit (x = ``grid.length``), y runs across the tile
from its right edge (y = 0) to its left edge (y = ``grid.width``); the trail's centre line
is y = width / 2. Heights are metres relative to the ground at the entry (0 there), and the
exit row sits at ``Patch.exit_height`` so the next segment joins without a step.

Register your own with :func:`register_primitive`; the trail composer only needs the name.
"""

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import map_coordinates

PIT_DEPTH = 1.0  # m, depth of the void under stepping stones and gaps at the top level
LANDING = 0.6  # m of level ground a gap-like primitive keeps at its entry and exit
TAPER = 0.5  # m over which noise fades in at segment ends (joins stay step-free)
ROBOT_HALF_WIDTH = 0.35  # m, half the shoulder width of an H1; corridors are cut this wide


@dataclass(frozen=True)
class Grid:
    """Sampling of one segment: cell (i, j) is the point x = i * res, y = j * res (m)."""

    length: float  # m along the trail
    width: float  # m across the trail
    res: float  # m per cell
    clearance: float = 0.4  # m a waypoint keeps from any obstacle
    geometry: str = "v2"  # which :data:`GEOMETRIES` table the gap-like primitives read

    @property
    def nx(self) -> int:
        return int(round(self.length / self.res))

    @property
    def ny(self) -> int:
        return int(round(self.width / self.res))

    @property
    def x(self) -> np.ndarray:
        """(nx,) segment x of each row, m."""
        return np.arange(self.nx) * self.res

    @property
    def y(self) -> np.ndarray:
        """(ny,) segment y of each column, m."""
        return np.arange(self.ny) * self.res

    def mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """(nx, ny) x and y of every cell, m."""
        return np.meshgrid(self.x, self.y, indexing="ij")


def _empty(n: int) -> np.ndarray:
    return np.zeros((0, n))


@dataclass
class Patch:
    """What a primitive returns, all in the segment frame (see module docstring).

    heights: (nx, ny) m. boxes: (M, 7) centre x, y, z-above-local-ground, half sizes x, y,
    z, yaw (rad). cylinders: (K, 5) centre x, y, z-above-local-ground, radius, half-height.
    waypoints: (W, 2) xy the primitive wants the expert to visit, in order. keepout: (nx, ny)
    bool, cells nobody should stand on (the floor of a pit). params: the sampled properties.
    """

    heights: np.ndarray
    exit_height: float = 0.0
    boxes: np.ndarray = field(default_factory=lambda: _empty(7))
    cylinders: np.ndarray = field(default_factory=lambda: _empty(5))
    waypoints: np.ndarray = field(default_factory=lambda: _empty(2))
    keepout: np.ndarray | None = None
    params: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.keepout is None:
            self.keepout = np.zeros(self.heights.shape, dtype=bool)

    def negated(self) -> "Patch":
        """The same segment mirrored in height (an up-slope becomes a down-slope)."""
        return Patch(-self.heights, -self.exit_height, self.boxes, self.cylinders,
                     self.waypoints, self.keepout, dict(self.params))


PrimitiveFn = Callable[[float, np.random.Generator, Grid], Patch]


@dataclass(frozen=True)
class PrimitiveSpec:
    """A registered primitive, the property that grows with difficulty, and its bounds."""

    fn: PrimitiveFn
    prop: str  # name of the measured property in ``Patch.params``
    bounds: tuple[float, float]  # documented min and max of ``prop`` over difficulty [0, 1]
    doc: str


PRIMITIVES: dict[str, PrimitiveSpec] = {}


def register_primitive(name: str, prop: str, bounds: tuple[float, float], doc: str):
    """Decorator: add a primitive to :data:`PRIMITIVES` under ``name``."""

    def wrap(fn: PrimitiveFn) -> PrimitiveFn:
        PRIMITIVES[name] = PrimitiveSpec(fn, prop, bounds, doc)
        return fn

    return wrap


def make_patch(name: str, difficulty: float, rng: np.random.Generator, grid: Grid) -> Patch:
    """Run primitive ``name``; raises ValueError naming the valid choices."""
    if name not in PRIMITIVES:
        raise ValueError(f"unknown terrain primitive {name!r}; valid: {sorted(PRIMITIVES)}")
    if not 0.0 <= difficulty <= 1.0:
        raise ValueError(f"difficulty must lie in [0, 1], got {difficulty}")
    return PRIMITIVES[name].fn(float(difficulty), rng, grid)


# ---- helpers ------------------------------------------------------------------------------


def lerp(a: float, b: float, d: float) -> float:
    """a at difficulty 0, b at difficulty 1."""
    return a + (b - a) * d


def jitter(rng: np.random.Generator, value: float, lo: float, hi: float, rel: float = 0.1):
    """``value`` scaled by a random factor in [1 - rel, 1 + rel], clipped to [lo, hi]."""
    return float(np.clip(value * rng.uniform(1 - rel, 1 + rel), lo, hi))


def taper(grid: Grid, ramp: float = TAPER) -> np.ndarray:
    """(nx, 1) window: 0 at both segment ends, 1 beyond ``ramp`` m from them."""
    x = grid.x
    return np.clip(np.minimum(x, grid.length - x) / ramp, 0.0, 1.0)[:, None]


def smooth_noise(rng: np.random.Generator, grid: Grid, scale: float) -> np.ndarray:
    """(nx, ny) noise in [-1, 1]: uniform values every ``scale`` m, bilinear in between."""
    coarse = rng.uniform(-1.0, 1.0, (int(grid.length / scale) + 2, int(grid.width / scale) + 2))
    xs, ys = grid.mesh()
    return map_coordinates(coarse, [xs / scale, ys / scale], order=1)


def _centre_waypoints(grid: Grid, xs: np.ndarray) -> np.ndarray:
    return np.stack([xs, np.full_like(xs, grid.width / 2)], axis=-1)


# ---- how the gap-like primitives and hurdles ramp with difficulty (trail.geometry) --------


@dataclass(frozen=True)
class Ramp:
    """A property that changes with difficulty d: ``at0`` at d = 0, ``at1`` from d = ``full``
    on, along ``(d / full) ** curve`` in between. A variant draws it times a random factor in
    [0.9, 1.1], clipped to [``lo``, ``hi``]."""

    at0: float
    at1: float
    lo: float = -np.inf
    hi: float = np.inf
    curve: float = 1.0  # > 1: small steps at the low levels, larger ones at the top
    full: float = 1.0  # difficulty from which the property stays at ``at1``

    def at(self, d: float) -> float:
        """The nominal value at difficulty ``d`` (no random factor)."""
        return lerp(self.at0, self.at1, min(1.0, d / self.full) ** self.curve)

    def draw(self, rng: np.random.Generator, d: float) -> float:
        """One variant's value at difficulty ``d``."""
        return jitter(rng, self.at(d), self.lo, self.hi)


@dataclass(frozen=True)
class GapGeometry:
    """Ramps of the gap-like primitives (stones, gaps, ditch) and hurdles, all in m."""

    pit_depth: Ramp  # void under stones and gaps; one depth per level (not drawn)
    stone_size: Ramp  # side of a square stepping stone
    stone_gap: Ramp  # pit between two stones, edge to edge
    stagger: Ramp  # sideways shift of staggered stones, alternating (not drawn)
    gap: Ramp  # full-width gap between two platforms of ``gaps``
    hurdle: Ramp  # hurdle height
    mound: Ramp  # mound height (RandomMix's hurdle in the ground: stepped over as well)
    ditch_top: Ramp | None  # ditch width lip to lip; None: whatever its walls make (v1)


DITCH_FLOOR = 0.3  # m, narrowest ditch floor in v2: a sole (H1 0.20 m) lands on it


# v1: the geometry the shipped policies trained on (a 0.8 m causeway over a 1 m pit at
# level 0). v2 (docs/terrain.md, "Trails that teach"): wide and shallow at level 0 (Extreme
# Parkour's 1.2-2.4 m valid width and 0.2-1 m pit depth), narrow and deep at the top, every
# level within the reach and lift of the smaller leg (G1; ``feasibility.LEGS``).
GEOMETRIES: dict[str, GapGeometry] = {
    "v1": GapGeometry(
        pit_depth=Ramp(PIT_DEPTH, PIT_DEPTH), stone_size=Ramp(0.8, 0.5, 0.45, 0.85),
        stone_gap=Ramp(0.05, 0.55, 0.045, 0.6), stagger=Ramp(0.15, 0.35),
        gap=Ramp(0.1, 0.7, 0.08, 0.75), hurdle=Ramp(0.05, 0.40, 0.04, 0.42),
        mound=Ramp(0.05, 0.40, 0.04, 0.42), ditch_top=None),
    "v2": GapGeometry(
        pit_depth=Ramp(0.2, PIT_DEPTH), stone_size=Ramp(1.6, 0.55, 0.5, 1.7),
        stone_gap=Ramp(0.05, 0.45, 0.045, 0.5), stagger=Ramp(0.05, 0.2),
        gap=Ramp(0.1, 0.5, 0.08, 0.55), hurdle=Ramp(0.05, 0.30, 0.04, 0.33, curve=1.5),
        mound=Ramp(0.05, 0.30, 0.04, 0.33),  # only the top capped: RandomMix keeps its ramp
        # wide and shallow (walked through) at level 0; as narrow as a step from level 2,
        # where it is deeper than a G1 leg lifts (0.34 m)
        ditch_top=Ramp(1.2, 0.45, 0.4, 1.3, full=0.5)),
}


def gap_geometry(name: str) -> GapGeometry:
    """The ramp table ``name``; raises ValueError naming the key and the valid values."""
    if name not in GEOMETRIES:
        raise ValueError(f"trail.geometry={name!r} is not a terrain geometry; valid: "
                         f"{sorted(GEOMETRIES)}")
    return GEOMETRIES[name]


# ---- the primitives -----------------------------------------------------------------------


@register_primitive("flat", "none", (0.0, 0.0), "level ground; difficulty has no effect")
def flat(d: float, rng: np.random.Generator, grid: Grid) -> Patch:
    return Patch(np.zeros((grid.nx, grid.ny)), params={"none": 0.0})


def _slope(d: float, rng: np.random.Generator, grid: Grid, sign: float) -> Patch:
    grade = jitter(rng, lerp(0.05, 0.40, d), 0.04, 0.42)
    h = sign * grade * grid.x[:, None] * np.ones((1, grid.ny))
    return Patch(h, sign * grade * grid.x[-1], params={"grade": grade})


@register_primitive("slope_up", "grade", (0.04, 0.42), "smooth ramp up; grade 0.05 -> 0.40")
def slope_up(d: float, rng: np.random.Generator, grid: Grid) -> Patch:
    return _slope(d, rng, grid, 1.0)


@register_primitive("slope_down", "grade", (0.04, 0.42), "smooth ramp down; grade 0.05 -> 0.40")
def slope_down(d: float, rng: np.random.Generator, grid: Grid) -> Patch:
    return _slope(d, rng, grid, -1.0)


@register_primitive("rough_slope", "grade", (0.04, 0.37),
                    "ramp up or down (random) with rough surface; grade 0.05 -> 0.35, "
                    "noise amplitude 0.01 -> 0.06 m")
def rough_slope(d: float, rng: np.random.Generator, grid: Grid) -> Patch:
    sign = float(rng.choice([-1.0, 1.0]))
    grade = jitter(rng, lerp(0.05, 0.35, d), 0.04, 0.37)
    amp = lerp(0.01, 0.06, d)
    noise = amp * smooth_noise(rng, grid, 0.3) * taper(grid)
    h = sign * grade * grid.x[:, None] + noise
    return Patch(h, sign * grade * grid.x[-1], params={"grade": grade, "roughness": amp})


def _stairs(d: float, rng: np.random.Generator, grid: Grid, sign: float) -> Patch:
    step = jitter(rng, lerp(0.04, 0.22, d), 0.035, 0.24)
    tread = jitter(rng, lerp(0.45, 0.30, d), 0.27, 0.5)
    n = max(1, int((grid.length - 2 * 0.3) / tread))  # 0.3 m landings at both ends
    k = np.clip(np.floor((grid.x - 0.3) / tread) + 1, 0, n)
    h = sign * step * k[:, None] * np.ones((1, grid.ny))
    xs = 0.3 + (np.arange(n) + 0.5) * tread  # one waypoint per tread would be too dense:
    return Patch(h, sign * step * n, waypoints=_centre_waypoints(grid, xs[[0, -1]]),
                 params={"step_height": step, "tread": tread})


@register_primitive("stairs_up", "step_height", (0.035, 0.24),
                    "flight up; riser 0.04 -> 0.22 m, tread 0.45 -> 0.30 m")
def stairs_up(d: float, rng: np.random.Generator, grid: Grid) -> Patch:
    return _stairs(d, rng, grid, 1.0)


@register_primitive("stairs_down", "step_height", (0.035, 0.24),
                    "flight down; riser 0.04 -> 0.22 m, tread 0.45 -> 0.30 m")
def stairs_down(d: float, rng: np.random.Generator, grid: Grid) -> Patch:
    return _stairs(d, rng, grid, -1.0)


@register_primitive("rough", "roughness", (0.0, 0.11),
                    "uneven ground; noise amplitude 0.01 -> 0.10 m every 0.4 m")
def rough(d: float, rng: np.random.Generator, grid: Grid) -> Patch:
    amp = jitter(rng, lerp(0.01, 0.10, d), 0.0, 0.11)
    return Patch(amp * smooth_noise(rng, grid, 0.4) * taper(grid), params={"roughness": amp})


@register_primitive("rocks", "rock_height", (0.0, 0.25),
                    "scattered rounded rocks; height 0.05 -> 0.25 m, 0.15 -> 0.8 per m2")
def rocks(d: float, rng: np.random.Generator, grid: Grid) -> Patch:
    top = lerp(0.05, 0.25, d)
    n = int(round(lerp(0.15, 0.8, d) * grid.length * grid.width))
    cx = rng.uniform(TAPER, grid.length - TAPER, n)
    cy = rng.uniform(0.0, grid.width, n)
    rad = rng.uniform(0.2, 0.45, n)
    hgt = top * rng.uniform(0.5, 1.0, n)
    xs, ys = grid.mesh()
    h = np.zeros_like(xs)
    for x0, y0, r, k in zip(cx, cy, rad, hgt, strict=True):  # n <= 0.8 per m2: a short loop
        sl = (slice(max(0, int((x0 - r) / grid.res)), int((x0 + r) / grid.res) + 2),
              slice(max(0, int((y0 - r) / grid.res)), int((y0 + r) / grid.res) + 2))
        rr = ((xs[sl] - x0) ** 2 + (ys[sl] - y0) ** 2) / r**2
        h[sl] = np.maximum(h[sl], k * np.clip(1.0 - rr, 0.0, None))  # paraboloid cap
    return Patch(h, params={"rock_height": float(hgt.max(initial=0.0)), "count": float(n)})


def _stones(d: float, rng: np.random.Generator, grid: Grid, staggered: bool) -> Patch:
    geo = gap_geometry(grid.geometry)
    size = geo.stone_size.draw(rng, d)
    gap = geo.stone_gap.draw(rng, d)
    depth = geo.pit_depth.at(d)
    wobble = lerp(0.0, 0.08, d)  # m, stone tops are not level with each other
    offset = geo.stagger.at(d) if staggered else 0.0  # m, sideways shift, alternating
    xs, ys = grid.mesh()
    h = np.full_like(xs, -depth)
    h[xs < LANDING] = 0.0
    x0, centres = LANDING + gap, []
    while x0 + size + gap + LANDING <= grid.length:
        cy = grid.width / 2 + (offset if len(centres) % 2 else -offset)
        on = (xs >= x0) & (xs < x0 + size) & (np.abs(ys - cy) < size / 2)
        h[on] = rng.uniform(-wobble, wobble)
        centres.append((x0 + size / 2, cy))
        x0 += size + gap
    h[xs >= x0] = 0.0  # exit landing starts one gap after the last stone
    wp = np.array(centres).reshape(-1, 2)
    return Patch(h, waypoints=wp, keepout=h < -depth / 2,
                 params={"gap": gap, "stone_size": size, "offset": offset, "depth": depth})


@register_primitive("stones", "gap", (0.045, 0.6),
                    "stepping stones in a line over a pit; gap 0.05 -> 0.45 m, "
                    "stone 1.6 -> 0.55 m, pit 0.2 -> 1 m deep (v2)")
def stones(d: float, rng: np.random.Generator, grid: Grid) -> Patch:
    return _stones(d, rng, grid, staggered=False)


@register_primitive("stones_staggered", "gap", (0.045, 0.6),
                    "stepping stones alternating left/right; gap 0.05 -> 0.45 m, "
                    "stone 1.6 -> 0.55 m, side offset 0.05 -> 0.2 m (v2)")
def stones_staggered(d: float, rng: np.random.Generator, grid: Grid) -> Patch:
    return _stones(d, rng, grid, staggered=True)


@register_primitive("gaps", "gap", (0.08, 0.75),
                    "uneven platforms split by full-width gaps; gap 0.1 -> 0.5 m, "
                    "pit 0.2 -> 1 m deep, platform height spread 0 -> 0.1 m (v2)")
def gaps(d: float, rng: np.random.Generator, grid: Grid) -> Patch:
    geo = gap_geometry(grid.geometry)
    gap = geo.gap.draw(rng, d)
    depth = geo.pit_depth.at(d)
    spread = lerp(0.0, 0.1, d)
    xs = grid.x
    h = np.full((grid.nx, grid.ny), -depth)
    h[xs < LANDING] = 0.0
    x0, centres = LANDING + gap, []
    while True:
        plat = rng.uniform(1.0, 1.6)
        if x0 + plat + gap + LANDING > grid.length:
            break
        h[(xs >= x0) & (xs < x0 + plat)] = rng.uniform(-spread, spread)
        centres.append(x0 + plat / 2)
        x0 += plat + gap
    h[xs >= x0] = 0.0
    return Patch(h, waypoints=_centre_waypoints(grid, np.array(centres)),
                 keepout=h < -depth / 2, params={"gap": gap, "depth": depth})


@register_primitive("ditch", "depth", (0.08, 0.85),
                    "trench with sloped walls and an uneven floor, crossing at an angle; "
                    "depth 0.1 -> 0.8 m, lip to lip 1.2 -> 0.45 m by level 2 (v2), "
                    "yaw 0 -> 0.5 rad")
def ditch(d: float, rng: np.random.Generator, grid: Grid) -> Patch:
    depth = jitter(rng, lerp(0.1, 0.8, d), 0.08, 0.85)
    wall = lerp(0.5, 2.0, d)  # rise per metre of wall
    floor = rng.uniform(0.4, 0.4 + lerp(0.2, 0.6, d))  # m, flat-ish bottom width
    top_half = floor / 2 + depth / wall
    top = gap_geometry(grid.geometry).ditch_top
    if top is not None:  # v2: lip to lip as the ramp says, the walls as steep as that needs
        top_half = top.draw(rng, d) / 2
        wall = max(wall, depth / (top_half - DITCH_FLOOR / 2))
    yaw = rng.uniform(-1, 1) * lerp(0.0, 0.5, d)
    normal = np.array([np.cos(yaw), np.sin(yaw)])
    cx = grid.length / 2
    cy = grid.width / 2 + rng.uniform(-1, 1) * lerp(0.0, 1.5, d)  # trail swerves: quick turns
    xs, ys = grid.mesh()
    s = (xs - cx) * normal[0] + (ys - cy) * normal[1]  # signed distance across the ditch
    h = -depth * np.clip((top_half - np.abs(s)) * wall / depth, 0.0, 1.0)
    h += lerp(0.02, 0.06, d) * smooth_noise(rng, grid, 0.3) * (h < -0.5 * depth)
    h *= taper(grid, 0.3)  # a slanted ditch is closed off where it meets the segment ends
    step_off = top_half + grid.clearance  # waypoints on both lips, facing straight across
    wp = np.array([[cx, cy]]) + np.array([[-step_off], [step_off]]) * normal
    inside = np.abs(s) < top_half  # the expert crosses lip to lip: no waypoint in the ditch
    return Patch(h, waypoints=wp, keepout=inside,
                 params={"depth": depth, "wall_grade": wall, "yaw": yaw,
                         "top_width": 2 * top_half})


@register_primitive("hurdles", "height", (0.04, 0.42),
                    "long cuboids lying across the trail; height 0.05 -> 0.30 m (v2), "
                    "length 60% -> 100% of the width, yaw 0 -> 0.3 rad")
def hurdles(d: float, rng: np.random.Generator, grid: Grid) -> Patch:
    n = max(1, int(grid.length // 2.0))  # one hurdle every 2 m
    boxes, wps = [], []
    for k in range(n):
        height = gap_geometry(grid.geometry).hurdle.draw(rng, d)
        thick = rng.uniform(0.1, 0.2)
        span = grid.width * rng.uniform(lerp(0.6, 1.0, d), 1.0)
        yaw = rng.uniform(-1, 1) * lerp(0.0, 0.3, d)
        cx = (k + 0.5) * grid.length / n
        shift = max(0.0, min(span / 2 - 1.0, (grid.width - span) / 2))  # inside, over centre
        cy = grid.width / 2 + rng.uniform(-1, 1) * shift
        boxes.append([cx, cy, height / 2, thick / 2, span / 2, height / 2, yaw])
        off = thick / 2 + grid.clearance + 0.1
        normal = np.array([np.cos(yaw), np.sin(yaw)])
        along = (grid.width / 2 - cy) / np.cos(yaw)  # where the hurdle meets the centre line
        cross = np.array([cx - np.sin(yaw) * along, grid.width / 2])
        wps += [cross - off * normal, cross + off * normal]
    b = np.array(boxes)
    return Patch(np.zeros((grid.nx, grid.ny)), boxes=b, waypoints=np.array(wps),
                 params={"height": float(b[:, 5].max() * 2), "count": float(n)})


@register_primitive("platforms", "height", (0.04, 0.32),
                    "full-width raised blocks to step up on and down from; height "
                    "0.05 -> 0.30 m, length 1.0 -> 2.0 m")
def platforms(d: float, rng: np.random.Generator, grid: Grid) -> Patch:
    xs = grid.x
    h = np.zeros((grid.nx, grid.ny))
    x0, centres, tops = 0.5, [], [0.0]
    while True:
        length = rng.uniform(1.0, 2.0)
        if x0 + length + 0.5 > grid.length:
            break
        top = jitter(rng, lerp(0.05, 0.30, d), 0.04, 0.32)
        h[(xs >= x0) & (xs < x0 + length)] = top
        centres.append(x0 + length / 2)
        tops.append(top)
        x0 += length + rng.uniform(0.5, 1.0)
    return Patch(h, waypoints=_centre_waypoints(grid, np.array(centres)),
                 params={"height": max(tops)})


@register_primitive("trees", "density", (0.0, 0.6),
                    "tree trunks of mixed sizes over gently rough ground, leaving one "
                    "winding corridor; density 0.08 -> 0.4 per m2 plus 0.3 -> 0.8 "
                    "blockers per m of trail, radius up to 0.2 -> 0.45 m")
def trees(d: float, rng: np.random.Generator, grid: Grid) -> Patch:
    density = jitter(rng, lerp(0.08, 0.40, d), 0.08, 0.44)
    n = int(round(density * grid.length * grid.width))
    # A corridor that weaves across the tile keeps the forest passable at any density;
    # the expert path is still searched (goals.py), so it may take another opening.
    amp = rng.uniform(0.7, 1.0) * lerp(1.2, 2.5, d)
    wave = rng.uniform(5.0, 9.0)
    phase = rng.uniform(0.0, 2 * np.pi)

    def corridor(x: np.ndarray) -> np.ndarray:
        return grid.width / 2 + amp * np.sin(2 * np.pi * x / wave + phase) * np.sin(
            np.pi * np.clip(x / grid.length, 0, 1))

    # Blockers first: trunks on the straight line force the detour wherever it may go.
    blockers = int(round(lerp(0.3, 0.8, d) * grid.length))
    cx = np.concatenate([rng.uniform(0.0, grid.length, blockers),
                         rng.uniform(0.0, grid.length, 3 * n)])
    cy = np.concatenate([grid.width / 2 + rng.uniform(-0.3, 0.3, blockers),
                         rng.uniform(0.0, grid.width, 3 * n)])
    r = rng.uniform(lerp(0.1, 0.15, d), lerp(0.2, 0.45, d), len(cx))
    half_h = rng.uniform(0.75, 2.0, len(cx))  # 1.5 to 4 m trunks: they block the view
    slope = (corridor(cx + 0.01) - corridor(cx - 0.01)) / 0.02
    across = np.abs(cy - corridor(cx)) / np.sqrt(1.0 + slope**2)  # ~ distance to the corridor
    free = across > r + grid.clearance + ROBOT_HALF_WIDTH + 0.3
    keep = np.flatnonzero(free)[:n + blockers]
    cyl = np.stack([cx, cy, half_h, r, half_h], axis=-1)[keep]
    ground = lerp(0.0, 0.04, d) * smooth_noise(rng, grid, 0.5) * taper(grid)
    return Patch(ground, cylinders=cyl, params={"density": len(keep) / (grid.length * grid.width),
                                                 "max_radius": float(r[keep].max(initial=0))})


@register_primitive("mounds", "height", (0.04, 0.42),
                    "smooth humps across the trail (buried logs, earth mounds); height "
                    "0.05 -> 0.30 m (v2), width 1.0 -> 0.6 m")
def mounds(d: float, rng: np.random.Generator, grid: Grid) -> Patch:
    xs, ys = grid.mesh()
    h = np.zeros_like(xs)
    n = max(1, int(grid.length // 1.5))
    tops = []
    for k in range(n):
        top = gap_geometry(grid.geometry).mound.draw(rng, d)
        width = lerp(1.0, 0.6, d) * rng.uniform(0.9, 1.1)
        yaw = rng.uniform(-0.4, 0.4)
        cx = (k + 0.5) * grid.length / n
        s = (xs - cx) * np.cos(yaw) + (ys - grid.width / 2) * np.sin(yaw)
        bump = top * np.cos(np.clip(s / width, -0.5, 0.5) * np.pi) ** 2  # cos^2 hump
        h = np.maximum(h, bump)
        tops.append(top)
    return Patch(h * taper(grid, 0.2), params={"height": max(tops)})
