"""Maps of the terrain that the step's heights and the gait clock read, built once per env
from the terrain map (numpy, at construction; looked up per step as ``state.Grid``).

* The support: what a robot stands on. The ground raised to obstacle tops (not tree
  trunks) with every pit narrower than a window filled to its rim, by a grey closing (a dilation,
  then an erosion, with a flat square window): narrow low features vanish, raised ones and
  monotone slopes and stairs keep their shape. A foot over a 0.6 m gap then reads its lift
  above the rim (a person's measure), not ~1 m above the pit floor; a foot over a box, its
  lift above the box top. Pits wider than the window (a level-4 ditch) stay: a robot in them
  stands on their floor.
* The clock weight: 1 where the gait clock holds, fading to 0 near an edge, a pit or an
  obstacle, where the terrain asks for steps the clock forbids (long, high, irregular).
"""

from __future__ import annotations

import numpy as np
import torch
from scipy import ndimage

from legoh.config.env import HeightReference
from legoh.envs.mdp.state import Grid

# m: an obstacle or pit rises or sinks at least this much against the support
FEATURE_HEIGHT = 0.05


def support_heights(scan_heights: np.ndarray, resolution: float, window: float) -> np.ndarray:
    """(nx, ny) heights of the support: ``scan_heights`` with pits up to ``window`` m wide
    filled to their rim."""
    cells = 2 * int(round(window / resolution / 2)) + 1  # odd: centred on the cell
    return ndimage.grey_closing(scan_heights, size=(cells, cells)).astype(np.float32)


def clock_weights(ground: np.ndarray, scan_heights: np.ndarray, support: np.ndarray,
                  edges: np.ndarray, resolution: float, near: float, fade: float
                  ) -> np.ndarray | None:
    """(nx, ny) weight of the gait clock's terms: 0 within ``near`` m of a feature (an edge
    cell, an obstacle top or a pit against the support), rising linearly to 1 at ``near +
    fade`` m. None for ``near`` = 0: the clock everywhere."""
    if near <= 0.0:
        return None
    feature = edges | (scan_heights - ground > FEATURE_HEIGHT) | (
        support - ground > FEATURE_HEIGHT)
    if not feature.any():
        return np.ones(ground.shape, dtype=np.float32)
    distance = ndimage.distance_transform_edt(~feature) * resolution  # m to the nearest
    return np.clip((distance - near) / max(fade, 1e-6), 0.0, 1.0).astype(np.float32)


def terrain_fields(scene, cfg, device: torch.device, dtype: torch.dtype
                   ) -> tuple[Grid, Grid | None]:
    """The env's (height reference, clock weight) grids for ``scene`` (a ``Scene``) under
    ``cfg`` (EnvConfig): the support or the bare ground; None for the clock everywhere."""
    from legoh.envs.scene import scan_height_grid

    tm = scene.terrain
    # tree trunks are neither ground to stand on nor a reason to leap: left out of both
    raised = scan_height_grid(tm, trees=False)
    filled = support_heights(raised, tm.resolution, cfg.support_window)
    heights = (filled if HeightReference(cfg.height_reference) == HeightReference.support
               else tm.heights)
    weights = clock_weights(tm.heights, raised, filled, tm.edge_mask, tm.resolution,
                            cfg.gait.yield_near, cfg.gait.yield_fade)

    def grid(values: np.ndarray) -> Grid:
        return Grid(values, tm.origin, tm.resolution, device, dtype)

    return grid(heights), (None if weights is None else grid(weights))
