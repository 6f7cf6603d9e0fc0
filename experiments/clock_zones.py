"""Where the gait clock yields along each trail (issue 44, "the zone tax").

    python experiments/clock_zones.py [--robot h1]

Builds the hiking map (``trail=hike``: five categories x levels 0-4) and samples the clock's
weight (``env.gait.yield_near`` / ``yield_fade``: 0 near an edge, pit or obstacle, 1 away
from them) every 5 cm along each tile's expert path. Prints per (category, level) the share
of the path where the clock yields (weight < 1) and the path's mean weight: with
``env.gait.yield_pay=0`` the clock's terms pay that share of what the same steps earn on open
ground. Writes ``experiments/results/clock_zones.md``.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
import torch  # noqa: E402

from legoh.config.compose import compose_config, register_configs  # noqa: E402
from legoh.envs.hiking_env import make_env  # noqa: E402

OUT = Path(__file__).resolve().parent / "results" / "clock_zones.md"


def path_points(trails, k: int, step: float = 0.05) -> np.ndarray:
    """Points every ``step`` m along tile ``k``'s expert path (start, then its waypoints)."""
    pts = np.vstack([trails.start[k, :2], trails.waypoints[k, : trails.count[k]]])
    out = [a + (b - a) * t for a, b in zip(pts[:-1], pts[1:], strict=True)
           for t in np.arange(0.0, 1.0, step / max(np.linalg.norm(b - a), step))]
    return np.array(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="h1")
    args = parser.parse_args()
    register_configs()
    env = make_env(compose_config(f"robot={args.robot}", "trail=hike"), 1)
    trails, grid, names = env.trails, env.clock_grid, env.terrain.categories
    weights: dict[tuple[int, int], list[np.ndarray]] = {}
    for k in range(len(trails.count)):
        w = grid.bilinear(torch.as_tensor(path_points(trails, k), dtype=grid.origin.dtype))
        weights.setdefault((int(trails.category[k]), int(trails.level[k])), []).append(w.numpy())
    lines = [f"# Where the gait clock yields ({args.robot}, `python experiments/clock_zones.py`)",
             "", "Per trail category and level, along the expert paths: the share where the "
             "clock yields (weight < 1) and its mean weight. With `env.gait.yield_pay=0` the "
             "clock's terms (feet_phase, feet_contact_phase: half the positive reward of the "
             "H1 v2 campaign's walkers on RandomMix) pay the mean weight's share of what "
             "the same steps earn on open ground; with `yield_pay=p`, a walker earning p "
             "of their best pays alike everywhere.", "",
             "| category | level | yields on | mean weight |", "|---|---|---|---|"]
    for (c, level), ws in sorted(weights.items()):
        w = np.concatenate(ws)
        lines.append(f"| {names[c]} | {level} | {(w < 1).mean():.0%} | {w.mean():.2f} |")
    text = "\n".join(lines) + "\n"
    print(text)
    OUT.write_text(text)
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
