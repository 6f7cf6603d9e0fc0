"""Procedural hiking trails: primitives, trail categories, expert goals, the terrain map.

    from legoh.envs.terrain import build_terrain_map
    tm = build_terrain_map(trail_cfg, seed=0)
"""

from legoh.envs.terrain.primitives import PRIMITIVES, Grid, Patch, register_primitive
from legoh.envs.terrain.terrain_map import TerrainMap, Tile, build_terrain_map
from legoh.envs.terrain.trails import ALL_CATEGORIES, CATEGORIES, CategorySpec

__all__ = ["build_terrain_map", "TerrainMap", "Tile", "PRIMITIVES", "Grid", "Patch",
           "register_primitive", "CATEGORIES", "CategorySpec", "ALL_CATEGORIES"]
