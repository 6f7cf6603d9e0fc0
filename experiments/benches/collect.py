"""Oracle training frames/s with 1 and 2 collector processes against the single-process loop.

In one run, the same training config (H1, RandomMix, ``algo.num_envs`` envs in total,
``algo.steps_per_env`` steps each per iteration) with:
  * sync, 1 worker: the envs step in the learner's process (the default; the baseline);
  * sync, 2 workers: torchrl's MultiSyncCollector, two local processes, half the envs each;
  * ray, 1 and 2 workers: torchrl's RayCollector on a local Ray cluster;
  * sync, 2 workers with ``sim.threads=1``: one MuJoCo thread per worker process;
  * sync, 1 worker with the learner's torch on 1 thread (the workers of the multi-process
    collectors run torch on 1 thread each; in-process, torch's default of one thread per
    core competes with MuJoCo's thread pool).

Per setting: ``train_oracle`` for 1 warm-up + ``--iterations`` iterations; the figure is the
median of the per-iteration frames/s in train.csv (collection + PPO update + weight sync),
warm-up left out. Set-up (env build, worker start) is reported apart.

    python experiments/bench.py collect [--iterations 5] [--num-envs 64]

Adds a run to experiments/results/bench_collect.{json,md}. Absolute numbers depend on the
machine; read the ratios to the single-process loop of the same run.
"""

from __future__ import annotations

import argparse
import csv
import os
import statistics
import tempfile
import time
from pathlib import Path

import torch
import torchrl

from benches.common import machine_line
from legoh.config.compose import compose_config
from legoh.threads import torch_threads
from legoh.train.oracle import train_oracle

RESULTS = "bench_collect"
TITLE = "Oracle training: collector processes vs the single-process loop"
TORCH_THREADS = None  # torch's default: the baseline's learner as training runs it
BASELINE = "sync x1 (in-process)"
SETTINGS = {  # label -> overrides
    BASELINE: ["collector=sync", "collector.workers=1"],
    "sync x2 (MultiSyncCollector)": ["collector=sync", "collector.workers=2"],
    "ray x1 (RayCollector)": ["collector=ray", "collector.workers=1"],
    "ray x2 (RayCollector)": ["collector=ray", "collector.workers=2"],
    "sync x2, sim.threads=1": ["collector=sync", "collector.workers=2", "sim.threads=1"],
    "sync x1, torch on 1 thread": ["collector=sync", "collector.workers=1"],
}
TORCH_ONE_THREAD = {"sync x1, torch on 1 thread"}


def measure_setting(label: str, overrides: list[str], args) -> dict:
    """Train 1 + ``iterations`` iterations; median frames/s over all but the first."""
    frames = args.num_envs * args.steps_per_env
    cfg = compose_config(f"algo.num_envs={args.num_envs}",
                         f"algo.steps_per_env={args.steps_per_env}",
                         f"algo.total_frames={frames * (args.iterations + 1)}",
                         "algo.checkpoint_every=1000", "algo.trajectory_every=1000",
                         *overrides)
    threads = 1 if label in TORCH_ONE_THREAD else torch.get_num_threads()
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as out, torch_threads(threads):
        start = time.perf_counter()
        run = train_oracle(cfg, Path(out))
        total = time.perf_counter() - start
        with open(run.csv) as f:
            rates = [float(row["frames_per_s"]) for row in csv.DictReader(f)]
    measured = rates[1:]
    run_time = sum(frames / r for r in rates)
    result = {"label": label, "overrides": overrides, "frames_per_iteration": frames,
              "frames_per_s": statistics.median(measured),
              "frames_per_s_min": min(measured), "frames_per_s_max": max(measured),
              "warmup_frames_per_s": rates[0],
              "setup_s": total - run_time,  # env build, workers, final checkpoint
              "learner_torch_threads": threads,
              "load_before": load, "load_after": os.getloadavg()[0]}  # 1-min load average
    print(f"{label:32s} {result['frames_per_s']:7.0f} frames/s "
          f"(min {result['frames_per_s_min']:.0f}, max {result['frames_per_s_max']:.0f}; "
          f"set-up {result['setup_s']:.1f} s; load {load:.1f})")
    return result


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--iterations", type=int, default=5, help="measured, after 1 warm-up")
    parser.add_argument("--num-envs", type=int, default=64, help="envs in total, all settings")
    parser.add_argument("--steps-per-env", type=int, default=24)


def measure(args: argparse.Namespace) -> dict:
    """Every setting in turn; frames/s and their ratio to the single-process loop."""
    rows = [measure_setting(label, overrides, args) for label, overrides in SETTINGS.items()]
    base = rows[0]["frames_per_s"]
    for row in rows:
        row["ratio_to_single_process"] = row["frames_per_s"] / base
    return {"config": {"robot": "h1", "trail": "randommix", "num_envs": args.num_envs,
                       "steps_per_env": args.steps_per_env, "iterations": args.iterations},
            "rows": rows}


def machine() -> str:
    return machine_line(torchrl=torchrl.__version__, Ray=_ray_version())


def _ray_version() -> str | None:
    try:
        import ray
    except ImportError:
        return None
    return ray.__version__


def summary(run: dict) -> str:
    best = max(run["results"]["rows"], key=lambda r: r["ratio_to_single_process"])
    return f"best {best['label']}: {best['ratio_to_single_process']:.2f} x the single process"


def markdown(run: dict) -> str:
    result = run["results"]
    c = result["config"]
    lines = [
        f"H1 on RandomMix, {c['num_envs']} envs in total x {c['steps_per_env']} steps per "
        f"iteration in every setting; median of {c['iterations']} iterations after one "
        "warm-up (collection + PPO update + weight sync, from train.csv). Set-up: env "
        "build, worker start-up, "
        "final checkpoint. Load: the machine's 1-minute load average before and after "
        "(other jobs share these cores: compare rows with similar load).", "",
        "| collector | frames/s | min-max | ratio to single process | set-up (s) | load |",
        "|---|---|---|---|---|---|",
    ]
    for row in result["rows"]:
        lines.append(f"| {row['label']} | {row['frames_per_s']:.0f} | "
                     f"{row['frames_per_s_min']:.0f}-{row['frames_per_s_max']:.0f} | "
                     f"{row['ratio_to_single_process']:.2f} | {row['setup_s']:.1f} | "
                     f"{row['load_before']:.1f}-{row['load_after']:.1f} |")
    return "\n".join(lines) + "\n"
