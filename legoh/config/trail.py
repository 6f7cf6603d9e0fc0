"""Trail config schema (``conf/trail/*.yaml``)."""

from dataclasses import dataclass, field


@dataclass
class TrailConfig:
    """Which trails to build and how: categories x levels x variants of tiles."""

    name: str = "???"
    categories: list[str] = field(default_factory=list)  # e.g. [randommix]; [flat]; [hill]
    levels: int = 5  # difficulty levels 0..levels-1
    variants: int = 5  # random variants per (category, level)
    tile_length: float = 24.0  # m, along the trail (x)
    tile_width: float = 8.0  # m, across the trail (y)
    resolution: float = 0.05  # m per height-field cell
    goal_spacing: float = 2.0  # m between expert waypoints on open trails
    clearance: float = 0.4  # m, minimum distance of a waypoint from any obstacle
