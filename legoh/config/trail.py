"""Trail config schema (``conf/trail/*.yaml``); see docs/terrain.md for every choice."""

from dataclasses import dataclass, field
from enum import Enum


class TrailGeometry(Enum):
    """How the gap-like primitives and hurdles ramp with the level (docs/terrain.md, "Trails
    that teach"). ``v1``: the first geometry, a 0.8 m causeway over a 1 m pit at level 0 (what
    the shipped policies trained on); ``v2``: wide and shallow at level 0, narrow and deep at
    the top, every level within a G1's and an H1's leg."""

    v1 = "v1"
    v2 = "v2"


@dataclass
class TrailConfig:
    """Which trails to build and how: categories x levels x variants of tiles."""

    name: str = "???"
    categories: list[str] = field(default_factory=list)  # e.g. [randommix]; [flat]; [hill]
    levels: int = 5  # difficulty levels 0..levels-1 (level / (levels - 1) is the difficulty)
    variants: int = 5  # random variants per (category, level)
    tile_length: float = 24.0  # m, along the trail (x)
    tile_width: float = 8.0  # m, across the trail (y)
    resolution: float = 0.05  # m per height-field cell
    goal_spacing: float = 2.0  # m between expert waypoints on open trails
    clearance: float = 0.4  # m, minimum distance of a waypoint from any obstacle
    border: float = 4.0  # m of flat ground between tiles and around the map
    start_pad: float = 2.0  # m of flat ground at each tile end (spawn, terminus)
    segment_length: list[float] = field(default_factory=lambda: [3.0, 5.0])  # m, min, max
    primitives: list[str] = field(default_factory=list)  # primitive pool; empty: category's
    max_elevation: float = 1.5  # m, a tile's ground keeps within this of its start height
    edge_grade: float = 2.0  # -, rise over run between cells that marks an edge
    plan_resolution: float = 0.1  # m per cell of the detour-planning occupancy grid
    detour_noise: float = 0.5  # -, random extra cost per planning cell (detour diversity)
    hill_categories: list[str] = field(
        default_factory=lambda: ["randommix", "ditch", "hurdle", "gap", "forest"])
    hill_rise: float = 4.0  # m, hillside height at the top level (40% of it at level 0)
    geometry: TrailGeometry = TrailGeometry.v2  # gap, ditch and hurdle ramps: v1 | v2
