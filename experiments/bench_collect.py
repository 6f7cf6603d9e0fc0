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

    python experiments/bench_collect.py [--iterations 5] [--num-envs 64]

Writes experiments/results/bench_collect.{json,md}. Absolute numbers depend on the machine;
read the ratios to the single-process loop of the same run.
"""

from __future__ import annotations

import argparse
import csv
import functools
import json
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")  # before mujoco is imported: headless rendering

import mujoco  # noqa: E402
import torch  # noqa: E402
import torchrl  # noqa: E402

from legoh.config.compose import compose_config  # noqa: E402
from legoh.threads import torch_threads  # noqa: E402
from legoh.train.oracle import train_oracle  # noqa: E402

print = functools.partial(print, flush=True)  # noqa: A001 - progress shows as it happens
ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "experiments" / "results"
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


def measure(label: str, overrides: list[str], args) -> dict:
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iterations", type=int, default=5, help="measured, after 1 warm-up")
    parser.add_argument("--num-envs", type=int, default=64, help="envs in total, all settings")
    parser.add_argument("--steps-per-env", type=int, default=24)
    args = parser.parse_args()
    rows = [measure(label, overrides, args) for label, overrides in SETTINGS.items()]
    base = rows[0]["frames_per_s"]
    for row in rows:
        row["ratio_to_single_process"] = row["frames_per_s"] / base
    result = {
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform(),
                    "python": platform.python_version(), "torch": torch.__version__,
                    "torchrl": torchrl.__version__, "mujoco": mujoco.__version__,
                    "ray": _ray_version()},
        "config": {"robot": "h1", "trail": "randommix", "num_envs": args.num_envs,
                   "steps_per_env": args.steps_per_env, "iterations": args.iterations},
        "rows": rows,
    }
    write_results(result)


def _ray_version() -> str | None:
    try:
        import ray
    except ImportError:
        return None
    return ray.__version__


def write_results(result: dict) -> None:
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "bench_collect.json").write_text(json.dumps(result, indent=2))
    m, c = result["machine"], result["config"]
    lines = [
        "# Oracle training: collector processes vs the single-process loop", "",
        f"`python experiments/bench_collect.py` on {m['cpus']} CPUs, torch {m['torch']}, "
        f"torchrl {m['torchrl']}, MuJoCo {m['mujoco']}, Ray {m['ray']}. H1 on RandomMix, "
        f"{c['num_envs']} envs in total x {c['steps_per_env']} steps per iteration in every "
        f"setting; median of {c['iterations']} iterations after one warm-up (collection + "
        "PPO update + weight sync, from train.csv). Set-up: env build, worker start-up, "
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
    (RESULTS / "bench_collect.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {RESULTS / 'bench_collect'}.json and .md")


if __name__ == "__main__":
    main()
