"""The stage-2 student loop beside the oracle loop: frames/s and where the student's time goes.

    python experiments/bench.py student [--sizes 64 256] [--iterations 4]
        [--variants "" "algo.update_precision=bfloat16 algo.distill_epochs=1 algo.epochs=3"]
        [--note "..."] [--tag compiled]

Per batch size N, in one run (these machines are noisy, so compare within a run):
  bare env:      HikingEnv.step_and_maybe_reset with random actions, depth off (the physics
                 and the term tables) and on (``env.depth.backend``'s frames at 10 Hz);
  oracle loop:   ``train_oracle`` (the default config, the shipped oracle's weights);
  student loop:  ``train_student`` with ``algo=unified`` (LEGO-H: TC-ViTs + GRU + HLM, the
                 shipped oracle teaching), frames/s of its iterations after the first, and
                 the split of an iteration from train.csv's ``time/*`` columns: collection
                 (env + depth + the student acting), the oracle's labels with the prior's
                 steps, PPO, the imitation losses; one row per ``--variants`` entry (Hydra
                 overrides of the student loop, "" the defaults);
  collection alone: the student loop's frames over its mean collection time (the env,
                 depth and the student acting; same run): what the loop would reach with a
                 free update, so no update can take it past this rate;
  update budget: the seconds an iteration leaves for the update at the target (its frames
                 at 2,500 frames/s minus its collection), beside the update's measured seconds;
  work bound:    the same student loop with one thread for everything (``algo.torch_threads=1
                 sim.threads=1``: the physics, depth and torch), times the CPUs: the rate the
                 loop's work allows with every core busy all the time. The student loop over
                 it is the loop's parallel efficiency; a target above it needs less work, not
                 better scheduling.
Adds a run to experiments/results/bench_student.{md,json}. The target (issue 20): the
student loop at >= 2,500 frames/s at N = 256 on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from benches.train import bare_rate
from legoh.config.compose import compose_config
from legoh.envs.hiking_env import make_env
from legoh.eval.curves import read_columns
from legoh.train.oracle import train_oracle
from legoh.train.unified import train_student

RESULTS = "bench_student"
TITLE = "Student loop vs oracle loop (frames/s, one run)"
TORCH_THREADS = 1
PARTS = ("collect", "prior", "ppo", "distill")  # the student's time columns (prior: the
# oracle's labels and the prior's steps, timed together by StudentDistillation.update)
TARGET = 2500.0
ONE_CORE = {"algo": {"torch_threads": 1}, "sim": {"threads": 1}}  # the work bound's loop


def loop(train, cfg, iterations: int) -> dict[str, float]:
    """frames/s of the loop's iterations after the first, and its mean ``time/*`` split."""
    frames = cfg.algo.num_envs * cfg.algo.steps_per_env
    with tempfile.TemporaryDirectory() as tmp:
        run_cfg = OmegaConf.merge(cfg, {"algo": {"total_frames": frames * iterations}})
        run = train(run_cfg, Path(tmp))
        cols = read_columns(run.csv)
    out = {"fps": float(np.mean(cols["frames_per_s"][1:]))}
    for part in PARTS:
        if f"time/{part}" in cols:
            out[f"s_{part}"] = float(np.mean(cols[f"time/{part}"][1:]))
    if "s_collect" in out:
        out["collect_fps"] = frames / out["s_collect"]
        out["update_s"] = sum(out.get(f"s_{p}", 0.0) for p in PARTS if p != "collect")
        out["budget_s"] = frames / TARGET - out["s_collect"]
    return out


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 256])
    parser.add_argument("--iterations", type=int, default=4)
    parser.add_argument("--variants", nargs="+", default=[""],
                        help="student loops to time, each a space-separated list of Hydra "
                             "overrides ('' = the defaults)")


def measure(args: argparse.Namespace) -> dict:
    """Per N: the bare env, the oracle loop, then each student loop variant."""
    rows = []
    for n in args.sizes:
        t0 = time.perf_counter()
        base = compose_config(f"algo.num_envs={n}")
        env = make_env(base, num_envs=n)
        bare = bare_rate(env, max(50, 6000 // n))
        env.close()
        student_cfg = compose_config("algo=unified", f"algo.num_envs={n}",
                                     "algo.prior_pretrain_frames=0")
        depth = OmegaConf.to_object(student_cfg.env.depth)
        depth.enabled = True
        env = make_env(base, num_envs=n, depth=depth)
        bare_depth = bare_rate(env, max(50, 6000 // n))
        env.close()
        oracle = loop(train_oracle, base, args.iterations)
        for variant in args.variants:
            cfg = compose_config("algo=unified", f"algo.num_envs={n}",
                                 "algo.prior_pretrain_frames=0", *variant.split())
            student = loop(train_student, cfg, args.iterations)
            one_core = loop(train_student, OmegaConf.merge(cfg, ONE_CORE), args.iterations)
            bound = (os.cpu_count() or 1) * one_core["fps"]
            total = sum(student.get(f"s_{p}", 0.0) for p in PARTS)
            row = {"N": n, "variant": variant or "defaults", "bare": bare, "bare_depth": bare_depth,
                   "depth_cost": bare / bare_depth - 1, "oracle_loop": oracle["fps"],
                   "student_loop": student["fps"],
                   "student_over_oracle": student["fps"] / oracle["fps"],
                   "collection_alone": student["collect_fps"],
                   "update_s": student["update_s"], "update_budget_s": student["budget_s"],
                   "one_core": one_core["fps"], "work_bound": bound,
                   "student_over_bound": student["fps"] / bound,
                   **{f"share_{p}": student.get(f"s_{p}", 0.0) / total for p in PARTS},
                   "depth_backend": str(depth.backend.value),
                   "wall_s": time.perf_counter() - t0}
            rows.append(row)
            print(json.dumps(row))
    return {"sizes": rows, "target_fps_at_256": TARGET}


def summary(run: dict) -> str:
    """The student loop's frames/s per N, one figure per variant."""
    by_n: dict[int, list[str]] = {}
    for r in run["results"]["sizes"]:
        by_n.setdefault(r["N"], []).append(f"{r['student_loop']:.0f}")
    return "student loop " + ", ".join(f"N={n} {' / '.join(v)}" for n, v in by_n.items()) + (
        " frames/s")


def markdown(run: dict) -> str:
    rows = run["results"]["sizes"]
    threads = run["conditions"].get("torch_threads", 1)
    lines = [f"{threads} torch thread(s). "
             f"Target (issue 20): the student loop >= {TARGET:.0f} frames/s at N = 256. Depth "
             "cost: the env step with depth frames over the one without, minus 1 (depth "
             "backend in its column). Student split: shares of one iteration. Collection "
             "alone: the student loop's frames over its collection seconds, the rate a free "
             "update would give. Update budget: the seconds an iteration's update may take "
             "at the target (frames / target - collection; negative: no update fits). Work "
             "bound: the same loop at one thread for everything (physics, depth, torch), "
             "times the CPUs: the most its work allows here; student / bound: its parallel "
             "efficiency.", "",
             "| N | student loop overrides | bare env | + depth | depth cost | oracle loop | "
             "student loop | student / oracle | collect | labels + prior | PPO | imitation | depth "
             "backend | collection alone | update (s) | update budget at the target (s) | "
             "one core | work bound | student / bound |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    lines += [f"| {r['N']} | {r['variant']} | {r['bare']:.0f} | {r['bare_depth']:.0f} | "
              f"{r['depth_cost']:.2f} | "
              f"{r['oracle_loop']:.0f} | {r['student_loop']:.0f} | "
              f"{r['student_over_oracle']:.2f} | "
              + " | ".join(f"{100 * r[f'share_{p}']:.0f} %" for p in PARTS)
              + f" | {r['depth_backend']} | {r['collection_alone']:.0f} | {r['update_s']:.2f} | "
              f"{r['update_budget_s']:.2f} | {r['one_core']:.0f} | {r['work_bound']:.0f} | "
              f"{r['student_over_bound']:.2f} |" for r in rows]
    return "\n".join(lines) + "\n"
