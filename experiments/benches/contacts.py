"""What the feet's colliders cost: contacts, narrow phase, env and oracle-loop frames/s.

For each robot and each ``robot.feet_collider`` (``source``: the MJCF's own colliders,
what checkpoints before 2026-12-05 trained on; ``spheres``; ``box``), in one run:
  * contacts: the robot's shipped oracle hikes RandomMix level 2 (N = 64, deterministic
    actions); sampled states are replayed one MjData at a time: contacts per foot on the
    ground (mean over feet touching it), and MuJoCo's own timers (``mjData.timer``) over the
    4 substeps from each state: microseconds a substep and the narrow-phase share;
  * env: HikingEnv policy steps/s at N in ``--sizes`` with random actions (the env
    benchmark's method) and the share of its step spent in its own physics, eager for each
    feet and with the default ``env.compile`` (null: compiled from 64 robots up) on the
    default feet;
  * loop: the oracle training loop's frames/s (the default config: warm-started from the
    shipped oracle, RandomMix, overlapped collection) at N in ``--sizes``: the old default
    (``source`` feet, eager), ``spheres`` eager, and the new default.
Rows run interleaved per size so that drift of the machine hits each alike; the ratios to
the old default in the same run are the figures to read (``loop_speedup``: N = 256).

    python experiments/bench.py contacts [--robots h1 g1] [--sizes 64 256] [--iterations 4]

Adds a run to experiments/results/bench_contacts.{md,json}.
"""

from __future__ import annotations

import argparse
import time

import mujoco
import numpy as np
import torch
from torchrl.envs.utils import ExplorationType, set_exploration_type

from benches.env import LEVEL, compose_cfg, env_rate
from benches.train import loop_rate
from legoh.config.compose import compose_config
from legoh.envs.hiking_env import make_env
from legoh.policies.oracle import load_oracle_actor

RESULTS = "bench_contacts"
TITLE = "Feet colliders: contacts, narrow phase, env and oracle-loop speed (one run)"
TORCH_THREADS = 1
FEET = ("source", "spheres", "box")
T = mujoco.mjtTimer


def contact_profile(robot: str, feet: str, n: int = 64, steps: int = 80,
                    samples: int = 8) -> dict[str, float]:
    """Contacts per foot and the substep's cost on the shipped oracle's hiking motion."""
    cfg = compose_cfg(robot, False, [f"robot.feet_collider={feet}"])
    env = make_env(cfg, num_envs=n)
    env.set_level(LEVEL)
    actor = load_oracle_actor(cfg, "pretrained", env)
    td = env.reset()
    states, ctrls = [], []
    every = max(1, (steps - 20) // samples)
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        for i in range(steps):
            td = actor(td)
            _, td = env.step_and_maybe_reset(td)
            if i >= 20 and (i - 20) % every == 0:  # past the spawn's settling
                states.append(env.sim.state.copy())
                ctrls.append(env.ctrl.numpy().copy())
    model, data = env.scene.model, mujoco.MjData(env.scene.model)
    feet_ids = [model.body(b).id for b in env.robot.feet_bodies]
    per_foot, touching = [], 0
    substeps = env.sim.substeps
    for state, ctrl in zip(states, ctrls, strict=True):
        for k in range(n):
            mujoco.mj_setState(model, data, state[k], mujoco.mjtState.mjSTATE_FULLPHYSICS)
            data.ctrl[:] = ctrl[k]
            mujoco.mj_forward(model, data)
            bodies = model.geom_bodyid[data.contact.geom[: data.ncon]]
            for foot in feet_ids:
                count = int((bodies == foot).any(axis=1).sum()) if data.ncon else 0
                if count:
                    per_foot.append(count)
    mujoco.mj_resetData(model, data)  # timers from zero: only the substeps below count
    for state, ctrl in zip(states, ctrls, strict=True):
        for k in range(n):
            mujoco.mj_setState(model, data, state[k], mujoco.mjtState.mjSTATE_FULLPHYSICS)
            data.ctrl[:] = ctrl[k]
            for _ in range(substeps):
                mujoco.mj_step(model, data)
    step_s = data.timer[T.mjTIMER_STEP].duration
    touching = len(per_foot) / (len(states) * n * len(feet_ids))
    env.close()
    return {"contacts_per_foot": float(np.mean(per_foot)) if per_foot else 0.0,
            "feet_touching": touching,
            "substep_us": 1e6 * step_s / data.timer[T.mjTIMER_STEP].number,
            "narrow_share": data.timer[T.mjTIMER_COL_NARROW].duration / step_s,
            "collision_share": (data.timer[T.mjTIMER_POS_COLLISION].duration / step_s)}


def env_speed(robot: str, feet: str, n: int, steps: int, compiled: str) -> dict[str, float]:
    rate, env = env_rate(robot, n, False, steps,
                         extra=[f"robot.feet_collider={feet}", f"env.compile={compiled}"])
    out = {"env": rate, "physics_share": env.physics_share, "outside_ms": env.outside_ms,
           "first_step_s": env.compile_s}
    env.close()
    return out


def loop_speed(robot: str, feet: str, n: int, iterations: int, compiled: str) -> float:
    cfg = compose_config(f"robot={robot}", f"algo.num_envs={n}", f"robot.feet_collider={feet}",
                         f"env.compile={compiled}", "video=false")
    return loop_rate(cfg, iterations)


# (label, feet, env.compile) of the speed rows; the first is the old default, the last the new
ROWS = [("source, eager (old default)", "source", "false"),
        ("spheres, eager", "spheres", "false"),
        ("box, eager", "box", "false"),
        ("spheres, compile=null (new default)", "spheres", "null")]
LOOPS = ("source, eager (old default)", "spheres, eager", "spheres, compile=null (new default)")


def summary(run: dict) -> str:
    speedup = run["results"]["loop_speedup"]
    return "loop speed-up at N = 256: " + ", ".join(f"{r} {v:.2f}" for r, v in speedup.items())


def markdown(run: dict) -> str:
    result = run["results"]
    lines = [
        "Contacts: the shipped oracle hiking RandomMix level 2 (N = 64), sampled states "
        "replayed one MjData at a time (MuJoCo's timers). Env: HikingEnv with random "
        "actions (the env benchmark's method), physics share = its own `mujoco.rollout` time over "
        "its step. Loop: the oracle's training loop, default config (warm start, RandomMix, "
        "overlapped collection), frames/s of its iterations after the first. Ratios are to "
        "the old default (`source` feet: the MJCF's colliders; eager env) in the same run. "
        "First step: seconds of the env's first reset and step (compiling, where it "
        "compiles).", "",
        "| robot | feet | contacts / foot | substep (us) | narrow phase | collision |",
        "|---|---|---|---|---|---|",
    ]
    for robot, by_feet in result["contacts"].items():
        for feet, c in by_feet.items():
            lines.append(f"| {robot} | {feet} | {c['contacts_per_foot']:.2f} | "
                         f"{c['substep_us']:.1f} | {100 * c['narrow_share']:.0f}% | "
                         f"{100 * c['collision_share']:.0f}% |")
    lines += ["", "| robot | N | row | env | / old | physics share | outside (ms/step) "
                  "| first step (s) | loop | / old |", "|---|---|---|---|---|---|---|---|---|---|"]
    for row in result["speed"]:
        loop = (f"{row['loop']:.0f} | {row['loop_ratio']:.2f}" if "loop" in row else "- | -")
        lines.append(f"| {row['robot']} | {row['n']} | {row['row']} | {row['env']:.0f} | "
                     f"{row['env_ratio']:.2f} | {100 * row['physics_share']:.0f}% | "
                     f"{row['outside_ms']:.1f} | {row['first_step_s']:.1f} | {loop} |")
    lines += ["", "loop_speedup (N = 256, new default over old): "
              + ", ".join(f"{r} {v:.2f}" for r, v in result["loop_speedup"].items())]
    lines += ["", *ceiling_lines(result["speed"])]
    return "\n".join(lines) + "\n"


def ceiling_lines(speed: list[dict]) -> list[str]:
    """What the loop could reach at N = 256: a loop runs no faster than its bare env, so
    the new bare env over the old loop bounds ``loop_speedup`` (reached only with an
    update that costs the collector nothing); and each loop's share of its bare env."""
    lines = []
    for robot in dict.fromkeys(r["robot"] for r in speed):
        rows = [r for r in speed if r["robot"] == robot and r["n"] == 256 and "loop" in r]
        if len(rows) < 2:
            continue
        old, new = rows[0], rows[-1]
        lines.append(f"- {robot}: the loop ran at {old['loop'] / old['env']:.2f} of its bare "
                     f"env (old) and {new['loop'] / new['env']:.2f} (new); the new bare env "
                     f"is {new['env'] / old['loop']:.2f}x the old loop, the most a loop on "
                     "it can gain, and only if the update cost the collector nothing (the "
                     "update shares the two cores; docs/env.md)")
    return ["Ceiling at N = 256 (from the rows above):", *lines] if lines else []


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--robots", nargs="+", default=["h1", "g1"])
    parser.add_argument("--feet", nargs="+", default=list(FEET))
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 256])
    parser.add_argument("--steps", type=int, default=100, help="env steps timed per row")
    parser.add_argument("--iterations", type=int, default=4, help="loop iterations per row")


def measure(args: argparse.Namespace) -> dict:
    """Contacts per robot and feet, then the speed rows interleaved per size."""
    default = compose_config().robot.feet_collider
    result = {"default_feet": str(default), "contacts": {}, "speed": []}
    for robot in args.robots:
        result["contacts"][robot] = {}
        for feet in args.feet:
            t0 = time.perf_counter()
            c = contact_profile(robot, feet)
            result["contacts"][robot][feet] = c
            print(f"{robot} {feet}: {c['contacts_per_foot']:.2f} contacts/foot, "
                  f"{c['substep_us']:.1f} us/substep, narrow {100 * c['narrow_share']:.0f}% "
                  f"({time.perf_counter() - t0:.0f} s)", flush=True)
    for robot in args.robots:
        for n in args.sizes:
            rows = []
            for label, feet, compiled in ROWS:
                if feet not in args.feet:
                    continue
                row = {"robot": robot, "n": n, "row": label, "feet": feet,
                       **env_speed(robot, feet, n, args.steps, compiled)}
                if label in LOOPS:
                    row["loop"] = loop_speed(robot, feet, n, args.iterations, compiled)
                rows.append(row)
                print(f"{robot} N={n} {label}: env {row['env']:.0f}/s (physics "
                      f"{100 * row['physics_share']:.0f}%), loop {row.get('loop', 0):.0f} "
                      "frames/s", flush=True)
            for row in rows:
                row["env_ratio"] = row["env"] / rows[0]["env"]
                if "loop" in row:
                    row["loop_ratio"] = row["loop"] / rows[0]["loop"]
            result["speed"] += rows
    result["loop_speedup"] = {r["robot"]: r["loop_ratio"] for r in result["speed"]
                              if r["n"] == 256 and r["row"] == ROWS[-1][0]}
    return result
