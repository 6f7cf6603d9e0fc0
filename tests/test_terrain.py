"""Terrain: primitives, trails, goals, the map, the export (small maps, coarse grids)."""

import numpy as np
import pytest

from legoh.config.trail import TrailConfig
from legoh.envs.terrain import PRIMITIVES, build_terrain_map
from legoh.envs.terrain.export import heightfield_mesh, tile_png, tile_scene
from legoh.envs.terrain.feasibility import MAX_LEAP, MAX_STEP, reachable
from legoh.envs.terrain.goals import box_clearance, trunk_clearance
from legoh.envs.terrain.primitives import PIT_DEPTH, Grid, make_patch

CATS = ["flat", "randommix", "ditch", "hurdle", "gap", "forest"]
COARSE = 0.1  # m: tests build at 10 cm cells to stay fast


def cfg_for(categories, **kw) -> TrailConfig:
    base = dict(name="test", categories=list(categories), levels=5, variants=2,
                resolution=COARSE)
    if categories == ["hill"]:
        base.update(tile_length=64.0, tile_width=12.0, variants=1)
    base.update(kw)
    return TrailConfig(**base)


@pytest.fixture(scope="module")
def maps():
    return {c: build_terrain_map(cfg_for([c]), seed=7) for c in [*CATS, "hill"]}


# ---- primitives ---------------------------------------------------------------------------

GRID = Grid(6.0, 8.0, 0.05)


def measure(name: str, patch) -> float:
    """The primitive's growing property, measured from the geometry, not from params."""
    h, prop = patch.heights, PRIMITIVES[name].prop
    centre = h[:, h.shape[1] // 2]
    if prop == "grade":
        core = slice(len(centre) // 5, -len(centre) // 5)  # skip the tapered ends
        return abs(np.polyfit(GRID.x[core], centre[core], 1)[0])
    if prop == "step_height":
        return float(np.median(np.abs(np.diff(centre))[np.abs(np.diff(centre)) > 1e-6]))
    if prop == "roughness":
        return float(np.abs(h - h.mean()).max())
    if prop == "rock_height" or (prop == "height" and len(patch.boxes) == 0):
        return float(h.max())
    if prop == "height":
        return float((2 * patch.boxes[:, 5]).max())
    if prop == "gap":  # median run of rows that are pit all across (between stones in x)
        pit = np.concatenate([[0], h.max(axis=1) < -PIT_DEPTH / 2, [0]])
        edges = np.flatnonzero(np.diff(pit.astype(int)))
        runs = edges[1::2] - edges[::2]
        return float(np.median(runs)) * GRID.res if len(runs) else 0.0
    if prop == "depth":
        return float(-h.min())
    if prop == "density":
        return len(patch.cylinders) / (GRID.length * GRID.width)
    raise AssertionError(f"no measure for {prop}")


def test_sixteen_primitives_registered():
    assert len(PRIMITIVES) == 16


@pytest.mark.parametrize("name", sorted(set(PRIMITIVES) - {"flat"}))
def test_primitive_property_grows_and_stays_in_bounds(name):
    lo, hi = PRIMITIVES[name].bounds
    means = []
    for d in (0.0, 0.5, 1.0):
        patches = [make_patch(name, d, np.random.default_rng(s), GRID) for s in range(6)]
        for p in patches:
            assert np.isfinite(p.heights).all()
            assert lo - 1e-9 <= p.params[PRIMITIVES[name].prop] <= hi + 1e-9
        means.append(np.mean([measure(name, p) for p in patches]))
    assert means[0] < means[1] < means[2], (name, means)


def test_flat_is_flat_at_every_difficulty():
    for d in (0.0, 1.0):
        assert not make_patch("flat", d, np.random.default_rng(0), GRID).heights.any()


def test_stones_gap_measured_matches_param():
    p = make_patch("stones", 1.0, np.random.default_rng(3), GRID)
    assert measure("stones", p) == pytest.approx(p.params["gap"], abs=2 * GRID.res)


def test_bad_primitive_or_difficulty_names_the_problem():
    with pytest.raises(ValueError, match="valid:.*flat"):
        make_patch("lava", 0.5, np.random.default_rng(0), GRID)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        make_patch("rough", 1.5, np.random.default_rng(0), GRID)


# ---- reproducibility and input errors -----------------------------------------------------

def test_same_seed_bit_identical_and_other_seed_differs():
    cfg = cfg_for(["gap", "forest"], levels=2)
    a, b, c = (build_terrain_map(cfg, s) for s in (3, 3, 4))
    assert np.array_equal(a.heights, b.heights) and np.array_equal(a.cylinders, b.cylinders)
    for ta, tb in zip(a.tiles, b.tiles, strict=True):
        assert np.array_equal(ta.waypoints, tb.waypoints)
    assert not np.array_equal(a.heights, c.heights)
    assert not np.array_equal(a.tiles[-1].waypoints, c.tiles[-1].waypoints)


def test_unknown_category_and_out_of_range_level_raise():
    with pytest.raises(ValueError, match="valid:.*randommix"):
        build_terrain_map(cfg_for(["swamp"]), 0)
    tm = build_terrain_map(cfg_for(["flat"], levels=2, variants=1), 0)
    with pytest.raises(ValueError, match="0..1"):
        tm.tile_index("flat", 2, 0)
    with pytest.raises(ValueError, match="not in this map"):
        tm.tile_index("forest", 0, 0)


# ---- the map ------------------------------------------------------------------------------

def test_map_layout_and_lookup(maps):
    tm = maps["gap"]
    assert tm.heights.dtype == np.float32 and len(tm.tiles) == 5 * 2
    assert np.isfinite(tm.heights).all() and tm.edge_mask.shape == tm.heights.shape
    for t in tm.tiles:
        assert tm.tiles[tm.tile_index(t.category, t.level, t.variant)] is t
        assert t.start[0] < t.terminus[0]  # trail runs along +x
        assert np.allclose(t.waypoints[-1], t.terminus)
        assert t.length >= t.size[0] - 2 * 1.0 - 1e-6
    ring = np.concatenate([tm.heights[0], tm.heights[-1], tm.heights[:, 0], tm.heights[:, -1]])
    assert not ring.any()  # flat border around the map
    assert tm.edge_mask.any()  # stones and gaps have edges


def test_height_at_matches_cells_and_is_vectorised(maps):
    tm = maps["randommix"]
    ij = np.array([[5, 7], [100, 200], [tm.heights.shape[0] - 1, 3]])
    xy = tm.origin + ij * tm.resolution
    assert np.allclose(tm.height_at(xy), tm.heights[ij[:, 0], ij[:, 1]], atol=1e-5)
    batch = np.random.default_rng(0).uniform(0, 30, (64, 132, 2))
    assert tm.height_at(batch).shape == (64, 132)


def test_heights_finite_in_every_category(maps):
    for tm in maps.values():
        assert np.isfinite(tm.heights).all()
        assert np.isfinite(tm.boxes).all() and np.isfinite(tm.cylinders).all()


# ---- goals --------------------------------------------------------------------------------

def _local(tm, tile):
    lo, hi = tile.origin - 1.0, tile.origin + tile.size + 1.0
    inb = lambda a: ((a[:, :2] > lo) & (a[:, :2] < hi)).all(axis=1)  # noqa: E731
    return tm.boxes[inb(tm.boxes)], tm.cylinders[inb(tm.cylinders)]


@pytest.mark.parametrize("category", [*CATS, "hill"])
def test_waypoints_on_ground_and_clear_of_obstacles(maps, category):
    tm = maps[category]
    clearance = 0.4
    for t in tm.tiles:
        boxes, cyl = _local(tm, t)
        xy = t.waypoints[:, :2]
        assert np.allclose(t.waypoints[:, 2], tm.height_at(xy), atol=0.02)
        width = 1e9  # the tile side is no obstacle for this check
        assert (trunk_clearance(xy, cyl, width) >= clearance - 1e-6).all()
        assert (box_clearance(xy, boxes) >= clearance - 1e-6).all()
        # traversable: never over a pit; at levels 0-2 no step beyond the budget under foot
        ring = xy[:, None, :] + 0.1 * np.array([[1, 0], [-1, 0], [0, 1], [0, -1]])
        drop = tm.height_at(xy)[:, None] - tm.height_at(ring)
        assert (drop < PIT_DEPTH / 2).all(), (t.category, t.level, t.plan)
        if t.level <= 2:
            assert (np.abs(drop) <= MAX_STEP).all(), (t.category, t.level, t.plan)


@pytest.mark.parametrize("category", [*CATS, "hill"])
def test_levels_0_to_2_are_passable(maps, category):
    tm = maps[category]
    for t in tm.tiles:
        if t.level <= 2:
            # one grid cell of tolerance on the leap: gaps are measured between cell centres
            assert reachable(tm, t, res=COARSE, max_leap=MAX_LEAP + COARSE), (t.category, t.level,
                                                                             t.variant, t.plan)


def test_forest_detour_never_touches_a_trunk(maps):
    tm = maps["forest"]
    detoured = 0
    for t in tm.tiles:
        _, cyl = _local(tm, t)
        pts = np.concatenate([t.start[None, :2], t.waypoints[:, :2]])
        seg = pts[:-1, None] + np.linspace(0, 1, 50)[None, :, None] * np.diff(pts, axis=0)[:, None]
        assert (trunk_clearance(seg, cyl, 1e9) > 0).all()  # the chords the robot walks
        assert (trunk_clearance(t.path[:, :2], cyl, 1e9) >= 0.4 - 1e-6).all()
        detoured += np.ptp(t.waypoints[:, 1]) > 0.2
    assert detoured >= len(tm.tiles) // 2


def test_middle_is_a_waypoint_near_half_way(maps):
    for tm in maps.values():
        for t in tm.tiles:
            assert any(np.array_equal(t.middle, w) for w in t.waypoints)
            assert t.start[0] < t.middle[0] < t.terminus[0]


# ---- export -------------------------------------------------------------------------------

def test_mesh_agrees_with_height_field(maps, tmp_path):
    tm = maps["ditch"]
    tile = tm.tiles[tm.tile_index("ditch", 3, 1)]
    scene = tile_scene(tm, tile)
    ground = scene.geometry["ground"]
    rng = np.random.default_rng(0)
    idx = rng.integers(0, len(ground.vertices), 200)
    v = ground.vertices[idx]
    assert np.allclose(v[:, 2], tm.height_at(v[:, :2]), atol=1e-4)
    assert (ground.face_normals[:, 2] > 0).all()
    out = tmp_path / "t.glb"
    out.write_bytes(scene.export(file_type="glb"))
    assert out.stat().st_size > 1000
    png = tile_png(tm, tile, tmp_path / "t.png")
    assert png.read_bytes()[:4] == b"\x89PNG"


def test_heightfield_mesh_counts():
    m = heightfield_mesh(np.zeros((4, 3)), 0.5, np.zeros(2))
    assert m.vertices.shape == (12, 3) and m.faces.shape == (2 * 3 * 2, 3)


def test_cli_writes_mesh_and_png(tmp_path):
    from legoh.envs.terrain.__main__ import main

    files = main(["--trail", "hurdle", "--level", "1", "--out", str(tmp_path), "--format", "obj",
                  "trail.resolution=0.1", "trail.levels=2", "trail.variants=1"])
    assert all(f.exists() and f.stat().st_size > 0 for f in files)
