"""Look at terrain: trimesh meshes (GLB / OBJ) and top-down PNGs of heights and goals."""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless: files only
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import trimesh  # noqa: E402
from matplotlib.patches import Circle, Polygon  # noqa: E402


def heightfield_mesh(heights: np.ndarray, resolution: float, origin: np.ndarray) -> trimesh.Trimesh:
    """Triangle mesh of a height field: vertex (i, j) at world (origin + (i, j) * res, h)."""
    nx, ny = heights.shape
    xs = origin[0] + np.arange(nx) * resolution
    ys = origin[1] + np.arange(ny) * resolution
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    verts = np.stack([gx, gy, heights], axis=-1).reshape(-1, 3)
    idx = np.arange(nx * ny).reshape(nx, ny)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])  # normals +z
    return trimesh.Trimesh(verts, faces, process=False)


def obstacle_meshes(boxes: np.ndarray, cylinders: np.ndarray) -> list[trimesh.Trimesh]:
    """One mesh per box (M, 7) and trunk (K, 5), world frame."""
    out = []
    for b in boxes:
        tf = trimesh.transformations.rotation_matrix(float(b[6]), [0, 0, 1])
        tf[:3, 3] = b[:3]
        out.append(trimesh.creation.box(extents=2 * b[3:6], transform=tf))
    for k in cylinders:
        tf = np.eye(4)
        tf[:3, 3] = k[:3]
        out.append(trimesh.creation.cylinder(radius=float(k[3]), height=2 * float(k[4]),
                                             transform=tf, sections=16))
    return out


def tile_window(tm, tile, margin: float = 0.0) -> tuple[slice, slice]:
    """Cell slices of ``tm.heights`` covering ``tile`` (plus ``margin`` m)."""
    lo = np.floor((tile.origin - margin - tm.origin) / tm.resolution).astype(int)
    hi = np.ceil((tile.origin + tile.size + margin - tm.origin) / tm.resolution).astype(int)
    lo, hi = np.maximum(lo, 0), np.minimum(hi + 1, tm.heights.shape)
    return slice(lo[0], hi[0]), slice(lo[1], hi[1])


def _inside(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    return ((points[:, :2] >= lo) & (points[:, :2] <= hi)).all(axis=1)


def tile_obstacles(tm, tile, margin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The boxes and cylinders whose centres lie on ``tile``."""
    lo, hi = tile.origin - margin, tile.origin + tile.size + margin
    return tm.boxes[_inside(tm.boxes, lo, hi)], tm.cylinders[_inside(tm.cylinders, lo, hi)]


def tile_scene(tm, tile, margin: float = 0.0) -> trimesh.Scene:
    """Ground mesh and obstacles of one tile."""
    si, sj = tile_window(tm, tile, margin)
    origin = tm.origin + np.array([si.start, sj.start]) * tm.resolution
    scene = trimesh.Scene()
    ground = heightfield_mesh(tm.heights[si, sj], tm.resolution, origin)
    scene.add_geometry(ground, geom_name="ground")
    for n, m in enumerate(obstacle_meshes(*tile_obstacles(tm, tile, margin))):
        scene.add_geometry(m, geom_name=f"obstacle_{n}")
    return scene


def plot_heights(ax, heights: np.ndarray, origin: np.ndarray, resolution: float,
                 boxes: np.ndarray, cylinders: np.ndarray):
    """Draw heights (colour), boxes (outlines) and trunks (discs) on ``ax``, world xy."""
    nx, ny = heights.shape
    ext = [origin[0], origin[0] + (nx - 1) * resolution, origin[1], origin[1] + (ny - 1) *
           resolution]
    im = ax.imshow(heights.T, origin="lower", extent=ext, cmap="terrain", interpolation="nearest")
    for b in boxes:
        c, s = np.cos(b[6]), np.sin(b[6])
        corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * b[3:5]
        pts = corners @ np.array([[c, s], [-s, c]]) + b[:2]
        ax.add_patch(Polygon(pts, closed=True, fc="saddlebrown", ec="k", lw=0.5))
    for k in cylinders:
        ax.add_patch(Circle(k[:2], k[3], fc="darkgreen", ec="k", lw=0.3))
    ax.set_aspect("equal")
    return im


def tile_png(tm, tile, path: Path, title: str = "", margin: float = 0.5) -> Path:
    """Top-down picture of one tile: heights, obstacles, numbered waypoints, start (green
    triangle), middle (orange square), terminus (red star), the dense expert path."""
    si, sj = tile_window(tm, tile, margin)
    origin = tm.origin + np.array([si.start, sj.start]) * tm.resolution
    fig, ax = plt.subplots(figsize=(max(6.0, tile.size[0] / 3), max(2.6, tile.size[1] / 3 + 0.8)))
    im = plot_heights(ax, tm.heights[si, sj], origin, tm.resolution,
                      *tile_obstacles(tm, tile, margin))
    fig.colorbar(im, ax=ax, label="height (m)", shrink=0.8)
    if len(tile.path):
        ax.plot(tile.path[:, 0], tile.path[:, 1], "w--", lw=0.8)
    w = tile.waypoints
    ax.plot(w[:, 0], w[:, 1], "o", ms=3.5, mfc="white", mec="k", mew=0.6)
    for n, p in enumerate(w):
        ax.annotate(str(n), p[:2], textcoords="offset points", xytext=(0, 4), fontsize=6,
                    ha="center")
    ax.plot(*tile.start[:2], "^", ms=9, c="lime", mec="k", label="start")
    ax.plot(*tile.middle[:2], "s", ms=8, c="orange", mec="k", label="middle")
    ax.plot(*tile.terminus[:2], "*", ms=13, c="red", mec="k", label="terminus")
    ax.legend(loc="upper left", fontsize=6, framealpha=0.7)
    ax.set_title(title or f"{tile.category} level {tile.level} variant {tile.variant}",
                 fontsize=9)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return Path(path)


def primitive_png(name: str, path: Path, seed: int = 0,
                  difficulties: tuple[float, ...] = (0.0, 0.5, 1.0)) -> Path:
    """One picture of primitive ``name`` on a 5 m x 4 m segment at several difficulties."""
    from legoh.envs.terrain.primitives import PRIMITIVES, Grid, make_patch

    grid = Grid(5.0, 4.0, 0.05)
    fig, axes = plt.subplots(1, len(difficulties), figsize=(2.6 * len(difficulties), 2.6))
    for ax, d in zip(np.atleast_1d(axes), difficulties, strict=True):
        patch = make_patch(name, d, np.random.default_rng(seed), grid)
        im = plot_heights(ax, patch.heights, np.zeros(2), grid.res, patch.boxes, patch.cylinders)
        if len(patch.waypoints):
            ax.plot(patch.waypoints[:, 0], patch.waypoints[:, 1], "o", ms=3, mfc="w", mec="k")
        spec = PRIMITIVES[name]
        value = patch.params.get(spec.prop, 0.0)
        ax.set_title(f"d={d:g}  {spec.prop}={value:.2f}", fontsize=8)
        ax.tick_params(labelsize=6)
        fig.colorbar(im, ax=ax, shrink=0.7).ax.tick_params(labelsize=6)
    fig.suptitle(name, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=72)
    plt.close(fig)
    return Path(path)
