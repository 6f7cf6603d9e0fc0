"""Depth on the CPU: the ray-marched camera against ``mj_multiRay`` and the physics step, in
one run.

For each robot, trail map (RandomMix: the default map, 576 height-field chunks; Forest: the
map with the most obstacles) and N in {64, 256}:
  * physics: ``mujoco.rollout`` of the same model, N, substeps and threads, holding the
    default pose (the ceiling of `bench.py env`), seconds per env per policy step;
  * depth: one 32 x 24 frame for all N cameras by each backend (``env.depth.backend``:
    ``raymarch``, ``multiray``), seconds per env per frame, and depth at 10 Hz (a frame every
    5 policy steps) over the physics step: the ratio the backends are judged by;
  * parity on the same cameras: median |raymarch - multiray| and the share within 5 cm, over
    the pixels where either sees a surface;
  * with ``--env`` (RandomMix rows): HikingEnv steps/s with depth on, per backend, against
    the ceiling (`bench.py env`'s measurement);
  * with ``--tradeoff``: the march's settings (step, bisections, block) against speed and
    accuracy, on a map of every category (2 levels, 1 variant; the parity test's map).

Cameras: robots in the default pose standing along the expert paths of every tile (all
levels), facing along them, N of them spread over the map.

    python experiments/bench.py depth [--quick] [--env] [--tradeoff] [--robots h1 g1]

Adds a run to experiments/results/bench_depth.{json,md}. Absolute numbers depend on the machine and
on what else runs on it; the ratios measured in the same run are the figures to read.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
import torch
from omegaconf import OmegaConf

from benches.env import LEVEL, ceiling_rate, env_rate
from legoh.config.compose import compose_config
from legoh.envs.hiking_env import HikingEnv
from legoh.envs.sensors import camera_poses

RESULTS = "bench_depth"
TITLE = "Depth on the CPU: ray-march vs mj_multiRay vs the physics step"
TORCH_THREADS = 1  # as training runs (algo.torch_threads: 1)
BACKENDS = ("raymarch", "multiray")
# (name, env.depth.backend): raymarch on the physics threads (the env's), on one, multiray
CAMERAS = [("raymarch", "raymarch"), ("raymarch_1thread", "raymarch"), ("multiray", "multiray")]
WITHIN = 0.05  # m


def standing_cameras(env: HikingEnv, n: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Camera positions (n, 3) and rotations (n, 3, 3) of default-pose robots standing along
    the expert paths of every tile of ``env``'s map, spread evenly."""
    scene = env.scene
    m, tm = scene.model, scene.terrain
    points = [(tile.path, i) for tile in tm.tiles for i in range(0, len(tile.path) - 1, 10)]
    qpos = []
    for path, i in (points[j] for j in np.linspace(0, len(points) - 1, n).astype(int)):
        ahead = path[min(i + 3, len(path) - 1)] - path[i]
        yaw = np.arctan2(ahead[1], ahead[0])
        q = m.qpos0.copy()
        q[0:3] = [*path[i, :2], tm.height_at(path[i, :2]) + scene.stand_height]
        q[3:7] = [np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]
        q[scene.qpos_adr] = scene.robot.default_pose
        qpos.append(q)
    pos, mat = camera_poses(m, np.array(qpos))
    return torch.as_tensor(pos), torch.as_tensor(mat)


def frame_cost(cam, pos: torch.Tensor, mat: torch.Tensor, reps: int) -> float:
    """Median seconds per env per frame over ``reps`` frames."""
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        cam.render(pos, mat)
        times.append(time.perf_counter() - t0)
    return float(np.median(times)) / len(pos)


def parity(got: np.ndarray, ref: np.ndarray, far: float) -> dict[str, float]:
    seen = (ref < far) | (got < far)
    err = np.abs(got - ref)[seen]
    return {"median_err_m": float(np.median(err)), "within_5cm": float(np.mean(err <= WITHIN)),
            "seen_pixels": float(seen.mean())}


def make(robot: str, trail: str, n: int) -> tuple[HikingEnv, object]:
    """HikingEnv without depth on ``trail``'s full map, robots on level 2; and its config."""
    cfg = compose_config(f"robot={robot}", f"trail={trail}", "env.curriculum.enabled=false")
    env = HikingEnv(OmegaConf.to_object(cfg.robot), OmegaConf.to_object(cfg.trail),
                    OmegaConf.to_object(cfg.env), OmegaConf.to_object(cfg.sim), n, seed=0)
    env.set_level(LEVEL)
    env.reset()
    return env, cfg


def row(robot: str, trail: str, n: int, args: argparse.Namespace) -> dict:
    """One robot, map and N: physics and each camera timed in interleaved rounds (so load
    from other work falls on all of them alike), medians over the rounds."""
    env, cfg = make(robot, trail, n)
    d, fovy = cfg.env.depth, cfg.robot.camera.fovy_deg
    pos, mat = standing_cameras(env, n)
    threads = env.sim.threads
    cams, out, images = {}, {"robot": robot, "trail": trail, "num_envs": n,
                             "threads": threads, "torch_threads": torch.get_num_threads()}, {}
    for name, backend in CAMERAS:
        t0 = time.perf_counter()
        cams[name] = env.sim.make_depth_camera(fovy, d.width, d.height, d.far, backend)
        if name == "raymarch_1thread":
            cams[name].threads, cams[name]._pool = 1, None
        images[name] = np.asarray(cams[name].render(pos, mat), dtype=np.float64)  # warm-up
        out[f"{name}_setup_s"] = time.perf_counter() - t0
    physics, frames = [], {name: [] for name in cams}
    for _ in range(args.rounds):
        physics.append(1.0 / ceiling_rate(env, args.physics_steps))
        for name, cam in cams.items():
            frames[name].append(frame_cost(cam, pos, mat, args.reps))
    out["physics_s_per_step"] = physics_s = float(np.median(physics))
    for name in cams:
        out[f"{name}_s_per_frame"] = cost = float(np.median(frames[name]))
        out[f"{name}_10hz_over_physics"] = cost / d.every / physics_s
    out.update(parity(images["raymarch"], images["multiray"], d.far))
    out["multiray_over_raymarch"] = out["multiray_s_per_frame"] / out["raymarch_s_per_frame"]
    if args.env and trail == "randommix":  # the env benchmark's map and level
        out["ceiling_steps_per_s"] = 1.0 / physics_s
        for backend in BACKENDS:
            rate, denv = env_rate(robot, n, True, args.physics_steps, scene=env.scene,
                                  extra=[f"env.depth.backend={backend}"])
            denv.close()
            out[f"env_{backend}_steps_per_s"] = rate
            out[f"env_{backend}_over_ceiling"] = rate * physics_s
    env.close()
    rm, r1, mr = (f"{out[f'{c}_s_per_frame'] * 1e6:5.0f} us ({out[f'{c}_10hz_over_physics']:.2f})"
                  for c, _ in CAMERAS)
    print(f"{robot} {trail:9s} N={n:4d}: physics {physics_s * 1e6:4.0f} us/step; per frame "
          f"(x physics at 10 Hz): raymarch {rm}, 1 thread {r1}, multiray {mr}; median err "
          f"{out['median_err_m'] * 1e3:.4f} mm, {out['within_5cm']:.2%} within 5 cm")
    return out


# (label, HeightmapDepthCamera settings): the default first
SETTINGS = [
    ("default: step 1 cell, 2 bisections, 2-cell blocks", {}),
    ("step 2 cells", {"samples": 2}),
    ("step 1/2 cell", {"samples": 8}),
    ("1 bisection", {"bisections": 1}),
    ("0 bisections (secant only)", {"bisections": 0}),
    ("4-cell blocks (step 1 cell)", {"block": 4, "samples": 8}),
    ("4-cell blocks, step 2 cells", {"block": 4, "samples": 4}),
]


def tradeoff(robot: str, args: argparse.Namespace) -> list[dict]:
    """Each setting of the march on one map of every category, against multiray."""
    from legoh.envs.heightmap_depth import HeightmapDepthCamera
    from legoh.envs.terrain import ALL_CATEGORIES

    cfg = compose_config(f"robot={robot}", "trail=flat", "trail.levels=2", "trail.variants=1",
                         f"trail.categories=[{','.join(ALL_CATEGORIES)}]",
                         "env.curriculum.enabled=false")
    env = HikingEnv(OmegaConf.to_object(cfg.robot), OmegaConf.to_object(cfg.trail),
                    OmegaConf.to_object(cfg.env), OmegaConf.to_object(cfg.sim), 1, seed=0)
    n = 14 * 12  # 12 cameras a tile
    pos, mat = standing_cameras(env, n)
    d, fovy = cfg.env.depth, cfg.robot.camera.fovy_deg
    ref = np.asarray(env.sim.make_depth_camera(fovy, d.width, d.height, d.far,
                                               "multiray").render(pos, mat))
    cams = {label: HeightmapDepthCamera(env.scene.model, fovy, d.width, d.height, d.far,
                                        **kw) for label, kw in SETTINGS}
    frames = {label: [] for label in cams}
    for _ in range(args.rounds):
        for label, cam in cams.items():
            frames[label].append(frame_cost(cam, pos, mat, args.reps))
    rows = []
    for label, cam in cams.items():
        got = np.asarray(cam.render(pos, mat), dtype=np.float64)
        seen = (ref < d.far) | (got < d.far)
        err = np.abs(got - ref)[seen]
        rows.append({"robot": robot, "setting": label, "s_per_frame": float(np.median(
            frames[label])), "median_err_m": float(np.median(err)),
            "within_1cm": float(np.mean(err <= 0.01)), "within_5cm": float(np.mean(err <= WITHIN))})
        print(f"{robot} {label:50s} {rows[-1]['s_per_frame'] * 1e6:5.0f} us/frame  "
              f"{rows[-1]['within_1cm']:.2%} within 1 cm, {rows[-1]['within_5cm']:.2%} within 5 cm")
    env.close()
    return rows


def load() -> dict:
    """How busy the machine was: the 1-minute load average."""
    return {"loadavg_1min": os.getloadavg()[0]}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--quick", action="store_true", help="N=64, H1, RandomMix only")
    parser.add_argument("--env", action="store_true", help="also HikingEnv rates with depth")
    parser.add_argument("--tradeoff", action="store_true",
                        help="also the march's settings: speed against accuracy")
    parser.add_argument("--robots", nargs="+", default=["h1", "g1"])
    parser.add_argument("--trails", nargs="+", default=["randommix", "forest"])
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 256])
    parser.add_argument("--reps", type=int, default=3, help="timed frames per round")
    parser.add_argument("--rounds", type=int, default=3, help="interleaved timing rounds")
    parser.add_argument("--physics-steps", type=int, default=20, help="per round")


def kind(args: argparse.Namespace) -> str:
    return "quick" if args.quick else ""


def measure(args: argparse.Namespace) -> dict:
    """The rows (robot x trail x N) and, with ``--tradeoff``, the march's settings."""
    if args.quick:
        args.robots, args.trails, args.sizes = ["h1"], ["randommix"], [64]
    before = load()
    rows = [row(r, t, n, args) for r in args.robots for t in args.trails for n in args.sizes]
    settings = [x for r in args.robots for x in tradeoff(r, args)] if args.tradeoff else []
    return {"load_before": before, "load_after": load(), "rows": rows, "tradeoff": settings}


def summary(run: dict) -> str:
    return "raymarch@10Hz / physics: " + ", ".join(
        f"{r['robot']} {r['trail']} N={r['num_envs']} {r['raymarch_10hz_over_physics']:.2f}"
        for r in run["results"]["rows"])


def markdown(run: dict) -> str:
    result = run["results"]
    threads = run["conditions"].get("torch_threads", 1)
    lines = [
        f"Torch on {threads} thread(s) (training runs one). One 32 x 24 frame for all N "
        "cameras (robots standing along the expert paths of every tile, all levels); "
        "physics: `mujoco.rollout` of the same model, N, 4 substeps and threads "
        "(microseconds per env per policy step). Cameras "
        "(microseconds per env per frame): raymarch on the physics threads (the env's), on "
        "one thread, and multiray (`mj_multiRay` on the physics threads). Depth at 10 Hz / "
        "physics = (frame cost / 5) / physics step; timings are medians of interleaved "
        "rounds. Parity: raymarch against multiray on the same cameras, over the pixels where "
        "either sees a surface. 1-minute load average before / after: "
        f"{result['load_before']['loadavg_1min']:.2f} / "
        f"{result['load_after']['loadavg_1min']:.2f} (other work on the same cores shows "
        "there: compare within a row).", "",
        "| robot | trail | N | physics us/step | raymarch us/frame | raymarch, 1 thread | "
        "multiray us/frame | raymarch@10Hz / physics | 1 thread | multiray@10Hz / physics | "
        "multiray / raymarch | median err mm | within 5 cm |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in result["rows"]:
        lines.append(
            f"| {r['robot']} | {r['trail']} | {r['num_envs']} | "
            f"{r['physics_s_per_step'] * 1e6:.0f} | {r['raymarch_s_per_frame'] * 1e6:.0f} | "
            f"{r['raymarch_1thread_s_per_frame'] * 1e6:.0f} | "
            f"{r['multiray_s_per_frame'] * 1e6:.0f} | {r['raymarch_10hz_over_physics']:.2f} | "
            f"{r['raymarch_1thread_10hz_over_physics']:.2f} | "
            f"{r['multiray_10hz_over_physics']:.2f} | {r['multiray_over_raymarch']:.1f} | "
            f"{r['median_err_m'] * 1e3:.4f} | {r['within_5cm']:.2%} |")
    env_rows = [r for r in result["rows"] if "env_raymarch_steps_per_s" in r]
    if env_rows:
        lines += ["", "HikingEnv with depth on (random actions, level 2), steps/s and share of "
                  "the ceiling:", "",
                  "| robot | trail | N | ceiling | env + raymarch | / ceiling | "
                  "env + multiray | / ceiling |", "|---|---|---|---|---|---|---|---|"]
        for r in env_rows:
            lines.append(
                f"| {r['robot']} | {r['trail']} | {r['num_envs']} | "
                f"{r['ceiling_steps_per_s']:.0f} | {r['env_raymarch_steps_per_s']:.0f} | "
                f"{r['env_raymarch_over_ceiling']:.0%} | {r['env_multiray_steps_per_s']:.0f} "
                f"| {r['env_multiray_over_ceiling']:.0%} |")
    if result["tradeoff"]:
        lines += ["", "The march's settings on a map of every category (2 levels, 1 variant; "
                  "12 standing cameras a tile), one thread; errors against multiray over the "
                  "pixels where either sees a surface:", "",
                  "| robot | setting | us/frame | median err mm | within 1 cm | within 5 cm |",
                  "|---|---|---|---|---|---|"]
        for r in result["tradeoff"]:
            lines.append(f"| {r['robot']} | {r['setting']} | {r['s_per_frame'] * 1e6:.0f} | "
                         f"{r['median_err_m'] * 1e3:.4f} | {r['within_1cm']:.2%} | "
                         f"{r['within_5cm']:.2%} |")
    return "\n".join(lines) + "\n"
