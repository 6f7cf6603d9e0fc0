"""Trail categories: how primitives are chained into one tile of a category and level.

Tile frame: x along the trail from the tile's -x end (0) to its +x end (``tile_length``),
y across from 0 to ``tile_width``; the robot starts on a flat pad at x = ``start_pad`` / 2
on the centre line and the terminus sits on the flat pad at the far end.
"""

from dataclasses import dataclass, field

import numpy as np

from legoh.envs.terrain.primitives import Grid, Patch, gap_geometry, lerp, make_patch


@dataclass(frozen=True)
class CategorySpec:
    """Segment k of a trail draws its primitive uniformly from ``pattern[k % len(pattern)]``.

    ``single``: one segment spans the whole trail between the pads (a forest, a flat trail).
    """

    pattern: tuple[tuple[str, ...], ...]
    single: bool = False
    doc: str = ""


# RandomMix's primitives, drawn uniformly per segment (``trail.primitives`` replaces a mix)
OPEN_MIX = ("slope_up", "slope_down", "rough_slope", "stairs_up", "stairs_down", "rough",
            "rocks", "mounds", "platforms")

CATEGORIES: dict[str, CategorySpec] = {
    "flat": CategorySpec((("flat",),), single=True, doc="flat ground at every level"),
    "randommix": CategorySpec((OPEN_MIX,), doc="long, unobstructed, mixed terrain"),
    "ditch": CategorySpec((("ditch",), ("gaps", "slope_up", "slope_down", "rough_slope",
                                       "rough")),
                          doc="ditches every other segment, between gaps and slopes"),
    "hurdle": CategorySpec((("hurdles",), ("flat", "rough", "slope_up", "slope_down")),
                           doc="long cuboid hurdles every other segment"),
    "gap": CategorySpec((("stones", "stones_staggered", "gaps", "platforms"),),
                        doc="stepping stones, gaps and uneven platforms"),
    "forest": CategorySpec((("trees",),), single=True, doc="one dense forest"),
}
HILL = "hill"  # chains several categories over a hillside (see ``compose_hill``)
ALL_CATEGORIES = (*CATEGORIES, HILL)


@dataclass
class TileLayout:
    """A composed tile in the tile frame (module docstring); heights in m, float64.

    boxes / cylinders: z is the height of the centre above the local ground (the map adds
    the ground). anchors: (A, 2) xy the primitives ask the expert to visit, start and
    terminus included, in order. keepout: (nx, ny) cells no waypoint may use.
    """

    heights: np.ndarray
    boxes: np.ndarray
    cylinders: np.ndarray
    anchors: np.ndarray
    keepout: np.ndarray
    plan: list[tuple[str, float]] = field(default_factory=list)  # (primitive, length m)


def check_category(name: str) -> None:
    """Raise ValueError naming the valid categories when ``name`` is not one."""
    if name not in ALL_CATEGORIES:
        raise ValueError(f"unknown trail category {name!r}; valid: {list(ALL_CATEGORIES)}")


def geometry_name(cfg) -> str:
    """``cfg.geometry`` as a plain string ("v1" | "v2"; an enum member gives its value),
    checked against the ramp tables (ValueError naming the valid ones)."""
    name = str(getattr(cfg.geometry, "value", cfg.geometry))
    gap_geometry(name)
    return name


def split_segments(total: int, lo: int, hi: int, rng: np.random.Generator) -> list[int]:
    """Cut ``total`` cells into pieces of ``lo``..``hi`` cells (the last may run longer)."""
    pieces = []
    while total - sum(pieces) > hi:
        pieces.append(int(rng.integers(lo, hi + 1)))
    rest = total - sum(pieces)
    if rest >= lo or not pieces:
        pieces.append(rest)
    else:
        pieces[-1] += rest
    return pieces


def plan_category(spec: CategorySpec, cells: int, seg_cells: tuple[int, int],
                  rng: np.random.Generator, pool: list[str] | None = None) -> list[tuple[str, int]]:
    """Primitive names and lengths (cells) filling ``cells`` along the trail."""
    pattern = (tuple(pool),) if pool else spec.pattern
    pieces = [cells] if spec.single else split_segments(cells, *seg_cells, rng)
    return [(str(rng.choice(pattern[k % len(pattern)])), n) for k, n in enumerate(pieces)]


def _place(patch: Patch, x0: float, elevation: float) -> Patch:
    """Shift a patch to start at tile x ``x0`` and ground ``elevation``."""
    shift = np.array([x0, 0.0])
    boxes, cyl = patch.boxes.copy(), patch.cylinders.copy()
    boxes[:, :2] += shift
    cyl[:, :2] += shift
    return Patch(patch.heights + elevation, patch.exit_height + elevation, boxes, cyl,
                 patch.waypoints + shift, patch.keepout, patch.params)


def assemble(plan: list[tuple[str, int]], difficulty: float, rng: np.random.Generator,
             cfg) -> TileLayout:
    """Run the primitives of ``plan`` one after another between the two flat pads.

    The ground keeps within +-``cfg.max_elevation`` of the start: a segment that would leave
    that band is mirrored (up becomes down), or, if that is not enough, scaled down.
    """
    res, width = cfg.resolution, cfg.tile_width
    nx, ny = int(round(cfg.tile_length / res)), int(round(width / res))
    pad = int(round(cfg.start_pad / res))
    heights = np.zeros((nx, ny))
    keepout = np.zeros((nx, ny), dtype=bool)
    boxes, cyls = [np.zeros((0, 7))], [np.zeros((0, 5))]
    anchors = [np.array([[cfg.start_pad / 2, width / 2]])]
    i0, elevation, names = pad, 0.0, []
    for name, cells in plan:
        grid = Grid(cells * res, width, res, cfg.clearance, geometry_name(cfg))
        patch = make_patch(name, difficulty, rng, grid)
        up, down = abs(elevation + patch.exit_height), abs(elevation - patch.exit_height)
        if up > cfg.max_elevation and down < up:
            patch = patch.negated()
        target = elevation + patch.exit_height
        if patch.exit_height and abs(target) > cfg.max_elevation + 1e-9:  # flatten it to fit
            scale = (np.sign(target) * cfg.max_elevation - elevation) / patch.exit_height
            patch.heights, patch.exit_height = patch.heights * scale, patch.exit_height * scale
        placed = _place(patch, i0 * res, elevation)
        heights[i0:i0 + cells] = placed.heights
        keepout[i0:i0 + cells] = placed.keepout
        boxes.append(placed.boxes)
        cyls.append(placed.cylinders)
        anchors.append(placed.waypoints)
        elevation = placed.exit_height
        names.append((name, round(cells * res, 6)))
        i0 += cells
    heights[i0:] = elevation
    anchors.append(np.array([[cfg.tile_length - cfg.start_pad / 2, width / 2]]))
    return TileLayout(heights, np.concatenate(boxes), np.concatenate(cyls),
                      np.concatenate(anchors), keepout, names)


def _seg_cells(cfg) -> tuple[int, int]:
    lo, hi = cfg.segment_length
    return int(round(lo / cfg.resolution)), int(round(hi / cfg.resolution))


def _middle_cells(cfg) -> int:
    return int(round(cfg.tile_length / cfg.resolution)) - 2 * int(round(cfg.start_pad /
                                                                         cfg.resolution))


def compose_tile(category: str, difficulty: float, rng: np.random.Generator, cfg) -> TileLayout:
    """One tile of ``category`` at ``difficulty`` in [0, 1] (hill included)."""
    check_category(category)
    if category == HILL:
        return compose_hill(difficulty, rng, cfg)
    pool = list(cfg.primitives) or None
    plan = plan_category(CATEGORIES[category], _middle_cells(cfg), _seg_cells(cfg), rng, pool)
    return assemble(plan, difficulty, rng, cfg)


def compose_hill(difficulty: float, rng: np.random.Generator, cfg) -> TileLayout:
    """Out-of-domain trail: stretches of several categories laid over a hillside.

    The hillside rises by ``lerp(0.4, 1.0, d) * hill_rise`` m to mid-trail and back down
    (sin^2 profile) and tilts sideways by a grade of up to 0.1, so every stretch sits on a
    slope it never had in training.
    """
    for name in cfg.hill_categories:
        if name not in CATEGORIES:
            raise ValueError(f"unknown hill category {name!r}; valid: {list(CATEGORIES)}")
    cells = _middle_cells(cfg)
    k = max(1, min(len(cfg.hill_categories), int(cells * cfg.resolution // 12.0)))
    chosen = [str(c) for c in rng.permutation(list(cfg.hill_categories))[:k]]
    plan = []
    for n, name in zip(split_segments(cells, cells // k, cells // k, rng), chosen, strict=False):
        plan += plan_category(CATEGORIES[name], n, _seg_cells(cfg), rng)
    tile = assemble(plan, difficulty, rng, cfg)
    xs = np.arange(tile.heights.shape[0]) * cfg.resolution
    ys = np.arange(tile.heights.shape[1]) * cfg.resolution
    rise = lerp(0.4, 1.0, difficulty) * cfg.hill_rise
    tilt = rng.choice([-1.0, 1.0]) * lerp(0.02, 0.1, difficulty)
    tile.heights += rise * np.sin(np.pi * xs / cfg.tile_length)[:, None] ** 2
    tile.heights += tilt * (ys - cfg.tile_width / 2)[None, :]
    return tile
