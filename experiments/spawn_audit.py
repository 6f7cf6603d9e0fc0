"""Audit the benchmark's spawns (issue 44, finding 6): where do the evaluation robots start?

    python experiments/spawn_audit.py                  # H1, the shipping protocol's map
    python experiments/spawn_audit.py --robot g1 --resets 20

Builds the shipping protocol's evaluation env (``trail=hike``, levels 0-4, the eval spawn
settings), resets every robot ``--resets`` times per level and measures each spawn from the
geometry alone, not from the spawn code under test:

* **foot over a pit** (Gap): a point of a sole (each foot's collider footprint in the default
  pose, a 3 x 3 grid over it, turned by the spawn's yaw) stands on ground more than
  ``PIT_DROP`` below the waypoint the robot was put on (stones and platforms sit on a 1 m pit);
* **base over a pit** (Gap): the same test at the base's xy;
* **no obstacle ahead**: the expert path from the spawn to the terminus (spawn, the
  waypoints ahead, terminus) crosses no hurdle's footprint (Hurdle), no pit (Gap: ground
  ``PIT_DROP`` below the stood-on waypoint);
* **in the window**: the stood-on waypoint has 2-10 m of path left (``eval.spawn_remaining``).

Prints one row per (category, level) and the shares the issue quotes; ``--json`` writes them.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from legoh import keys  # noqa: E402
from legoh.envs.scene import standing_pose  # noqa: E402

# m below the stood-on waypoint: a pit (trail.geometry v2: pits 0.18-1.1 m deep by level,
# stone tops wobble up to 0.08 m; v1: 1 m deep)
PIT_DROP = 0.15
PATH_STEP = 0.025  # m between samples of the path ahead (half a height-field cell)


def sole_grid(scene, n: int = 3) -> np.ndarray:
    """(F * n * n, 2) base-frame xy points covering each foot's collider footprint in the
    default pose (yaw 0), from MuJoCo's own kinematics."""
    model, data = scene.model, standing_pose(scene)
    points = []
    for body in scene.robot.feet_bodies:
        bid = model.body(body).id
        lo, hi = np.full(2, np.inf), np.full(2, -np.inf)
        for g in np.flatnonzero((model.geom_bodyid == bid) & (model.geom_contype > 0)):
            rot = data.geom_xmat[g].reshape(3, 3)
            centre = data.geom_xpos[g] + rot @ model.geom_aabb[g, :3]
            half = np.abs(rot) @ model.geom_aabb[g, 3:]
            lo, hi = np.minimum(lo, (centre - half)[:2]), np.maximum(hi, (centre + half)[:2])
        u, v = np.meshgrid(np.linspace(lo[0], hi[0], n), np.linspace(lo[1], hi[1], n))
        points.append(np.stack([u.ravel(), v.ravel()], axis=-1))
    return np.concatenate(points)


def in_boxes(xy: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """(P,) bool: points ``xy`` (P, 2) inside any box footprint (world frame)."""
    rel = xy[:, None, :] - boxes[None, :, :2]
    c, s = np.cos(boxes[:, 6]), np.sin(boxes[:, 6])
    along = rel[..., 0] * c + rel[..., 1] * s
    across = -rel[..., 0] * s + rel[..., 1] * c
    return ((np.abs(along) <= boxes[:, 3]) & (np.abs(across) <= boxes[:, 4])).any(axis=1)


def path_ahead(start: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(P, 2) samples every ``PATH_STEP`` m of the polyline ``start`` -> ``points``."""
    nodes = np.concatenate([start[None], points])
    out = [start[None]]
    for a, b in zip(nodes[:-1], nodes[1:], strict=True):
        k = max(1, int(np.ceil(np.linalg.norm(b - a) / PATH_STEP)))
        out.append(a + np.linspace(0.0, 1.0, k + 1)[1:, None] * (b - a))
    return np.concatenate(out)


def audit_reset(env, td, soles: np.ndarray) -> dict[str, np.ndarray]:
    """Per robot of one reset TensorDict: ``foot_pit``, ``base_pit``, ``hurdle_ahead``,
    ``pit_ahead``, ``in_window`` (bool), ``category`` (names)."""
    tm, trails = env.terrain, env.trails
    pos = td[keys.BASE_POS].cpu().numpy()
    quat = td[keys.BASE_QUAT].cpu().numpy()
    yaw = 2.0 * np.arctan2(quat[:, 3], quat[:, 0])
    tile = td[keys.TILE].cpu().numpy()
    goal = td[keys.WAYPOINT].cpu().numpy()
    n = len(tile)
    stood = np.array([tm.tiles[tile[i]].waypoints[goal[i] - 1, 2] if goal[i] > 0
                      else tm.tiles[tile[i]].start[2] for i in range(n)])
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    feet = np.stack([pos[:, None, 0] + c * soles[:, 0] - s * soles[:, 1],
                     pos[:, None, 1] + s * soles[:, 0] + c * soles[:, 1]], axis=-1)
    foot_pit = (tm.height_at(feet) < stood[:, None] - PIT_DROP).any(axis=1)
    base_pit = tm.height_at(pos[:, :2]) < stood - PIT_DROP
    ahead, pit = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
    for i in range(n):
        path = path_ahead(pos[i, :2], trails.waypoints[tile[i], goal[i]: trails.count[tile[i]]])
        ahead[i] = len(tm.boxes) > 0 and in_boxes(path, tm.boxes).any()
        pit[i] = (tm.height_at(path) < stood[i] - PIT_DROP).any()
    on = np.maximum(goal - 1, 0)
    left = trails.length[tile] - np.where(goal > 0, trails.cum_length[tile, on], 0.0)
    lo, hi = env.cfg.spawn_remaining
    names = np.asarray(tm.categories)[env.category.cpu().numpy()]
    return {"foot_pit": foot_pit, "base_pit": base_pit, "hurdle_ahead": ahead,
            "pit_ahead": pit, "in_window": (left >= lo - 1e-6) & (left <= hi + 1e-6),
            "category": names}


def audit(env, levels: list[int], resets: int) -> dict[str, dict[str, float]]:
    """``{"<category> <level>": {"spawns", "foot_pit", "base_pit", "no_hurdle_ahead",
    "no_pit_ahead", "in_window"}}``: shares in % over ``resets`` resets of every robot on
    each level."""
    soles = sole_grid(env.scene)
    rows = {}
    for level in levels:
        env.set_level(level)
        parts = [audit_reset(env, env.reset(), soles) for _ in range(resets)]
        got = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
        for cat in dict.fromkeys(got["category"].tolist()):
            sel = got["category"] == cat
            rows[f"{cat} {level}"] = {
                "spawns": int(sel.sum()),
                "foot_pit": 100.0 * got["foot_pit"][sel].mean(),
                "base_pit": 100.0 * got["base_pit"][sel].mean(),
                "no_hurdle_ahead": 100.0 * (~got["hurdle_ahead"][sel]).mean(),
                "no_pit_ahead": 100.0 * (~got["pit_ahead"][sel]).mean(),
                "in_window": 100.0 * got["in_window"][sel].mean()}
    return rows


def main() -> None:
    from legoh.config import register_configs
    from legoh.config.compose import compose_config
    from legoh.eval.benchmark import make_eval_env

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="h1")
    parser.add_argument("--robots", type=int, default=80, help="robots of the eval env")
    parser.add_argument("--resets", type=int, default=10, help="resets per level")
    parser.add_argument("--variants", type=int, default=5)
    parser.add_argument("--runs", type=int, default=2, help="evaluation runs (seeds 2000..)")
    parser.add_argument("--json", help="write the rows to this file")
    args = parser.parse_args()
    register_configs()
    cfg = compose_config(f"robot={args.robot}", "trail=hike", f"eval.robots={args.robots}",
                         f"eval.variants={args.variants}", "eval.levels=[0,1,2,3,4]",
                         "eval.seed=2000")
    runs = []
    for run in range(args.runs):  # the shipping protocol's runs: seeds 2000, 2001
        env = make_eval_env(cfg, run)
        try:
            runs.append(audit(env, list(cfg.eval.levels), args.resets))
        finally:
            env.close()
    rows = {name: {k: float(np.mean([r[name][k] for r in runs])) for k in runs[0][name]}
            for name in runs[0]}
    print("| category level | spawns | foot over a pit % | base over a pit % | no obstacle "
          "ahead % | 2-10 m left % |\n|---|---|---|---|---|---|")
    for name, r in rows.items():
        cat = name.split()[0]
        if cat in ("gap", "hurdle"):
            none = r["no_pit_ahead" if cat == "gap" else "no_hurdle_ahead"]
            print(f"| {name} | {r['spawns'] * args.runs:.0f} | {r['foot_pit']:.1f} | "
                  f"{r['base_pit']:.1f} | {none:.1f} | {r['in_window']:.1f} |")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
