"""Learn to hike: the oracle from a flat-ground walker to every trail category, as a
campaign of runs that each resume from the last one's committed checkpoint.

    python experiments/learn_hike.py [--robot h1] [--seed 0] [--minutes 85] [--init PATH]
                                     [--recipe v2|v1]   # folder <robot>-s<seed>-v2 | -s<seed>
    python experiments/learn_hike.py --evaluate [--robot h1] [--seed 0]   # benchmark snapshots
    python experiments/learn_hike.py --plot [--robot h1] [--seed 0]
    python experiments/learn_hike.py --compare warm scratch [--robot h1] [--seed 0]
    python experiments/learn_hike.py --arm ground --init PATH --minutes 13   # an A/B arm

Training (``trail=hike``: RandomMix, Ditch, Hurdle, Gap and Forest in one map, each robot
its own category and level under the curriculum; randomisation brought in by the gate) starts
from ``--init`` (default: the committed walker of the robot; ``none``: from scratch) and, when
the run folder already holds ``oracle.pt``, resumes from it instead: a campaign is this command
run again on a fresh clone after the previous run's files were committed. Every
``--eval-every`` minutes of training it saves the actor to ``snapshots/`` (git-ignored) and
runs the walk test of milestone (c) in-process; ``--evaluate`` then scores every snapshot not
yet scored with the benchmark (robots placed along the trail, randomisation on) for (d) and
(e). Milestones (frames and minutes of training; evaluation time excluded):

  (c) >= 80 % of 16 robots walk >= 10 m on RandomMix level 0 with randomisation on;
  (d) SR >= 50 % on RandomMix levels 0-2 (the benchmark, randomisation on);
  (e) SR >= 70 % on RandomMix levels 0-4 and >= 50 % on each of Ditch, Hurdle, Gap, Forest.

Writes experiments/results/learn_hike/<robot>-s<seed>[-tag]/ (tag: --tag, else ab3-<arm>, else
v2 for recipe v2): oracle.pt, train.csv,
sessions.csv (each start: iteration, commit, recipe), clock.csv (training minutes per
iteration), evals.csv (walk tests), bench.csv (benchmark per snapshot, category and level),
milestones.json, summary.md and curve.png. The videos in ``videos/`` are the play mode's
(``python run.py mode=play robot=<robot> checkpoint=<run folder>/oracle.pt trail=hurdle
'eval.levels=[2]' eval.spawn_remaining=null``: from the trail start, level 2).
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import sys
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402
import torch  # noqa: E402
from campaign import (  # noqa: E402
    Session,
    add_campaign_arguments,
    compare_runs,
    finish_figure,
    mark_recipe_changes,
    milestone_lines,
    plot_training,
    read_rows,
    snapshots_to_score,
    training_row,
    write_rows,
)
from learn_walk import compose_run, eval_env, read_evals, walk_test  # noqa: E402

from legoh.eval.benchmark import rollout_level  # noqa: E402
from legoh.policies.embodiment import with_checkpoint_body  # noqa: E402
from legoh.train.oracle import train_oracle  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "experiments" / "results" / "learn_hike"
WALKER = {"h1": ROOT / "experiments/results/learn_walk/h1-walk-s0-fast-c256-e3/oracle.pt",
          # (b) at 140 chained minutes (docs/oracle.md, "G1"); it learned with the hike preset
          "g1": ROOT / "experiments/results/learn_walk/g1-hike-s0-bent-kp200-wp2/oracle.pt"}
# the lean loop of learn_walk (bfloat16 update, overlapped collection, 256-128-64 critic,
# 3 epochs): the walker it starts from was trained with it
LEAN = ["algo.update_precision=bfloat16", "collector.overlap=true",
        "algo.critic_hidden=[256,128,64]", "algo.epochs=3"]
# The recipe (``--recipe``): v2 (default) is the config's own defaults since 2026-12-05: the
# ``leap`` reward preset, support heights, a gait clock that yields near edges, commands up
# to 1.5 m/s, the appendix's curriculum thresholds (0.8 / 0.4), sphere feet. v1 is the
# shipped oracles' (conf/experiment/recipe_v1.yaml): the ``hike`` preset (the velocity
# kernel toward the next waypoint: with the heading form h1-s0 learned to walk in circles;
# docs/oracle.md), heights against pit floors, the clock everywhere, the MJCF's feet, and
# thresholds 0.6 / 0.3 (the walker covers ~60 % of its commanded distance, so at the
# paper's 0.8 no robot was promoted in 25 minutes).
RECIPES = {"v1": ("hike", ["+experiment=recipe_v1"]), "v2": ("leap", [])}
HIKE = RECIPES["v1"][1]  # paper_tables' committed jobs trained with the v1 teachers' recipe
# Issue 44's A/B round (``--arm``): recipe v2 whole, and v2 without one of its changes at a
# time (leave one out), each a short run from the same warm start; training only (the walk
# test and the benchmark stay on v2's trails and protocol). Run folder: <robot>-s<seed>-ab3-<arm>
ARMS = {
    "v2": [],
    "ground": ["env.height_reference=ground"],  # heights against the pit floors
    "clock": ["env.gait.yield_near=0"],  # the gait clock everywhere
    "hike": ["env.reward_preset=hike"],  # no clearance terms, no leap air time
    "speed": ["env.command.speed=[0.3,1.0]"],  # commands to 1 m/s
    "start": ["env.spawn_along=0"],  # every robot at the trail start
    "mix": ["env.curriculum.lagging_mix=0"],  # each robot keeps its category
    "pay": ["env.gait.yield_pay=0"],  # the clock's terms pay nothing where it yields
    "terminate": ["env.reach_truncates=false"],  # a reach ends the episode unbootstrapped
}
CATEGORIES = ("randommix", "ditch", "hurdle", "gap", "forest")
D_SR, E_SR_MIX, E_SR_CAT = 50.0, 70.0, 50.0


def run_dir(args) -> Path:
    if args.out:
        return Path(args.out)
    # recipe v2's campaign is <robot>-s<seed>-v2: <robot>-s<seed> holds the v1 campaign,
    # which a v2 run must not resume
    tag = args.tag or (f"ab3-{args.arm}" if args.arm else "v2" if args.recipe == "v2" else "")
    return OUT / f"{args.robot}-s{args.seed}{'-' + tag if tag else ''}"


def train_config(args) -> tuple[list[str], object]:
    """(the campaign's own overrides, the composed training config) of a session."""
    init = args.init if args.init != "walker" else str(WALKER.get(args.robot, "none"))
    preset, recipe = RECIPES[args.recipe]
    extra = [f"algo.total_frames={args.frames}", f"algo.num_envs={args.envs}", *LEAN, *recipe,
             *ARMS.get(args.arm, []), f"init={init}"]
    return extra, own_body(args, compose_run(args.robot, args.seed, preset, "hike",
                                             [*extra, *args.overrides]))


def own_body(args, cfg):
    """``cfg`` with the feet the campaign's checkpoint trained on, when it has one: a
    campaign resumes, walk-tests and benchmarks on its own body."""
    ckpt = run_dir(args) / "oracle.pt"
    return with_checkpoint_body(cfg, ckpt) if ckpt.is_file() else cfg


def train(args) -> None:
    out = run_dir(args)
    out.mkdir(parents=True, exist_ok=True)
    (out / "snapshots").mkdir(exist_ok=True)
    extra, cfg = train_config(args)
    walk_env = eval_env(cfg, "randommix", True, args.walk_robots)
    frames_per_it = cfg.algo.num_envs * cfg.algo.steps_per_env
    session = Session(out, out / "oracle.pt", frames_per_it, args.minutes, args.eval_every,
                      [*extra, *args.overrides])

    def on_iteration(it: int, stats: dict, actor) -> bool:
        due, stop = session.iteration_done(it)
        if due:
            torch.save({"iteration": it, "frames": it * frames_per_it,
                        "minutes": session.minutes, "actor": actor.state_dict()},
                       out / "snapshots" / f"it{it:06d}.pt")
            row = {**session.stamp(it), **training_row(stats, cfg)}
            row.update({f"c_{k}": v for k, v in walk_test(walk_env, actor).items()})
            session.add_row(row)
            write_summary(out, args)
            print(f"[learn_hike] it {it} {row['minutes']:.1f} min: level {row['level_mean']:.2f}"
                  f", DR {row['randomization']:.2f}, (c) {row['c_walked_share']:.2f}", flush=True)
        session.resume_clock()
        return stop

    hint = " ".join(["python", *map(shlex.quote, sys.argv)])  # rerun: it resumes from out
    train_oracle(cfg, out, resume=session.resume, on_iteration=on_iteration, resume_hint=hint)
    write_summary(out, args)


# ----------------------------------------------------------------------------- benchmark
def bench_config(args):
    """The benchmark of (d) and (e): the hike map's five categories, levels 0-4, robots
    placed 2-10 m of path from the terminus (the protocol's default), randomisation on,
    30 s, ``--bench-robots`` robots per level (round-robin over the categories)."""
    init = [] if args.robot not in WALKER else LEAN[2:3]  # the critic size the actor needs
    preset, recipe = RECIPES[args.recipe]
    return own_body(args, compose_run(args.robot, args.seed, preset, "hike",
                                      [*init, *recipe, *bench_overrides(args), *args.overrides]))


def bench_overrides(args) -> list[str]:
    """The benchmark's eval settings (learn_student scores its students and their
    teachers with the same): ``--bench-robots`` per level, one run, two variants, levels
    0-4, randomisation on, seed 1000 + ``--seed``."""
    return [f"eval.robots={args.bench_robots}", "eval.runs=1", "eval.variants=2",
            "eval.levels=[0,1,2,3,4]", "eval.randomization=true",
            f"eval.seed={1000 + args.seed}"]


def bench_snapshot(env, actor) -> dict:
    """SR (%) per category over levels 0-4, per (category, level), and milestone columns."""
    outs = {}
    for level in range(5):
        rec = rollout_level(env, actor, level)
        for c in CATEGORIES:
            mine = rec.category == c
            outs[(c, level)] = (rec.outcomes.success[mine], rec.outcomes.fall[mine],
                                rec.outcomes.distance[mine])
    row = {}
    for c in CATEGORIES:
        succ = np.concatenate([outs[(c, lv)][0] for lv in range(5)])
        fell = np.concatenate([outs[(c, lv)][1] for lv in range(5)])
        row[f"sr_{c}"] = 100.0 * succ.mean()
        row[f"fr_{c}"] = 100.0 * fell.mean()
        row[f"dw_{c}"] = float(np.nanmean(np.concatenate([outs[(c, lv)][2] for lv in range(5)])))
        for lv in range(5):
            row[f"sr_{c}_l{lv}"] = 100.0 * outs[(c, lv)][0].mean()
    row["d_sr"] = float(np.mean([row[f"sr_randommix_l{lv}"] for lv in range(3)]))
    row["e_sr_mix"] = row["sr_randommix"]
    return row


def evaluate_snapshots(args) -> None:
    """Score every snapshot not yet in bench.csv (at least ``--bench-every`` training
    minutes after the last scored one, and always the newest)."""
    from legoh.eval.benchmark import make_eval_env
    from legoh.threads import torch_threads
    from legoh.train.oracle import build_oracle

    out = run_dir(args)
    rows = read_rows(out / "bench.csv")
    cfg = bench_config(args)
    env = make_eval_env(cfg)
    _, actor, _, _ = build_oracle(env, cfg)
    for _, snap in snapshots_to_score(out, rows, args.bench_every):
        actor.load_state_dict(snap["actor"])
        t0 = time.perf_counter()
        with torch_threads(1):
            row = {"iteration": snap["iteration"], "frames": snap["frames"],
                   "minutes": round(snap["minutes"], 2), **bench_snapshot(env, actor.eval())}
        rows.append(row)
        rows.sort(key=lambda r: r["iteration"])
        write_rows(out / "bench.csv", rows)
        write_summary(out, args)
        print(f"[learn_hike] bench it {row['iteration']} ({row['minutes']:.0f} min): (d) SR "
              f"{row['d_sr']:.0f} %, " + ", ".join(f"{c} {row[f'sr_{c}']:.0f}"
                                                   for c in CATEGORIES)
              + f" ({time.perf_counter() - t0:.0f} s)", flush=True)
    env.close()


# ----------------------------------------------------------------------------- records
def milestones(out: Path) -> dict:
    """First snapshot (frames, minutes) meeting each milestone, from the records."""
    found: dict[str, dict | None] = {"c": None, "d": None, "e": None}
    for r in read_rows(out / "evals.csv"):
        if found["c"] is None and r["c_walked_share"] >= 0.8:
            found["c"] = {"frames": int(r["frames"]), "minutes": r["minutes"]}
    for r in read_rows(out / "bench.csv"):
        stamp = {"frames": int(r["frames"]), "minutes": r["minutes"]}
        if found["d"] is None and r.get("d_sr", 0.0) >= D_SR:
            found["d"] = stamp
        cats = [r.get(f"sr_{c}", 0.0) for c in CATEGORIES[1:]]
        if found["e"] is None and r.get("e_sr_mix", 0.0) >= E_SR_MIX and min(cats) >= E_SR_CAT:
            found["e"] = stamp
    return found


def write_summary(out: Path, args) -> None:
    found = milestones(out)
    meta = {"robot": args.robot, "seed": args.seed, "milestones": found, "criteria": {
        "c": ">= 80 % of 16 robots walk >= 10 m toward the terminus without falling, "
             "RandomMix level 0, randomisation on, 30 s",
        "d": f"benchmark SR >= {D_SR:.0f} % on RandomMix levels 0-2, randomisation on",
        "e": f"SR >= {E_SR_MIX:.0f} % on RandomMix levels 0-4 and >= {E_SR_CAT:.0f} % on each "
             "of Ditch, Hurdle, Gap, Forest"}}
    (out / "milestones.json").write_text(json.dumps(meta, indent=2))
    lines = [f"# learn_hike: {args.robot}, seed {args.seed}", "", *milestone_lines(found)]
    (out / "summary.md").write_text("\n".join(lines) + "\n")
    plot(out)


def plot(out: Path) -> None:
    """Training levels and falls per category, randomisation, walk test, benchmark SR."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not (out / "evals.csv").exists():
        return
    e = read_evals(out)
    x = e["frames"] / 1e6
    fig, axes = plt.subplots(1, 4, figsize=(20, 4))
    plot_training(axes[:2], out, e["frames"][-1] / max(e["iteration"][-1], 1), CATEGORIES)
    axes[2].plot(x, 100 * e["c_walked_share"], "k", label="% walking >= 10 m")
    axes[2].plot(x, 10 * e["c_distance_m"], "k--", label="10 x m toward the terminus")
    axes[2].axhline(80, color="k", lw=0.5)
    bench = read_rows(out / "bench.csv")
    if bench:
        bx = np.array([r["frames"] for r in bench]) / 1e6
        axes[3].plot(bx, [r["d_sr"] for r in bench], "k", lw=2, label="(d) RandomMix 0-2")
        for i, c in enumerate(CATEGORIES):
            axes[3].plot(bx, [r.get(f"sr_{c}", np.nan) for r in bench], color=f"C{i}",
                         label=f"{c} 0-4")
        axes[3].axhline(D_SR, color="k", lw=0.5)
    mark_recipe_changes(out, axes)  # where a session changed the recipe
    titles = ["training: mean terrain level per category (25-iteration mean)",
              "training: falls / ended episodes per category (dotted: randomisation)",
              "(c) walk test, RandomMix L0 + randomisation", "benchmark SR (%), "
              "randomisation on"]
    finish_figure(fig, axes, titles, out / "curve.png")


def compare(args) -> Path:
    """``--compare TAG ...``: runs of ``--robot`` and ``--seed`` by tag (``-``: the untagged
    campaign) or by folder, side by side (:func:`campaign.compare_runs`), written beside the
    first run as ``<robot>-s<seed>-compare-<names>.{png,md}``."""
    base = f"{args.robot}-s{args.seed}"
    runs = [Path(t) if Path(t).is_dir() else OUT / (base if t == "-" else f"{base}-{t}")
            for t in args.compare]
    names = ["campaign" if t == "-" else Path(t).name for t in args.compare]
    return compare_runs(runs, runs[0].parent / f"{base}-compare-{'-'.join(names)}", "c",
                        "16 robots, RandomMix level 0, randomisation on, 30 s")


def make_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_campaign_arguments(parser, envs=512, scored="d, e")
    parser.add_argument("--recipe", choices=sorted(RECIPES), default="v2",
                        help="v2: the config's defaults (leap preset, support heights, ...); "
                             "v1: the shipped oracles' (conf/experiment/recipe_v1.yaml)")
    parser.add_argument("--init", default="walker",
                        help="walker (the committed learn_walk walker) | none | PATH")
    parser.add_argument("--arm", choices=list(ARMS), default=None,
                        help="an A/B arm: recipe v2 without one change (ARMS); its run "
                             "folder is <robot>-s<seed>-ab3-<arm> unless --tag is given")
    parser.add_argument("--compare", nargs="+", metavar="TAG",
                        help="draw these runs' walk tests side by side ('-': untagged)")
    return parser


def main() -> None:
    args = make_parser().parse_args()
    if args.compare:
        return compare(args)
    if args.plot:
        return write_summary(run_dir(args), args)
    if args.evaluate:
        return evaluate_snapshots(args)
    train(args)


if __name__ == "__main__":
    main()
