"""Evidence of learning: a longer oracle run on an easy trail, trained vs untrained.

    python experiments/oracle_study.py [--frames 2000000] [--trail flat]

Same seeds for both policies: the untrained actor is the trained one's initialisation. Writes
to experiments/results/oracle_study/: the learning curve, both benchmark tables side by
side (Markdown + CSV), trajectory pictures, and the training loop's frames/s against the
bare HikingEnv's (random actions, same N, measured in this run).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import torch  # noqa: E402

from legoh.config.compose import compose_config  # noqa: E402
from legoh.envs.hiking_env import make_env  # noqa: E402
from legoh.eval.benchmark import compare, evaluate  # noqa: E402
from legoh.eval.curves import plot_learning_curve, read_columns  # noqa: E402
from legoh.eval.metrics import write_csv, write_markdown  # noqa: E402
from legoh.policies.oracle import build_oracle  # noqa: E402
from legoh.train.oracle import train_oracle  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "experiments" / "results" / "oracle_study"


def bare_env_rate(cfg, steps: int = 200) -> float:
    """Policy steps/s of HikingEnv alone (random actions), same N as training."""
    env = make_env(cfg, num_envs=cfg.algo.num_envs)
    td = env.reset()
    gen = torch.Generator().manual_seed(0)
    t0 = 0.0
    for i in range(steps + 10):
        if i == 10:
            t0 = time.perf_counter()
        td["action"] = torch.randn(env.num_envs, env.num_actions, generator=gen) * 0.5
        _, td = env.step_and_maybe_reset(td)
    rate = env.num_envs * steps / (time.perf_counter() - t0)
    env.close()
    return rate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=2_000_000)
    parser.add_argument("--trail", default="flat")
    parser.add_argument("--robot", default="h1")
    parser.add_argument("--resume", action="store_true",
                        help="continue the last study's training up to --frames, then re-evaluate")
    args = parser.parse_args()
    cfg = compose_config(f"robot={args.robot}", f"trail={args.trail}",
                         f"algo.total_frames={args.frames}", "init=none")  # vs its untrained start
    checkpoint = OUT / "train" / "oracle.pt"
    resume = str(checkpoint) if args.resume and checkpoint.exists() else None
    if not resume:
        shutil.rmtree(OUT, ignore_errors=True)
    OUT.mkdir(parents=True, exist_ok=True)

    bare = bare_env_rate(cfg)
    print(f"bare HikingEnv: {bare:.0f} steps/s at N={cfg.algo.num_envs}", flush=True)

    # The untrained policy is the trained one's initialisation: built in the same order from
    # the same seed as train_oracle builds it.
    torch.manual_seed(cfg.seed)
    env = make_env(cfg, num_envs=cfg.algo.num_envs)
    _, untrained, _, _ = build_oracle(env, cfg)
    env.close()

    t0 = time.perf_counter()
    run = train_oracle(cfg, OUT / "train", resume=resume)
    train_s = time.perf_counter() - t0  # this session's share when resuming

    results = {
        "untrained": evaluate(cfg, untrained, OUT / "eval_untrained", label="untrained"),
        "trained": evaluate(cfg, run.policy, OUT / "eval_trained", label="trained oracle"),
    }
    rows = compare(results)
    title = (f"Oracle ({args.robot}, trail={args.trail}) after {run.iterations} iterations "
             f"({args.frames:,} frames) vs its initialisation; "
             f"protocol: {cfg.eval.robots} robots x {cfg.eval.seconds:.0f} s, levels "
             f"{list(cfg.eval.levels)}, {cfg.eval.runs} runs")
    write_markdown(OUT / "comparison.md", rows, label="Policy", title=title)
    write_csv(OUT / "comparison.csv", rows, label="policy")
    curve = plot_learning_curve(run.csv, OUT / "learning_curve.png",
                                title=f"oracle PPO, {args.robot} on {args.trail}",
                                frames_per_iteration=cfg.algo.num_envs * cfg.algo.steps_per_env,
                                dt=cfg.sim.dt * cfg.sim.decimation)
    cols = read_columns(run.csv)
    loop_rate = float(cols["frames_per_s"][1:].mean()) if len(cols["frames_per_s"]) > 1 else 0.0
    summary = {
        "robot": args.robot, "trail": args.trail, "frames": args.frames,
        "iterations": run.iterations, "train_minutes_this_session": train_s / 60,
        "resumed": bool(resume),
        "training_loop_frames_per_s": loop_rate, "bare_env_steps_per_s": bare,
        "loop_over_bare": loop_rate / bare,
        "overall": {label: {m: list(v) for m, v in r["rows"]["overall"].items()}
                    for label, r in results.items()},
        "learning_curve": str(curve.relative_to(ROOT)),
    }
    (OUT / "summary.json").write_text(json.dumps(summary, indent=2))
    print((OUT / "comparison.md").read_text())
    print(json.dumps({k: v for k, v in summary.items() if k != "overall"}, indent=2))


if __name__ == "__main__":
    main()
