"""Qualitative pictures of an evaluation: robots' torso paths over the trail, top-down.

Like the paper's qualitative figures: the tile's heights (colour) with its obstacles, the
expert waypoints and terminus, and each robot's path from its start (circle) to the end
of its first episode: a star where it reached the terminus, a cross where it fell, a
square where its time ran out.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless: files only
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from legoh.envs.terrain.export import plot_heights, tile_obstacles, tile_window  # noqa: E402

OUTCOMES = ("reached", "fell", "timeout")
END_MARKER = {"reached": ("*", "gold", 11), "fell": ("X", "red", 8),  # marker, colour, size
              "timeout": ("s", "deepskyblue", 6)}
PATH_COLOUR = {"reached": "gold", "fell": "red", "timeout": "deepskyblue"}
MAX_PANELS = 6  # a picture stays small: at most this many tiles


def outcome_labels(success: np.ndarray, fall: np.ndarray) -> np.ndarray:
    """(N,) ``"reached"`` / ``"fell"`` / ``"timeout"`` from per-robot success and fall flags."""
    return np.where(success, "reached", np.where(fall, "fell", "timeout"))


def plot_trajectories(terrain, tiles: Sequence[int], paths: Sequence[np.ndarray],
                      outcomes: Sequence[str], path: str | Path, title: str = "",
                      margin: float = 0.5) -> Path:
    """Write a top-down PNG of robots' paths on their trail tiles, one panel per tile.

    Args:
        terrain: the env's ``TerrainMap`` (heights, boxes, cylinders, tiles).
        tiles: (N,) index into ``terrain.tiles`` of each robot's tile.
        paths: N arrays (T_n, 2 or 3), world frame, m: each robot's torso path, start first.
        outcomes: (N,) ``"reached"``, ``"fell"`` or ``"timeout"`` per robot.
        path: output PNG. title: figure title. margin: m shown around each tile.

    Returns:
        ``path``. Panels are the distinct tiles in order of first appearance (at most
        :data:`MAX_PANELS`), stacked top to bottom.
    """
    tiles = np.asarray(tiles, dtype=np.int64)
    if not (len(tiles) == len(paths) == len(outcomes)):
        raise ValueError(f"tiles, paths and outcomes must have one entry per robot, got "
                         f"{len(tiles)}, {len(paths)}, {len(outcomes)}")
    bad = sorted(set(outcomes) - set(OUTCOMES))
    if bad:
        raise ValueError(f"unknown outcome(s) {bad}; expected {OUTCOMES}")
    shown = list(dict.fromkeys(tiles.tolist()))[:MAX_PANELS]
    if not shown:
        raise ValueError("no robots to draw")
    sizes = np.array([terrain.tiles[k].size for k in shown])
    width = float(np.clip(sizes[:, 0].max() / 3.0, 6.0, 12.0))
    heights = [max(2.2, width * s[1] / s[0] + 0.6) for s in sizes]
    fig, axes = plt.subplots(len(shown), 1, figsize=(width, sum(heights)), squeeze=False)
    for ax, k in zip(axes[:, 0], shown, strict=True):
        tile = terrain.tiles[k]
        si, sj = tile_window(terrain, tile, margin)
        origin = terrain.origin + np.array([si.start, sj.start]) * terrain.resolution
        im = plot_heights(ax, terrain.heights[si, sj], origin, terrain.resolution,
                          *tile_obstacles(terrain, tile, margin))
        fig.colorbar(im, ax=ax, label="height (m)", shrink=0.8)
        w = tile.waypoints
        ax.plot(w[:, 0], w[:, 1], "o", ms=3.5, mfc="white", mec="k", mew=0.6, zorder=3)
        ax.plot(*tile.terminus[:2], "P", ms=11, c="magenta", mec="k", zorder=3,
                label="terminus")
        counts = dict.fromkeys(OUTCOMES, 0)
        for n in np.flatnonzero(tiles == k):
            xy, end = np.asarray(paths[n])[:, :2], outcomes[n]
            counts[end] += 1
            ax.plot(xy[:, 0], xy[:, 1], "-", lw=1.0, c=PATH_COLOUR[end], alpha=0.85, zorder=4)
            ax.plot(*xy[0], "o", ms=4, c="lime", mec="k", mew=0.4, zorder=5)
            marker, colour, size = END_MARKER[end]
            ax.plot(*xy[-1], marker, ms=size, c=colour, mec="k", mew=0.5, zorder=6)
        for end in OUTCOMES:  # legend entries, drawn once per panel
            marker, colour, size = END_MARKER[end]
            ax.plot([], [], marker, ms=size * 0.8, c=colour, mec="k",
                    label=f"{end} ({counts[end]})")
        ax.plot([], [], "o", ms=4, c="lime", mec="k", label="start")
        ax.legend(loc="upper left", fontsize=6, framealpha=0.7, ncol=5)
        ax.set_title(f"{tile.category} level {tile.level} variant {tile.variant}", fontsize=9)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return Path(path)
