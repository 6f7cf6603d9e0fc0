"""Where hikers stop: the benchmark's time-outs and how far from the terminus they stand.

    python experiments/stops_short.py LABEL=CHECKPOINT [LABEL=CHECKPOINT ...]
                                      [--robot h1] [--robots 40] [--out NAME]

Scores each oracle checkpoint (``pretrained`` for the shipped one) on the shipping
protocol's scenes (``trail=hike``: five categories x levels 0-4 x 5 variants, robots placed
2-10 m of path from the terminus, randomisation on, 30 s, eval seed 2000), one run of
``--robots`` robots a level, on the feet each checkpoint trained on. Per checkpoint and
category: SR, falls, time-outs, and the time-outs that ended *short*: standing (under
0.1 m/s over their last 5 s) within 2 m of the terminus. A reach that terminated the
training episode cut off the value of the steps after it, so a policy whose steps pay more
than they cost learns to stop short (docs/oracle.md, "Recipe v2": ``env.reach_truncates``).
Writes ``experiments/results/stops_short/<out>.md`` and ``<out>.png`` (distance left at
each time-out).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402

from legoh.config.compose import compose_config, register_configs  # noqa: E402
from legoh.eval.benchmark import make_eval_env, rollout_level  # noqa: E402
from legoh.eval.cli import build_actor, for_checkpoint  # noqa: E402
from legoh.threads import torch_threads  # noqa: E402

OUT = Path(__file__).resolve().parent / "results" / "stops_short"
NEAR_M, STILL_MS, LAST_S = 2.0, 0.1, 5.0  # "short": within 2 m, under 0.1 m/s over 5 s


def score(robot: str, checkpoint: str, robots: int) -> dict[str, np.ndarray]:
    """Per robot (all levels pooled): category, outcome, metres left to the terminus at the
    end, mean speed over the last ``LAST_S`` seconds."""
    register_configs()
    cfg = compose_config(f"robot={robot}", "trail=hike", f"eval.robots={robots}", "eval.runs=1",
                         "eval.variants=5", "eval.levels=[0,1,2,3,4]",
                         "eval.randomization=true", "eval.seed=2000")
    cfg, checkpoint = for_checkpoint(cfg, checkpoint)
    actor, _ = build_actor(cfg, checkpoint)
    env = make_eval_env(cfg)
    last = int(round(LAST_S / env.dt))
    rows: dict[str, list] = {k: [] for k in ("category", "success", "fall", "left", "speed")}
    with torch_threads(1):
        for level in tqdm(range(5), desc=f"{Path(checkpoint).stem} levels", leave=False):
            rec = rollout_level(env, actor, level)
            terminus = env.trails.terminus[rec.tile][:, :2]
            for i, path in enumerate(rec.paths):
                step = np.linalg.norm(np.diff(path[:, :2], axis=0), axis=1) / env.dt
                rows["left"].append(float(np.linalg.norm(path[-1, :2] - terminus[i])))
                rows["speed"].append(float(step[-last:].mean()) if len(step) else 0.0)
            rows["category"].extend(rec.category.tolist())
            rows["success"].extend(rec.outcomes.success.tolist())
            rows["fall"].extend(rec.outcomes.fall.tolist())
    env.close()
    return {k: np.asarray(v) for k, v in rows.items()}


def time_outs(r: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(N,) bool each: the robots that timed out (neither reached nor fell), and those of
    them that ended short (standing within ``NEAR_M`` of the terminus)."""
    timeout = ~r["success"] & ~r["fall"]
    return timeout, timeout & (r["left"] < NEAR_M) & (r["speed"] < STILL_MS)


def table_rows(label: str, r: dict[str, np.ndarray]) -> list[str]:
    timeout, short = time_outs(r)
    lines = []
    for cat in [*dict.fromkeys(r["category"].tolist()), "overall"]:
        m = np.ones(len(timeout), bool) if cat == "overall" else r["category"] == cat
        left = r["left"][m & timeout]
        median = f"{np.median(left):.2f}" if len(left) else "-"
        lines.append(f"| {label} | {cat} | {100 * r['success'][m].mean():.1f} | "
                     f"{100 * r['fall'][m].mean():.1f} | {100 * timeout[m].mean():.1f} | "
                     f"{100 * short[m].mean():.1f} | {median} |")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", help="LABEL=CHECKPOINT (pretrained: the shipped)")
    parser.add_argument("--robot", default="h1")
    parser.add_argument("--robots", type=int, default=40, help="robots per level")
    parser.add_argument("--out", default="stops_short")
    args = parser.parse_args()
    pairs = [run.split("=", 1) for run in args.runs]
    bad = [run for run, pair in zip(args.runs, pairs, strict=True) if len(pair) != 2]
    if bad:
        raise SystemExit(f"runs {bad}: write each as LABEL=CHECKPOINT")
    results = {label: score(args.robot, ckpt, args.robots) for label, ckpt in pairs}
    OUT.mkdir(parents=True, exist_ok=True)
    lines = [f"# Where hikers stop ({args.robot}; `python experiments/stops_short.py "
             + " ".join(args.runs) + f" --robots {args.robots}`)", "",
             f"The shipping protocol's scenes, one run of {args.robots} robots a level "
             "(levels 0-4 pooled). *Short*: a time-out standing (under "
             f"{STILL_MS} m/s over its last {LAST_S:.0f} s) within {NEAR_M:.0f} m of the "
             "terminus (the benchmark's reach radius: 0.89 m).", "",
             "| checkpoint | category | SR (%) | falls (%) | time-outs (%) | short (%) | "
             "median m left at a time-out |", "|---|---|---|---|---|---|---|"]
    for label, r in results.items():
        lines += table_rows(label, r)
    md = OUT / f"{args.out}.md"
    md.write_text("\n".join(lines) + "\n")
    fig, ax = plt.subplots(figsize=(7, 3.5))
    bins = np.linspace(0.0, 10.0, 41)
    for label, r in results.items():
        timeout, _ = time_outs(r)
        ax.hist(r["left"][timeout], bins=bins, histtype="step", lw=2,
                label=f"{label} ({timeout.sum()} time-outs)")
    ax.axvline(0.89, color="k", ls=":", label="reach radius (0.89 m)")
    ax.set(xlabel="m from the terminus at the time-out", ylabel="robots",
           title=f"Where the time-outs stood ({args.robot}, levels 0-4, 5 categories)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(OUT / f"{args.out}.png", dpi=120)
    print(md.read_text())


if __name__ == "__main__":
    main()
