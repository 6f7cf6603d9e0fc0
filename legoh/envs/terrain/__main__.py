"""Write a trail's mesh and top-down picture.

    python -m legoh.envs.terrain --trail forest --level 2 --seed 0 --out terrain_out
    python -m legoh.envs.terrain --trail hill --format obj trail.resolution=0.1
    python -m legoh.envs.terrain --primitives docs/img     # one picture per primitive

Extra ``key=value`` arguments are Hydra overrides of the composed run config.
"""

import argparse
from pathlib import Path

from legoh.envs.terrain.export import primitive_png, tile_png, tile_scene
from legoh.envs.terrain.primitives import PRIMITIVES
from legoh.envs.terrain.terrain_map import build_terrain_map


def load_trail(name: str, overrides: list[str]):
    """The ``trail`` group of the run config composed with ``trail=name`` (DictConfig)."""
    from legoh.config.compose import compose_config

    return compose_config(f"trail={name}", *overrides).trail


def main(argv: list[str] | None = None) -> list[Path]:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--trail", default="randommix", help="conf/trail/<name>.yaml")
    ap.add_argument("--category", default=None, help="category of the trail (default: first)")
    ap.add_argument("--level", type=int, default=0)
    ap.add_argument("--variant", type=int, default=0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--format", choices=["glb", "obj"], default="glb")
    ap.add_argument("--out", type=Path, default=Path("terrain_out"))
    ap.add_argument("--primitives", type=Path, default=None,
                    help="write terrain_<primitive>.png for every primitive into this folder")
    ap.add_argument("overrides", nargs="*", help="Hydra overrides, e.g. trail.resolution=0.1")
    args = ap.parse_args(argv)
    if args.primitives is not None:
        args.primitives.mkdir(parents=True, exist_ok=True)
        return [primitive_png(n, args.primitives / f"terrain_{n}.png", args.seed)
                for n in PRIMITIVES]
    cfg = load_trail(args.trail, args.overrides)
    category = args.category or cfg.categories[0]
    cfg.variants = max(int(cfg.variants), args.variant + 1)
    tm = build_terrain_map(cfg, args.seed)
    tile = tm.tiles[tm.tile_index(category, args.level, args.variant)]
    args.out.mkdir(parents=True, exist_ok=True)
    stem = args.out / f"{category}_l{args.level}_v{args.variant}_s{args.seed}"
    mesh = tile_scene(tm, tile).export(f"{stem}.{args.format}")
    if isinstance(mesh, dict):  # OBJ with materials comes back as files by name
        mesh = mesh.get(f"{stem.name}.obj", next(iter(mesh.values())))
    Path(f"{stem}.{args.format}").write_bytes(mesh if isinstance(mesh, bytes) else mesh.encode())
    png = tile_png(tm, tile, Path(f"{stem}.png"))
    print(f"wrote {stem}.{args.format} and {png}: {len(tile.waypoints)} waypoints, "
          f"path {tile.length:.1f} m")
    return [Path(f"{stem}.{args.format}"), png]


if __name__ == "__main__":
    main()
