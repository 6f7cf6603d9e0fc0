"""Benchmark: build time and peak memory of the terrain map.

    python experiments/bench.py terrain   # adds a run to experiments/results/bench_terrain.*

Cases: the full map (5 categories x 5 levels x 5 variants, 5 cm cells), the map at
1, 2 and 3 variants (linear growth check), and the hill trail (5 levels x 1 variant).
Each case runs in a fresh process so peak RSS is its own.
"""

import argparse
import multiprocessing as mp
import resource
import time

RESULTS = "bench_terrain"
TITLE = "Terrain map build benchmark"
TORCH_THREADS = None  # no torch
CATEGORIES = ["randommix", "ditch", "hurdle", "gap", "forest"]
RESOLUTION = 0.05  # m: the map's cells (TrailConfig's default)


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


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """No arguments of its own: every case."""


def measure(args: argparse.Namespace) -> dict:
    """Each case in a fresh process."""
    cases = {f"full_{v}v": dict(name="bench", categories=CATEGORIES, levels=5, variants=v)
             for v in (1, 2, 3, 5)}
    cases["hill"] = dict(name="hill", categories=["hill"], levels=5, variants=1,
                         tile_length=64.0, tile_width=12.0)
    return {"resolution_m": RESOLUTION, "cases": {name: run(kw) for name, kw in cases.items()}}


def summary(run: dict) -> str:
    full = run["results"]["cases"]["full_5v"]
    return f"full map {full['build_s']:.1f} s, peak {full['peak_rss_mib']:.0f} MiB"


def markdown(run: dict) -> str:
    results = run["results"]["cases"]
    lines = [f"{run['results']['resolution_m'] * 100:g} cm cells; one fresh process per case "
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
    return "\n".join(lines) + "\n"
