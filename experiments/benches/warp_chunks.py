"""Height-field chunk size per physics backend, measured: step and depth cost on the full map.

The terrain is a grid of square height-field chunks (``sim.hfield_chunk``). Small chunks
keep MuJoCo's CPU ray casts cheap (docs/env.md); MuJoCo Warp's broadphase tests every robot
geom against every chunk, so its step grows with their number. For H1 on the full RandomMix
map, N worlds standing at N tile starts, each chunk size gets: policy steps/s of the Warp
step (4 substeps), seconds per depth frame of N cameras (Warp ray cast), and the same two on
the CPU backend (``mujoco.rollout``, ``DepthRaycaster``) for reference.

    python experiments/bench.py warp-chunks [--device cpu|cuda] [--num-envs 8] [--steps 20]

Adds a run to experiments/results/bench_warp_chunks.{json,md} (of kind ``<device>``).
"""

from __future__ import annotations

import argparse
import os
import time

import mujoco
import numpy as np
import torch
from mujoco import rollout
from omegaconf import OmegaConf

from legoh.config.compose import compose_config
from legoh.envs.randomization import PhysicsDraw
from legoh.envs.scene import Scene, build_scene
from legoh.envs.sensors import DepthRaycaster, camera_poses
from legoh.envs.terrain import build_terrain_map
from legoh.envs.warp_sim import WarpSim

RESULTS = "bench_warp_chunks"
TITLE = "Height-field chunk size: H1 on the full RandomMix map"
TORCH_THREADS = None  # torch's default
SINGLE = 1e4  # m: a chunk larger than any map, i.e. one height field
FOVY, WIDTH, HEIGHT, FAR = 87.0, 32, 24, 3.0  # the H1 camera's defaults (conf/robot/h1.yaml)


def spawn(scene: Scene, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(qpos, ctrl): the default pose at the starts of n tiles, 2 cm above the ground."""
    tiles = scene.terrain.tiles
    starts = np.array([tiles[i * len(tiles) // n].start for i in range(n)])
    qpos = np.tile(scene.model.qpos0, (n, 1))
    qpos[:, :2] = starts[:, :2]
    qpos[:, 2] = scene.terrain.height_at(starts[:, :2]) + scene.stand_height + 0.02
    qpos[:, scene.qpos_adr] = scene.robot.default_pose
    return qpos, np.tile(scene.robot.default_pose, (n, 1))


def timed(fn, repeats: int) -> float:
    """Seconds per call, after one warm-up call."""
    fn()
    t0 = time.perf_counter()
    for _ in range(repeats):
        fn()
    return (time.perf_counter() - t0) / repeats


def warp_physics(scene: Scene, n: int, steps: int, device: str, **warp_options: object
                 ) -> dict:
    """MuJoCo Warp alone: set-up seconds (build, first step and its graph capture), policy
    steps/s of ``WarpSim.step`` holding the default pose, seconds per depth frame of all n
    cameras, and how many worlds overflowed their contact capacity."""
    model = scene.model
    qpos, ctrl = spawn(scene, n)
    draws = PhysicsDraw(np.ones(1), np.zeros(1), np.zeros((1, 3)), np.ones(1))
    t0 = time.perf_counter()
    sim = WarpSim(model, scene.robot.base_body, draws, n, 4, device=device, **warp_options)
    sim.reset_envs(torch.arange(n), torch.as_tensor(qpos), torch.zeros(n, model.nv),
                   torch.as_tensor(ctrl))
    u = torch.as_tensor(ctrl, dtype=torch.float32, device=sim.device)
    sync = torch.cuda.synchronize if sim.device.type == "cuda" else (lambda: None)

    def step() -> None:
        sim.step(u)
        sync()

    step()
    setup_s = time.perf_counter() - t0
    step_s = timed(step, steps)
    cam = sim.make_depth_camera(FOVY, WIDTH, HEIGHT, FAR)
    pos, mat = (torch.as_tensor(x) for x in camera_poses(scene.model, qpos))

    def render() -> None:
        cam.render(pos, mat)
        sync()

    depth_s = timed(render, max(2, steps // 5))
    overflow = sim.check_overflow()
    sim.close()
    return {"setup_s": setup_s, "steps_per_s": n / step_s, "depth_s_per_frame": depth_s,
            "overflow_worlds": overflow}


def measure_scene(scene: Scene, n: int, steps: int, device: str, cpu: bool = True) -> dict:
    """Warp and (``cpu``) the CPU backend side by side on one scene."""
    warp = warp_physics(scene, n, steps, device)
    row = {"nhfield": int(scene.model.nhfield), "ngeom": int(scene.model.ngeom),
           "warp_steps_per_s": warp["steps_per_s"],
           "warp_depth_s_per_frame": warp["depth_s_per_frame"],
           "warp_overflow_worlds": warp["overflow_worlds"],
           "cpu_steps_per_s": float("nan"), "cpu_depth_s_per_frame": float("nan")}
    if cpu:
        row.update(cpu_backend(scene, n, steps))
    return row


def cpu_backend(scene: Scene, n: int, steps: int) -> dict:
    """The CPU backend on the same worlds: mujoco.rollout steps/s, DepthRaycaster frames."""
    model = scene.model
    qpos, ctrl = spawn(scene, n)
    cam_pos, cam_mat = camera_poses(scene.model, qpos)
    pool = rollout.Rollout(nthread=os.cpu_count() or 1)
    datas = [mujoco.MjData(model) for _ in range(os.cpu_count() or 1)]
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state = np.zeros((n, mujoco.mj_stateSize(model, spec)))
    d = mujoco.MjData(model)
    for i in range(n):
        d.qpos[:], d.ctrl[:] = qpos[i], ctrl[i]
        mujoco.mj_forward(model, d)
        mujoco.mj_getState(model, d, state[i], spec)
    control = np.repeat(ctrl[:, None], 4, 1)
    out = np.zeros((n, 4, state.shape[1]))
    sens = np.zeros((n, 4, model.nsensordata))

    def cpu_step() -> None:
        pool.rollout([model] * n, datas, state, control, nstep=4, state=out, sensordata=sens,
                     skip_checks=True)
        state[:] = out[:, -1]

    cpu_s = timed(cpu_step, steps)
    pool.close()
    caster = DepthRaycaster(model, FOVY, WIDTH, HEIGHT, FAR)
    cpu_depth_s = timed(lambda: caster.render(d, cam_pos, cam_mat), max(2, steps // 5))
    return {"cpu_steps_per_s": n / cpu_s, "cpu_depth_s_per_frame": cpu_depth_s}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--device", default="cpu", help="Warp device: cpu | cuda | cuda:N")
    parser.add_argument("--num-envs", type=int, default=8)
    parser.add_argument("--steps", type=int, default=20, help="timed policy steps per size")
    parser.add_argument("--chunks", type=float, nargs="+", default=[4.0, 8.0, 16.0, 32.0,
                                                                   SINGLE])
    parser.add_argument("--skip-cpu", action="store_true", help="Warp rows only (large N)")


def kind(args: argparse.Namespace) -> str:
    return args.device


def measure(args: argparse.Namespace) -> dict:
    """One row per chunk size."""
    cfg = compose_config("robot=h1", "trail=randommix")
    terrain = build_terrain_map(OmegaConf.to_object(cfg.trail), cfg.seed)
    rows = []
    for chunk in args.chunks:
        scene = build_scene(OmegaConf.to_object(cfg.robot), terrain, cfg.sim.dt,
                            hfield_chunk=chunk)
        row = {"chunk_m": chunk, **measure_scene(scene, args.num_envs, args.steps,
                                                 args.device, cpu=not args.skip_cpu)}
        rows.append(row)
        print(f"chunk {'single' if chunk >= SINGLE else f'{chunk:g} m':>7}: "
              f"{row['nhfield']:4d} fields  warp {row['warp_steps_per_s']:8.1f} steps/s, "
              f"depth {row['warp_depth_s_per_frame'] * 1e3:7.1f} ms/frame | cpu "
              f"{row['cpu_steps_per_s']:8.1f} steps/s, depth "
              f"{row['cpu_depth_s_per_frame'] * 1e3:7.1f} ms/frame")
    return {"device": args.device, "num_envs": args.num_envs, "rows": rows}


def summary(run: dict) -> str:
    best = max(run["results"]["rows"], key=lambda r: r["warp_steps_per_s"])
    name = "single" if best["chunk_m"] >= SINGLE else f"{best['chunk_m']:g} m"
    return f"fastest Warp step with {name} chunks: {best['warp_steps_per_s']:.0f} steps/s"


def markdown(run: dict) -> str:
    result = run["results"]
    lines = [f"{result['num_envs']} worlds; Warp device `{result['device']}`; CPU backend on "
             "the machine's cores. Policy steps/s (4 substeps); depth: one 32x24 frame for "
             "every world.", "",
             "| chunk | height fields | Warp steps/s | Warp depth ms | CPU steps/s "
             "| CPU depth ms |", "|---|---|---|---|---|---|"]
    for r in result["rows"]:
        name = "single" if r["chunk_m"] >= SINGLE else f"{r['chunk_m']:g} m"
        lines.append(f"| {name} | {r['nhfield']} | {r['warp_steps_per_s']:.1f} | "
                     f"{r['warp_depth_s_per_frame'] * 1e3:.1f} | {r['cpu_steps_per_s']:.1f} | "
                     f"{r['cpu_depth_s_per_frame'] * 1e3:.1f} |")
    return "\n".join(lines) + "\n"
