"""Learn to walk: train the oracle from scratch and time the milestones of a walking robot.

    python experiments/learn_walk.py [--robot h1] [--seed 0] [--preset walk] [--minutes 60]

Milestones (frames and wall-clock minutes of training, evaluation time excluded):
  (a) training episodes last >= 15 s with <= 10 % of the ended ones a fall;
  (b) >= 80 % of 16 robots walk >= 10 m toward the terminus on the flat trail without
      falling in a 30 s evaluation (randomisation off, deterministic policy);
  (c) the same on RandomMix level 0 with randomisation on (physics draws, pushes, delay).
Writes experiments/results/learn_walk/<robot>-<preset>-s<seed>/: curve.png, evals.csv,
train.csv, milestones.json, summary.md, oracle.pt and (with a renderer) a video of the
final policy. ``--summarize`` redraws the joint picture and table from every run folder.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import shlex
import sys
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402
from hydra import compose, initialize_config_dir  # noqa: E402
from omegaconf import OmegaConf  # noqa: E402

from legoh.config import register_configs  # noqa: E402
from legoh.config.env import from_first_step  # noqa: E402
from legoh.envs.hiking_env import make_env  # noqa: E402
from legoh.eval.benchmark import rollout_level  # noqa: E402
from legoh.threads import torch_threads  # noqa: E402
from legoh.train.oracle import train_oracle  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "experiments" / "results" / "learn_walk"
WALK_M, WALK_SHARE, ROBOTS, SECONDS = 10.0, 0.8, 16, 30.0


def compose_run(robot: str, seed: int, preset: str, trail: str, extra: list[str]):
    register_configs()
    with initialize_config_dir(str(ROOT / "conf"), version_base="1.3"):
        return compose("config", overrides=[f"robot={robot}", f"seed={seed}", f"trail={trail}",
                                              f"env.reward_preset={preset}", *extra])


def walk_env_settings(cfg, trail: str, randomize: bool) -> tuple:
    """(config, env overrides) of a walk test on ``trail``: seed 1000 + the run's, 30 s
    episodes, curriculum off; randomisation from the first step or off."""
    register_configs()
    with initialize_config_dir(str(ROOT / "conf"), version_base="1.3"):
        base = compose("config", overrides=[f"trail={trail}"])
    run = OmegaConf.merge(cfg, {"trail": base.trail, "seed": 1000 + int(cfg.seed)})
    rand = from_first_step(OmegaConf.to_object(run.env.randomization), enabled=randomize)
    cur = OmegaConf.to_object(run.env.curriculum)
    cur.enabled = False
    # every robot from the trail start: the metres walked measure a walk, not a spawn
    return run, {"episode_length_s": SECONDS, "randomization": rand, "curriculum": cur,
                 "spawn_along": 0.0}


def eval_env(cfg, trail: str, randomize: bool, robots: int = ROBOTS):
    """``robots`` robots (16) in the walk test's env (:func:`walk_env_settings`)."""
    run, overrides = walk_env_settings(cfg, trail, randomize)
    return make_env(run, num_envs=robots, evaluation=True, **overrides)


def walk_test(env, actor) -> dict:
    """Metres each robot walked toward the terminus (start distance minus end distance)
    in its first episode on level 0, and whether it fell."""
    with torch_threads(1):
        was = actor.training
        actor.eval()
        rec = rollout_level(env, actor, 0)
        actor.train(was)
    terminus = env.trails.terminus[rec.tile]
    start = np.array([p[0, :2] for p in rec.paths])
    end = np.array([p[-1, :2] for p in rec.paths])
    dist = np.linalg.norm(terminus - start, axis=1) - np.linalg.norm(terminus - end, axis=1)
    fell = rec.outcomes.fall
    walked = (dist >= WALK_M) & ~fell
    return {"walked_share": float(walked.mean()), "distance_m": float(dist.mean()),
            "fall_rate": float(fell.mean()), "ttf_s": float(rec.outcomes.duration.mean())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="h1")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--preset", default="walk", help="env.reward_preset: walk | table6")
    parser.add_argument("--trail", default="flat", help="training trail")
    parser.add_argument("--minutes", type=float, default=60.0, help="training wall-clock budget")
    parser.add_argument("--frames", type=int, default=50_000_000, help="frame budget")
    parser.add_argument("--eval-every", type=float, default=3.0, help="minutes between evals")
    parser.add_argument("--tag", default="", help="suffix of the run folder (a variant)")
    parser.add_argument("--summarize", action="store_true")
    parser.add_argument("overrides", nargs="*", help="Hydra overrides, e.g. algo.num_envs=512")
    args = parser.parse_args()
    if args.summarize:
        return summarize()
    out = OUT / f"{args.robot}-{args.preset}-s{args.seed}{'-' + args.tag if args.tag else ''}"
    out.mkdir(parents=True, exist_ok=True)
    cfg = compose_run(args.robot, args.seed, args.preset, args.trail,
                      [f"algo.total_frames={args.frames}", "init=none", *args.overrides])
    envs = {"b": eval_env(cfg, "flat", False), "c": eval_env(cfg, "randommix", True)}
    frames_per_it = cfg.algo.num_envs * cfg.algo.steps_per_env
    milestones: dict[str, dict | None] = {"a": None, "b": None, "c": None}
    rows: list[dict] = []
    clock = {"train_s": 0.0, "tick": time.perf_counter(), "next_eval": 0.0}
    resume = out / "oracle.pt"
    if resume.exists() and (out / "evals.csv").exists():  # a killed run: keep its records
        rows, milestones = resume_records(out, resume)
        clock["train_s"] = 60.0 * rows[-1]["minutes"] if rows else 0.0
        clock["next_eval"] = clock["train_s"] + 60.0 * args.eval_every

    def stamp(it: int) -> dict:
        return {"iteration": it, "frames": it * frames_per_it,
                "minutes": round(clock["train_s"] / 60.0, 2)}

    def on_iteration(it: int, stats: dict, actor) -> bool:
        now = time.perf_counter()
        clock["train_s"] += now - clock["tick"]
        ep_s = stats["episode_frames"] * cfg.sim.dt * cfg.sim.decimation
        if milestones["a"] is None and ep_s >= 15.0 and stats["fell_frac"] <= 0.10:
            milestones["a"] = {**stamp(it), "episode_s": ep_s, "fell_frac": stats["fell_frac"]}
        stop = clock["train_s"] >= 60.0 * args.minutes
        if clock["train_s"] >= clock["next_eval"] or stop:
            clock["next_eval"] += 60.0 * args.eval_every
            row = {**stamp(it), "train_episode_s": ep_s, "train_fell": stats["fell_frac"]}
            for name, env in envs.items():
                res = walk_test(env, actor)
                row.update({f"{name}_{k}": v for k, v in res.items()})
                if milestones[name] is None and res["walked_share"] >= WALK_SHARE:
                    milestones[name] = {**stamp(it), **res}
            rows.append(row)
            write_results(out, args, cfg, rows, milestones)
            print(f"[learn_walk] {row}", flush=True)
        clock["tick"] = time.perf_counter()
        return stop

    hint = " ".join(["python", *map(shlex.quote, sys.argv)])  # rerun: it resumes from out
    run = train_oracle(cfg, out, resume=str(resume) if resume.exists() else None,
                       on_iteration=on_iteration, resume_hint=hint)
    write_results(out, args, cfg, rows, milestones)
    try:
        from legoh.play import render_policy_video

        render_policy_video(cfg, run.policy, out / "final_policy.mp4")
    except ImportError:
        print("[learn_walk] no renderer (legoh.play) yet: video skipped")


def resume_records(out: Path, checkpoint: Path) -> tuple[list[dict], dict]:
    """Evaluations and milestones of a killed run, up to its checkpoint's iteration (the
    training clock resumes from the last evaluation kept; the time after it is lost)."""
    import torch

    it = int(torch.load(checkpoint, map_location="cpu", weights_only=False)["iteration"])
    with open(out / "evals.csv") as f:
        rows = [{k: float(v) for k, v in r.items()} for r in csv.DictReader(f)]
    rows = [r for r in rows if r["iteration"] <= it]
    meta = json.loads((out / "milestones.json").read_text())["milestones"]
    milestones = {k: (m if m is not None and m["iteration"] <= it else None)
                  for k, m in meta.items()}
    return rows, milestones


def write_results(out: Path, args, cfg, rows: list[dict], milestones: dict) -> None:
    """evals.csv, milestones.json, summary.md and curve.png of one run (rewritten each eval)."""
    if rows:
        with open(out / "evals.csv", "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
    meta = {"robot": args.robot, "seed": args.seed, "preset": args.preset,
            "trail": args.trail, "num_envs": int(cfg.algo.num_envs),
            "milestones": milestones, "criteria": {
                "a": "training episodes >= 15 s, <= 10 % of ended episodes falls",
                "b": f">= {WALK_SHARE:.0%} of {ROBOTS} robots walk >= {WALK_M} m toward the "
                     "terminus without falling, flat, randomisation off, 30 s",
                "c": "as (b) on RandomMix level 0 with randomisation on"},
            "last_eval": rows[-1] if rows else None}
    (out / "milestones.json").write_text(json.dumps(meta, indent=2))
    plot_runs([out], out / "curve.png")
    lines = [f"# learn_walk: {args.robot}, preset {args.preset}, seed {args.seed}", ""]
    for k, m in milestones.items():
        lines.append(f"- ({k}) " + ("not reached" if m is None else
                                    f"{m['frames']:,} frames, {m['minutes']} min"))
    (out / "summary.md").write_text("\n".join(lines) + "\n")


def read_evals(run: Path) -> dict[str, np.ndarray]:
    with open(run / "evals.csv") as f:
        rows = list(csv.DictReader(f))
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}


def plot_runs(runs: list[Path], path: Path) -> None:
    """Per run: training episode length, evaluation walked share and distance vs frames."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 4, figsize=(18, 4))
    for i, run in enumerate(runs):  # one colour per run; dashed: RandomMix L0 + DR
        if not (run / "evals.csv").exists():
            continue
        e = read_evals(run)
        x, c = e["frames"] / 1e6, f"C{i}"
        axes[0].plot(x, e["train_episode_s"], color=c, label=run.name)
        axes[1].plot(x, e["train_fell"], color=c)
        axes[2].plot(x, e["b_distance_m"], color=c)
        axes[2].plot(x, e["c_distance_m"], "--", color=c)
        axes[3].plot(x, 100 * e["b_walked_share"], color=c)
        axes[3].plot(x, 100 * e["c_walked_share"], "--", color=c)
    titles = ["training episode length (s)", "training falls / ended episodes",
              "eval: m toward the terminus (solid flat, dashed RandomMix+DR)",
              "eval: % of 16 walking >= 10 m"]
    for ax, t in zip(axes, titles, strict=True):
        ax.set_title(t)
        ax.set_xlabel("frames (M)")
        ax.grid(alpha=0.3)
    axes[0].axhline(15, color="k", lw=0.5)
    axes[2].axhline(WALK_M, color="k", lw=0.5)
    axes[3].axhline(100 * WALK_SHARE, color="k", lw=0.5)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def summarize() -> None:
    """curve.png and summary.md over every run folder under results/learn_walk/."""
    runs = sorted(p for p in OUT.iterdir() if (p / "milestones.json").exists())
    plot_runs(runs, OUT / "curve.png")
    lines = ["| run | (a) frames / min | (b) frames / min | (c) frames / min | last eval: "
             "flat m, % walking; RandomMix m, % |", "|---|---|---|---|---|"]
    for run in runs:
        meta = json.loads((run / "milestones.json").read_text())
        cells = ["-" if m is None else f"{m['frames'] / 1e6:.1f} M / {m['minutes']:.0f}"
                 for m in meta["milestones"].values()]
        last = meta["last_eval"] or {}
        lines.append(f"| {run.name} | " + " | ".join(cells) + " | "
                     f"{last.get('b_distance_m', float('nan')):.1f}, "
                     f"{100 * last.get('b_walked_share', float('nan')):.0f}; "
                     f"{last.get('c_distance_m', float('nan')):.1f}, "
                     f"{100 * last.get('c_walked_share', float('nan')):.0f} |")
    (OUT / "summary.md").write_text("# learn_walk runs\n\n" + "\n".join(lines) + "\n")
    print((OUT / "summary.md").read_text())


if __name__ == "__main__":
    main()
