"""Where the oracle loop's time goes: bare env, collection, update and loop frames/s.

    python experiments/bench.py train [--sizes 64 256 512 1024] [--iterations 3]
    python experiments/bench.py train --sizes 64 256 --no-variants \
        --set env.compile=true --tag compiled

Per batch size N, in one run (these machines are noisy, so compare within a run):
  bare:       HikingEnv.step_and_maybe_reset with random actions (the ceiling);
  collection: torchrl's Collector with the oracle actor (N x steps_per_env frames a batch);
  update:     ``OraclePPO.update`` (GAE + the PPO epochs + the adaptation module) on each
              collected batch, in float32 and with ``algo.update_precision=bfloat16``
              (autocast);
  loop:       the real training loop (``train_oracle``), frames/s of its iterations after
              the first, in two settings of the default config (the lean update: 3
              epochs, a 256-128-64 critic, update_precision=auto: bfloat16 on AMX /
              AVX512-BF16 CPUs):
                turns:   ``collector.overlap=false``: collection and update take turns in
                         one process (the default until 2026-12-03, "default" in older
                         results);
                overlap: ``collector.overlap=true``: the next batch is collected in a
                         worker process while the learner updates (the oracle's default
                         since 2026-12-03 evening; "lean" before 2026-12-03).
Then update variants at the largest N (epochs x minibatches, precision): what a cheaper
update would buy. Adds a run to experiments/results/bench_train.{md,json}.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
from omegaconf import OmegaConf
from torchrl.collectors import Collector

from legoh.config.compose import compose_config
from legoh.envs.hiking_env import make_env
from legoh.eval.curves import read_columns
from legoh.train.oracle import OraclePPO, train_oracle

RESULTS = "bench_train"
TITLE = "Oracle training loop vs its env (frames/s, one run)"
TORCH_THREADS = 1
BF16, F32 = "algo.update_precision=bfloat16", "algo.update_precision=float32"
CRITIC256, CRITIC512 = "algo.critic_hidden=[256,128,64]", "algo.critic_hidden=[512,256,128]"
EPOCHS3, EPOCHS5 = "algo.epochs=3", "algo.epochs=5"
LOOPS = {"turns": ["collector.overlap=false"], "overlap": ["collector.overlap=true"]}


OVERRIDES: list[str] = []  # --set: applied to every config of the run


def config(n: int, *extra: str):
    """The benchmark's config: ``n`` robots on the flat trail."""
    return compose_config("trail=flat", f"algo.num_envs={n}", *OVERRIDES, *extra)


def bare_rate(env, steps: int) -> float:
    gen = torch.Generator().manual_seed(0)
    td = env.reset()
    t0 = 0.0
    for i in range(steps + 5):
        if i == 5:
            t0 = time.perf_counter()
        td["action"] = torch.randn(env.num_envs, env.num_actions, generator=gen) * 0.5
        _, td = env.step_and_maybe_reset(td)
    return env.num_envs * steps / (time.perf_counter() - t0)


def collect_and_update(cfg, env, batches: int, precisions=("float32",)
                       ) -> tuple[float, list[float], object]:
    """(collection frames/s, update frames/s per precision, last batch): the real
    :meth:`OraclePPO.update`, one algorithm per precision, each on every batch."""
    algorithms = {}
    for p in precisions:
        torch.manual_seed(0)  # the same initial networks for each precision
        algorithms[p] = OraclePPO(OmegaConf.merge(cfg, {"algo": {"update_precision": p}}), env,
                                  device=torch.device("cpu"))
    frames = cfg.algo.num_envs * cfg.algo.steps_per_env
    collector = Collector(env, algorithms[precisions[0]].policy, frames_per_batch=frames,
                          total_frames=frames * batches, auto_register_policy_transforms=False)
    t_col, t_upd, batch = [], {p: [] for p in precisions}, None
    tick = time.perf_counter()
    for batch in collector:
        t_col.append(time.perf_counter() - tick)
        for p, algorithm in algorithms.items():  # the same batch through each, interleaved
            t0 = time.perf_counter()
            algorithm.update(batch.reshape(-1, batch.shape[-1]).clone())
            t_upd[p].append(time.perf_counter() - t0)
        tick = time.perf_counter()
    collector.shutdown()
    return (frames / np.mean(t_col[1:]), [frames / np.mean(t_upd[p][1:]) for p in precisions],
            batch)


def loop_rate(cfg, iterations: int) -> float:
    frames = cfg.algo.num_envs * cfg.algo.steps_per_env
    with tempfile.TemporaryDirectory() as tmp:
        run_cfg = OmegaConf.merge(cfg, {"algo": {"total_frames": frames * iterations}})
        run = train_oracle(run_cfg, Path(tmp))
        fps = read_columns(run.csv)["frames_per_s"]
    return float(np.mean(fps[1:]))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 256, 512, 1024])
    parser.add_argument("--iterations", type=int, default=3)
    parser.add_argument("--no-variants", action="store_true", help="skip the update variants")
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                        help="overrides for every env and loop, e.g. env.compile=true")


def measure(args: argparse.Namespace) -> dict:
    """Per N: bare env, collection, update and both loops; then the update variants."""
    OVERRIDES[:] = args.set
    rows = []
    for n in args.sizes:
        cfg = config(n)
        env = make_env(cfg, num_envs=n)
        bare = bare_rate(env, max(50, 6000 // n))
        col, (upd, upd_bf16), _ = collect_and_update(cfg, env, args.iterations,
                                                     ("float32", "bfloat16"))
        env.close()
        loops = {name: loop_rate(config(n, *extra), args.iterations + bool(extra))
                 for name, extra in LOOPS.items()}
        row = {"N": n, "bare": bare, "collection": col, "update": upd, "update_bf16": upd_bf16,
               **{f"loop_{name}": fps for name, fps in loops.items()},
               **{f"{name}_over_bare": fps / bare for name, fps in loops.items()},
               "update_share": (1 / upd) / (1 / col + 1 / upd)}
        rows.append(row)
        print(json.dumps(row), flush=True)

    n = args.sizes[-1]
    variants = {} if args.no_variants else {
        "5 x 4, float32, critic 512-256-128 (the paper's)": [F32, EPOCHS5, CRITIC512],
        "5 x 4, bfloat16": [BF16, EPOCHS5, CRITIC512],
        "5 x 2, bfloat16": [BF16, EPOCHS5, CRITIC512, "algo.minibatches=2"],
        "3 x 4, bfloat16": [BF16, EPOCHS3, CRITIC512],
        "5 x 4, bfloat16, critic 256-128-64": [BF16, EPOCHS5, CRITIC256],
        "3 x 4, bfloat16, critic 256-128-64 (lean, the default)": [BF16, CRITIC256, EPOCHS3]}
    var_rows = []
    for name, extra in variants.items():
        cfg = config(n, *extra)
        env = make_env(cfg, num_envs=n)
        col, (upd,), _ = collect_and_update(cfg, env, 2 + 1,
                                            (str(cfg.algo.update_precision.value),))
        env.close()
        var_rows.append({"variant": name, "collection": col, "update": upd,
                         "loop_estimate": 1 / (1 / col + 1 / upd)})
        print(json.dumps(var_rows[-1]), flush=True)
    return {"sizes": rows, "update_variants_at_N": n, "variants": var_rows}


def summary(run: dict) -> str:
    """The loops' frames/s per N (older runs named their loops otherwise)."""
    return "; ".join(f"N={r['N']} " + ", ".join(f"{k[5:]} {v:.0f}" for k, v in r.items()
                                                 if k.startswith("loop_"))
                     for r in run["results"]["sizes"]) + " loop frames/s"


def markdown(run: dict) -> str:
    result, overrides = run["results"], run["conditions"].get("set", [])
    rows, var_rows, n = result["sizes"], result["variants"], result["update_variants_at_N"]
    lines = [f"{run['conditions'].get('torch_threads', 1)} torch thread(s).", "",
             *([f"Every env and loop with `{' '.join(overrides)}`.", ""] if overrides else []),
             "Loops of the default config (the lean update): turns = "
             f"`{' '.join(LOOPS['turns'])}` (collection and update in turns, one process), "
             f"overlap = `{' '.join(LOOPS['overlap'])}` (the oracle's default: the next batch "
             "collected in a worker process during the update).", "",
             "| N | bare env | collection | update | update bf16 | "
             + " | ".join(f"{name} loop | / bare" for name in LOOPS) + " | update share |",
             "|---|---|---|---|---|" + "---|---|" * len(LOOPS) + "---|"]
    lines += [f"| {r['N']} | {r['bare']:.0f} | {r['collection']:.0f} | {r['update']:.0f} | "
              f"{r['update_bf16']:.0f} | "
              + " | ".join(f"{r[f'loop_{name}']:.0f} | {r[f'{name}_over_bare']:.2f}"
                           for name in LOOPS)
              + f" | {r['update_share']:.0%} |" for r in rows]
    if var_rows:
        lines += ["", f"Update variants at N = {n} (epochs x minibatches; the loop estimate "
                  "is collection and update in series)", "",
                  "| variant | collection | update | loop estimate |", "|---|---|---|---|"]
    lines += [f"| {r['variant']} | {r['collection']:.0f} | {r['update']:.0f} | "
              f"{r['loop_estimate']:.0f} |" for r in var_rows]
    return "\n".join(lines) + "\n"
