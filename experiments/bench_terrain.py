"""Benchmark: build time and peak memory of the terrain map.

    python experiments/bench_terrain.py        # writes experiments/results/bench_terrain.{json,md}

Cases: the full map (5 categories x 5 levels x 5 variants, 5 cm cells), the map at
1, 2 and 3 variants (linear growth check), and the hill trail (5 levels x 1 variant).
Each case runs in a fresh process so peak RSS is its own.
"""

import json
import multiprocessing as mp
import platform
import resource
import time
from pathlib import Path

CATEGORIES = ["randommix", "ditch", "hurdle", "gap", "forest"]
OUT = Path(__file__).parent / "results"


def _case(kw: dict, queue) -> None:
    import numpy as np

    from legoh.config.trail import TrailConfig
    from legoh.envs.terrain import build_terrain_map

    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.perf_counter()
    tm = build_terrain_map(TrailConfig(**kw), seed=0)
    dt = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB on Linux
    queue.put({"build_s": round(dt, 3), "peak_rss_mib": round(peak / 1024, 1),
               "build_rss_mib": round((peak - base) / 1024, 1), "tiles": len(tm.tiles),
               "cells": int(tm.heights.size), "heights_mib": round(tm.heights.nbytes / 2**20, 1),
               "boxes": len(tm.boxes), "cylinders": len(tm.cylinders),
               "height_range_m": [float(tm.heights.min()), float(tm.heights.max())],
               "waypoints": int(sum(len(t.waypoints) for t in tm.tiles)),
               "edge_share": float(np.mean(tm.edge_mask))})


def run(kw: dict) -> dict:
    queue = mp.get_context("spawn").Queue()
    proc = mp.get_context("spawn").Process(target=_case, args=(kw, queue))
    proc.start()
    result = queue.get()
    proc.join()
    return result


def main() -> None:
    cases = {f"full_{v}v": dict(name="bench", categories=CATEGORIES, levels=5, variants=v)
             for v in (1, 2, 3, 5)}
    cases["hill"] = dict(name="hill", categories=["hill"], levels=5, variants=1,
                         tile_length=64.0, tile_width=12.0)
    results = {name: run(kw) for name, kw in cases.items()}
    meta = {"machine": platform.processor() or platform.machine(), "python":
            platform.python_version(), "resolution_m": 0.05}
    OUT.mkdir(exist_ok=True)
    (OUT / "bench_terrain.json").write_text(json.dumps({"meta": meta, "cases": results},
                                                       indent=2))
    lines = ["# Terrain map build benchmark", "",
             "`python experiments/bench_terrain.py`; 5 cm cells; one fresh process per case "
             "(peak RSS includes the Python + numpy + scipy baseline; build RSS is the rise "
             "during the build).", "",
             "| case | tiles | cells (M) | build (s) | peak RSS (MiB) | build RSS (MiB) | "
             "heights (MiB) | boxes | trunks | height range (m) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for name, r in results.items():
        lo, hi = r["height_range_m"]
        lines.append(f"| {name} | {r['tiles']} | {r['cells'] / 1e6:.1f} | {r['build_s']:.2f} | "
                     f"{r['peak_rss_mib']:.0f} | {r['build_rss_mib']:.0f} | "
                     f"{r['heights_mib']:.0f} | {r['boxes']} | {r['cylinders']} | "
                     f"{lo:.2f} .. {hi:.2f} |")
    lines += ["", f"Machine: {meta['machine']}, Python {meta['python']}."]
    (OUT / "bench_terrain.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
