"""HikingEnv speed against the raw physics ceiling and two peers, in one run.

For H1 and G1 on RandomMix level 2 and N in {16, 64, 256}:
  * ceiling: ``mujoco.rollout`` of the same model, same N, same substeps, same threads,
    holding the default pose (no observations, rewards or resets);
  * HikingEnv without depth and with depth (10 Hz: a frame every 5 policy steps), random
    actions through the public ``env.step`` / ``step_and_maybe_reset`` path;
  * HikingEnv with ``env.compile=true``, random actions and holding the default pose (the
    ceiling's own motion);
  * depth cost: the env's camera (``env.depth.backend``; the ``raycast`` keys are its cost,
    `bench.py depth` compares the backends) vs MuJoCo's EGL renderer, per frame;
  * peers: gymnasium's Humanoid-v5 and torchrl's ``HumanoidEnv`` (MuJoCo C backend), one env.

With ``--backend warp`` (or ``both``: the CPU rows above, then these, in one run), MuJoCo
Warp on ``--device`` for N in ``--sizes`` (default 1024, 4096, 8192 on a GPU):
  * ceiling: ``WarpSim.step`` of the same scene (4 substeps, one CUDA graph), default pose;
  * depth: one 32 x 24 frame for all N cameras by Warp's batched ray cast, and the policy
    rate with a frame every 5 steps;
  * HikingEnv on the Warp backend, without and with depth, where the env supports it
    (``sim=warp``; n/a before the backend factory ``legoh.envs.physics`` exists).

    python experiments/bench.py env [--quick] [--backend mujoco|warp|both] [--device cuda]
                                    [--sizes 1024 4096 8192]

Adds a run to experiments/results/bench_env.{json,md} (a Warp-only run is of kind
"warp <device>", a ``--quick`` one of kind "quick": each keeps its own newest table).
Absolute numbers depend on the machine; the ratios in the same run are the figures to read.
"""

from __future__ import annotations

import argparse
import time

import mujoco
import numpy as np
import torch
from mujoco import rollout
from omegaconf import OmegaConf

from legoh.config.compose import compose_config
from legoh.envs.hiking_env import make_env
from legoh.envs.robots import CAMERA_NAME

RESULTS = "bench_env"
TITLE = "HikingEnv speed (policy steps/s, 50 Hz policy, 4 substeps)"
TORCH_THREADS = None  # torch's default
LEVEL = 2


def compose_cfg(robot: str, depth: bool, extra: list[str] | None = None):
    """The benchmark's config: ``robot`` on RandomMix, curriculum off, depth on or off."""
    return compose_config(f"robot={robot}", "trail=randommix",
                          f"env.depth.enabled={str(depth).lower()}",
                          "env.curriculum.enabled=false", *(extra or []))


def env_rate(robot: str, n: int, depth: bool, steps: int, scene=None,
             extra: list[str] | None = None, hold: bool = False) -> tuple[float, object]:
    """Policy steps/s of HikingEnv at level 2 with random actions (resets included), or
    (``hold``) zero actions: the default pose held, the ceiling's own motion. The env's
    ``compile_s``: seconds of its first reset and step (``env.compile``'s graphs)."""
    extra = list(extra or [])
    if not any(e.startswith("env.compile=") for e in extra):
        extra.append("env.compile=false")  # the eager env unless a row asks otherwise
    cfg = compose_cfg(robot, depth, extra)
    if scene is None:
        env = make_env(cfg, num_envs=n)
    else:
        from legoh.envs.hiking_env import HikingEnv
        env = HikingEnv(OmegaConf.to_object(cfg.robot), OmegaConf.to_object(cfg.trail),
                        OmegaConf.to_object(cfg.env), OmegaConf.to_object(cfg.sim), n, seed=0,
                        scene=scene)
    env.set_level(LEVEL)
    t0 = time.perf_counter()
    td = env.reset()
    gen = torch.Generator().manual_seed(0)
    timer = PhysicsTimer.attach(env)
    for i in range(steps + 5):
        if i == 1:
            env.compile_s = time.perf_counter() - t0
        if i == 5:
            t0, timer.seconds = time.perf_counter(), 0.0
        noise = 0.0 if hold else 0.5
        td["action"] = (torch.randn(n, env.num_actions, generator=gen) * noise).to(env.device)
        _, td = env.step_and_maybe_reset(td)
    wall = time.perf_counter() - t0
    env.physics_share = timer.seconds / wall  # read by cpu_benchmark
    env.outside_ms = 1e3 * (wall - timer.seconds) / steps
    return n * steps / wall, env


class PhysicsTimer:
    """Times the env's own ``mujoco.rollout`` calls: the share of an env step that is its
    physics, on the motion the env really steps. The ceiling's robots hold the default pose
    from their spawn (few contacts), the env's thrash under random actions and fall (more),
    so env / ceiling also counts a costlier physics, not only the work around it."""

    def __init__(self, pool) -> None:
        self.pool, self.seconds = pool, 0.0

    @classmethod
    def attach(cls, env) -> PhysicsTimer:
        timer = cls(env.sim._pool)
        env.sim._pool = timer
        return timer

    def rollout(self, *args, **kwargs):
        t0 = time.perf_counter()
        out = self.pool.rollout(*args, **kwargs)
        self.seconds += time.perf_counter() - t0
        return out

    def close(self) -> None:
        self.pool.close()


def ceiling_rate(env, steps: int) -> float:
    """mujoco.rollout of the same model, N, substeps and threads: the physics alone."""
    sim = env.sim
    n = env.num_envs
    pool = rollout.Rollout(nthread=sim.threads)
    datas = [mujoco.MjData(env.scene.model) for _ in range(sim.threads)]
    state0 = sim.state.copy()
    control = np.tile(env.ctrl.cpu().numpy()[:, None], (1, sim.substeps, 1))
    out = np.zeros((n, sim.substeps, state0.shape[1]))
    sens = np.zeros((n, sim.substeps, env.scene.model.nsensordata))
    state = state0.copy()
    t0 = time.perf_counter()
    for _ in range(steps):
        pool.rollout([env.scene.model] * n, datas, state, control, nstep=sim.substeps, state=out,
                     sensordata=sens, skip_checks=True)
        state[:] = out[:, -1]
    rate = n * steps / (time.perf_counter() - t0)
    pool.close()
    return rate


def depth_cost(env, frames: int, egl_frames: int = 4) -> dict[str, float]:
    """Seconds per depth frame per env: ray casting (the env's) vs the EGL renderer."""
    n = env.num_envs
    ids = torch.arange(n)
    t0 = time.perf_counter()
    for _ in range(frames):
        env.depth.render(env, ids)
    ray = (time.perf_counter() - t0) / (frames * n)

    model = env.scene.model
    d = env.cfg.depth
    data = mujoco.MjData(model)
    egl = float("nan")
    try:
        # The renderer draws the whole height field every frame (millions of triangles on a
        # trail map), so a few frames are enough to time it.
        with mujoco.Renderer(model, height=d.height, width=d.width) as renderer:
            renderer.enable_depth_rendering()
            count = min(n, egl_frames)
            if count == 0:
                raise RuntimeError("not asked for")
            t0 = time.perf_counter()
            for i in range(count):
                data.qpos[:] = env.sim.qpos[i].cpu().numpy()
                mujoco.mj_kinematics(model, data)
                mujoco.mj_camlight(model, data)
                renderer.update_scene(data, camera=CAMERA_NAME)
                renderer.render()
            egl = (time.perf_counter() - t0) / count
    except Exception as err:  # no EGL on this machine: report, do not fail the benchmark
        if egl_frames:
            print(f"  EGL renderer unavailable: {err}")
    return {"raycast_s_per_frame": ray, "egl_s_per_frame": egl}


def gymnasium_rate(steps: int) -> float | None:
    try:
        import gymnasium as gym

        env = gym.make("Humanoid-v5")
    except Exception as err:
        print(f"  gymnasium Humanoid-v5 unavailable: {err}")
        return None
    env.reset(seed=0)
    t0 = time.perf_counter()
    for _ in range(steps):
        _, _, term, trunc, _ = env.step(env.action_space.sample())
        if term or trunc:
            env.reset()
    rate = steps / (time.perf_counter() - t0)
    env.close()
    return rate


def torchrl_humanoid_rate(steps: int) -> float | None:
    try:
        from torchrl.envs.custom.mujoco import HumanoidEnv

        env = HumanoidEnv(backend="mujoco")
    except Exception as err:
        print(f"  torchrl HumanoidEnv unavailable: {err}")
        return None
    td = env.reset()
    t0 = time.perf_counter()
    for _ in range(steps):
        td = env.rand_action(td)
        _, td = env.step_and_maybe_reset(td)
    rate = steps / (time.perf_counter() - t0)
    env.close()
    return rate


def warp_rows(args: argparse.Namespace) -> list[dict]:
    """MuJoCo Warp: physics ceiling, depth cost and (where supported) HikingEnv rates."""
    from benches.warp_chunks import warp_physics
    from legoh.envs.scene import build_scene
    from legoh.envs.terrain import build_terrain_map

    rows = []
    for robot in args.robots:
        cfg = compose_cfg(robot, False, ["sim=warp"])
        scene = build_scene(OmegaConf.to_object(cfg.robot),
                            build_terrain_map(OmegaConf.to_object(cfg.trail), cfg.seed),
                            cfg.sim.dt, hfield_chunk=cfg.sim.hfield_chunk)
        for n in args.sizes:
            w = warp_physics(scene, n, args.warp_steps, args.device, nconmax=cfg.sim.nconmax,
                             njmax=cfg.sim.njmax, graph=cfg.sim.graph)
            step_s = 1.0 / w["steps_per_s"]  # per world per policy step
            row = {"robot": robot, "num_envs": n, "device": args.device,
                   "chunk_m": cfg.sim.hfield_chunk, "setup_s": w["setup_s"],
                   "ceiling_steps_per_s": w["steps_per_s"],
                   "depth_s_per_frame": w["depth_s_per_frame"],
                   "ceiling_depth_10hz_steps_per_s": 1.0 / (
                       step_s + w["depth_s_per_frame"] / n / 5),
                   "overflow_worlds": w["overflow_worlds"], "env_steps_per_s": None,
                   "env_depth_steps_per_s": None}
            extra = ["sim=warp", f"sim.warp_device={args.device}"]
            row["env_steps_per_s"] = env_rate(robot, n, False, args.warp_steps, extra=extra)[0]
            row["env_depth_steps_per_s"] = env_rate(robot, n, True, args.warp_steps,
                                                    extra=extra)[0]
            rows.append(row)

            def fmt(x: float | None) -> str:
                return "n/a" if x is None else f"{x:.0f}"

            print(f"warp {robot} N={n:5d}: ceiling {row['ceiling_steps_per_s']:9.0f}  "
                  f"+depth@10Hz {row['ceiling_depth_10hz_steps_per_s']:9.0f}  env "
                  f"{fmt(row['env_steps_per_s'])}  env+depth {fmt(row['env_depth_steps_per_s'])}"
                  f"  (setup {row['setup_s']:.1f} s, overflow worlds {row['overflow_worlds']})")
    return rows


def _fmt(x: float | None) -> str:
    return "n/a" if x is None else f"{x:.0f}"


def warp_markdown(result: dict) -> list[str]:
    """The Warp rows' table (``result["warp_rows"]``)."""
    rows = result["warp_rows"]
    lines = ["MuJoCo Warp speed (policy steps/s, 50 Hz policy, 4 substeps), device "
             f"`{result['warp_device']}`, RandomMix level map, default pose. Ceiling: "
             "`WarpSim.step` alone; depth: one 32x24 ray-cast frame per world every 5 policy "
             "steps; env: HikingEnv with `sim=warp` (the same term tables as the CPU rows, in "
             "the same run with `--backend both`).", "",
             "| robot | N | chunk m | ceiling | ceiling + depth | env | env + depth | "
             "depth ms/frame (all N) | overflow worlds |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['robot']} | {r['num_envs']} | {r['chunk_m']:g} | "
                     f"{r['ceiling_steps_per_s']:.0f} | {r['ceiling_depth_10hz_steps_per_s']:.0f}"
                     f" | {_fmt(r['env_steps_per_s'])} | {_fmt(r['env_depth_steps_per_s'])} | "
                     f"{r['depth_s_per_frame'] * 1e3:.1f} | {r['overflow_worlds']} |")
    return lines


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--quick", action="store_true", help="N=16 only, fewer steps")
    parser.add_argument("--backend", choices=["mujoco", "warp", "both"], default="mujoco")
    parser.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu",
                        help="Warp device: cuda | cuda:N | cpu")
    parser.add_argument("--sizes", type=int, nargs="+", default=None,
                        help="Warp world counts (default 1024 4096 8192; 8 on the CPU)")
    parser.add_argument("--robots", nargs="+", default=["h1"], help="Warp rows' robots")
    parser.add_argument("--warp-steps", type=int, default=50, help="timed Warp policy steps")


def kind(args: argparse.Namespace) -> str:
    if args.backend == "warp":
        return f"warp {args.device}"
    return "quick" if args.quick else ""


def measure(args: argparse.Namespace) -> dict:
    """The CPU rows (``--backend mujoco``), the Warp rows (``warp``) or both."""
    if args.sizes is None:
        args.sizes = [1024, 4096, 8192] if args.device.startswith("cuda") else [8]
    result = {}
    if args.backend in ("mujoco", "both"):
        result.update(cpu_benchmark(args))
    if args.backend in ("warp", "both"):
        result.update(warp_rows=warp_rows(args), warp_device=args.device)
    return result


def cpu_benchmark(args: argparse.Namespace) -> dict:
    """The CPU rows, the depth costs and the peers."""
    sizes = [16] if args.quick else [16, 64, 256]
    rows = []
    for robot in ["h1", "g1"]:
        for n in sizes:
            steps = max(10, (400 if not args.quick else 100) // max(1, n // 16))
            rate_env, env = env_rate(robot, n, depth=False, steps=steps)
            rate_ceiling = ceiling_rate(env, steps)
            env.close()
            # env.compile: the step's and the reset's derivations as one graph each
            rate_comp, cenv = env_rate(robot, n, False, steps, scene=env.scene,
                                       extra=["env.compile=true"])
            cenv.close()
            rate_hold, henv = env_rate(robot, n, False, steps, scene=env.scene,
                                       extra=["env.compile=true"], hold=True)
            henv.close()
            rate_depth, denv = env_rate(robot, n, depth=True, steps=steps,
                                        scene=env.scene)
            cost = depth_cost(denv, frames=3)
            denv.close()
            if n == 64:  # what resolution costs: the default and two larger images
                for w, h in [(48, 36), (64, 48)]:
                    _, big = env_rate(robot, n, depth=True, steps=1, scene=env.scene,
                                      extra=[f"env.depth.width={w}", f"env.depth.height={h}"])
                    cost[f"raycast_s_per_frame_{w}x{h}"] = depth_cost(big, 3, 0)[
                        "raycast_s_per_frame"]
                    big.close()
            physics_s = 1.0 / rate_ceiling  # per env per policy step
            depth_s = cost["raycast_s_per_frame"] / denv.cfg.depth.every
            row = {
                "robot": robot, "num_envs": n, "threads": env.sim.threads,
                "ceiling_steps_per_s": rate_ceiling, "env_steps_per_s": rate_env,
                "env_depth_steps_per_s": rate_depth,
                "env_over_ceiling": rate_env / rate_ceiling,
                "env_physics_share": env.physics_share, "env_outside_ms": env.outside_ms,
                "compiled_steps_per_s": rate_comp,
                "compiled_over_ceiling": rate_comp / rate_ceiling,
                "compiled_outside_ms": cenv.outside_ms, "compile_s": cenv.compile_s,
                "compiled_hold_steps_per_s": rate_hold,
                "compiled_hold_over_ceiling": rate_hold / rate_ceiling,
                "compiled_hold_outside_ms": henv.outside_ms,
                "depth_env_over_ceiling": rate_depth / rate_ceiling,
                "depth_10hz_over_physics": depth_s / physics_s,
                **cost,
                "egl_over_raycast": cost["egl_s_per_frame"] / cost["raycast_s_per_frame"],
            }
            rows.append(row)
            print(f"{robot} N={n:4d}: ceiling {rate_ceiling:8.0f}  env {rate_env:8.0f} "
                  f"({row['env_over_ceiling']:.0%}; its physics {env.physics_share:.0%}, "
                  f"{env.outside_ms:.1f} ms a step outside)  compiled {rate_comp:8.0f} "
                  f"({row['compiled_over_ceiling']:.0%}, {cenv.outside_ms:.1f} ms; "
                  f"holding the pose {row['compiled_hold_over_ceiling']:.0%}, "
                  f"compiling {cenv.compile_s:.0f} s)  env+depth {rate_depth:8.0f} "
                  f"({row['depth_env_over_ceiling']:.0%})  depth@10Hz/physics "
                  f"{row['depth_10hz_over_physics']:.2f}  EGL/raycast "
                  f"{row['egl_over_raycast']:.2f}")
    peer_steps = 300 if args.quick else 1000
    peers = {"gymnasium_humanoid_v5_steps_per_s": gymnasium_rate(peer_steps),
             "torchrl_humanoid_c_steps_per_s": torchrl_humanoid_rate(peer_steps)}
    print(peers)
    return {"level": LEVEL, "trail": "randommix", "rows": rows, "peers": peers,
            "depth_backend": compose_cfg("h1", True).env.depth.backend.value}


def summary(run: dict) -> str:
    result = run["results"]
    rows = [(r["robot"], r["num_envs"], r["env_steps_per_s"], r["env_over_ceiling"])
            for r in result.get("rows", [])]
    rows += [(r["robot"], r["num_envs"], r["env_steps_per_s"], None)
             for r in result.get("warp_rows", [])]
    return "env steps/s " + ", ".join(
        f"{robot} N={n} {_fmt(rate)}" + (f" ({ratio:.0%} of the ceiling)" if ratio else "")
        for robot, n, rate, ratio in rows)


def markdown(run: dict) -> str:
    result = run["results"]
    lines = cpu_markdown(result) if "rows" in result else []
    if "warp_rows" in result:
        lines += ["", *warp_markdown(result)] if lines else warp_markdown(result)
    return "\n".join(lines) + "\n"


def cpu_markdown(result: dict) -> list[str]:
    """The CPU rows' tables, the depth costs and the peers."""
    lines = [
        f"RandomMix level {result['level']}. Ceiling: `mujoco.rollout` of the same model, "
        "N, substeps and threads, from the env's spawn state holding the default pose. "
        "Env physics: the share of the env's step spent in its own `mujoco.rollout` call, "
        "on the motion it steps (random actions: robots thrash and fall, more contacts than "
        "the ceiling's standing robots), and the milliseconds a step spends outside it. "
        "Depth: 32 x 24 frame of the env's camera "
        f"(env.depth.backend={result.get('depth_backend', 'multiray')}) every 5 policy steps "
        "(the default).", "",
        "| robot | N | ceiling | env | env / ceiling | env physics | outside (ms/step) "
        "| env + depth | (env+depth) / ceiling | depth@10Hz / physics "
        "| EGL / ray cast (per frame) |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in result["rows"]:
        lines.append(
            f"| {r['robot']} | {r['num_envs']} | {r['ceiling_steps_per_s']:.0f} | "
            f"{r['env_steps_per_s']:.0f} | {r['env_over_ceiling']:.0%} | "
            f"{r.get('env_physics_share', float('nan')):.0%} | "
            f"{r.get('env_outside_ms', float('nan')):.1f} | "
            f"{r['env_depth_steps_per_s']:.0f} | {r['depth_env_over_ceiling']:.0%} | "
            f"{r['depth_10hz_over_physics']:.2f} | {r['egl_over_raycast']:.2f} |")
    if any("compiled_steps_per_s" in r for r in result["rows"]):
        lines += ["", "With `env.compile=true` (a step's and a reset's derivations from the "
                  "physics as one torch.compile graph each; the eager env above). Random "
                  "actions as above, and holding the default pose (zero actions: the "
                  "ceiling's own motion, so env / ceiling counts only the work around the "
                  "physics). Compiling: seconds of the first reset and step (the inductor's "
                  "cache, warm or cold, decides most of it).", "",
                  "| robot | N | ceiling | compiled env | / ceiling | outside (ms/step) "
                  "| holding the pose | / ceiling | outside (ms/step) | compiling (s) |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
        for r in result["rows"]:
            if "compiled_steps_per_s" in r:
                lines.append(
                    f"| {r['robot']} | {r['num_envs']} | {r['ceiling_steps_per_s']:.0f} | "
                    f"{r['compiled_steps_per_s']:.0f} | {r['compiled_over_ceiling']:.0%} | "
                    f"{r['compiled_outside_ms']:.1f} | {r['compiled_hold_steps_per_s']:.0f} | "
                    f"{r['compiled_hold_over_ceiling']:.0%} | "
                    f"{r['compiled_hold_outside_ms']:.1f} | {r['compile_s']:.0f} |")
    lines += ["", "Depth cost by resolution at N=64 (ray cast, seconds per frame per env; "
              "physics: seconds per policy step per env from the ceiling):", "",
              "| robot | 32x24 | 48x36 | 64x48 | physics per step |", "|---|---|---|---|---|"]
    for r in result["rows"]:
        if "raycast_s_per_frame_64x48" in r:
            lines.append(f"| {r['robot']} | {r['raycast_s_per_frame'] * 1e3:.2f} ms | "
                         f"{r['raycast_s_per_frame_48x36'] * 1e3:.2f} ms | "
                         f"{r['raycast_s_per_frame_64x48'] * 1e3:.2f} ms | "
                         f"{1e3 / r['ceiling_steps_per_s']:.3f} ms |")
    p = result["peers"]
    lines += ["", "Peers (one env, their own models and frame skips: gymnasium Humanoid-v5 "
              "steps 5 substeps of 3 ms, torchrl HumanoidEnv its own):", "",
              f"* gymnasium Humanoid-v5: {_fmt(p['gymnasium_humanoid_v5_steps_per_s'])} steps/s",
              f"* torchrl HumanoidEnv (MuJoCo C backend): "
              f"{_fmt(p['torchrl_humanoid_c_steps_per_s'])} steps/s"]
    return lines
