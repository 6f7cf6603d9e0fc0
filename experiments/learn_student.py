"""Learn to hike from vision: the unified student (stage 2) distilled from a hiking oracle,
as a campaign of sessions that each resume from the last one's committed checkpoint.

    python experiments/learn_student.py [--robot h1] [--seed 0] [--algo unified] [--minutes 85]
    python experiments/learn_student.py --evaluate [--robot h1] [--seed 0]   # (s2), (s3)
    python experiments/learn_student.py --plot [--robot h1] [--seed 0]
    python experiments/learn_student.py --compare - fast [--robot h1] [--seed 0]   # an A/B
    python experiments/learn_student.py --average 8 [--robot h1] [--seed 0]   # weights' mean

Teacher (``--teacher``): ``pretrained`` (default) is ``pretrained/<robot>_oracle.pt``; while
the repository ships none, the H1 hiking oracle of the learn_hike campaign,
``experiments/results/learn_hike/h1-s0/oracle.pt``, as committed when the session starts
(a line says so); or a path. The teacher is rebuilt from its own checkpoint (head, critic).
Its file's hash is part of each session's recipe (``sessions.csv``), so a newer teacher
shows on the curves where it took over.

Training trail (``--trail``, default ``hike``): RandomMix, Ditch, Hurdle, Gap and Forest in
one map, each robot its own category and level under the curriculum, as the oracle learned
(``--recipe``: learn_hike's, v2 by default, the shipped teachers' since 2026-12-06; v1 for
the students of the v1 oracles, e.g. to resume their campaigns). Why not flat, though
(s1) is a flat walk: the paper distils the unified policy on the hiking trails; the
teacher's labels are worth most on the terrain it learned; the curriculum starts every
robot on level 0, where RandomMix is nearly flat, so walking is learned first there anyway;
and a campaign keeps one trail (a checkpoint's curriculum belongs to its map), so (s1),
(s2) and (s3) are milestones of one run rather than of a flat run and a second one.

Every ``--eval-every`` training minutes the student's weights go to ``snapshots/``
(git-ignored) and the walk test of (s1) runs in-process with the student's depth env;
``--evaluate`` scores every snapshot not yet scored with the benchmark of learn_hike's
``--evaluate`` (the hike map, levels 0-4, robots 2-10 m of path from the terminus,
randomisation on, the same seeds), and the snapshot's teacher once, in a fresh env of the
same kind each (depth on, the oracle ignoring it: same terrain, spawns, commands and
draws until the policies' own falls and resets differ), cached in ``teacher.json``.
Milestones (frames and minutes of training; evaluation time excluded):

  (s1) >= 80 % of 16 robots walk >= 10 m toward the terminus on flat ground from depth,
       randomisation off, 30 s (learn_walk's walk test);
  (s2) benchmark SR >= 0.8 x the teacher's on RandomMix levels 0-2;
  (s3) benchmark SR >= 0.9 x the teacher's on each of the five categories (levels 0-4).
A ratio needs a teacher that succeeds: where the teacher's SR is 0 it is undefined and the
milestone is not reached (summary.md names the category).

Writes experiments/results/learn_student/<robot>-<algo>-s<seed>[-tag]/: <algo>.pt (the
checkpoint: commit it with ``git add -f``, results' *.pt are ignored), train.csv,
clock.csv (training minutes per iteration), sessions.csv (each start: iteration, commit,
recipe), evals.csv (walk tests), bench.csv (benchmark per snapshot, with the teacher's
numbers and the ratios), teacher.json, milestones.json, summary.md and curve.png.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
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
    smooth,
    snapshots_to_score,
    training_row,
    write_rows,
)
from learn_hike import CATEGORIES, RECIPES, bench_overrides, bench_snapshot  # noqa: E402
from learn_walk import ROBOTS, compose_run, read_evals, walk_env_settings, walk_test  # noqa: E402
from omegaconf import OmegaConf  # noqa: E402

from legoh.checkpoint import load_checkpoint, save_checkpoint  # noqa: E402
from legoh.eval.benchmark import BENCHMARK_VERSION, student_eval_env_fn  # noqa: E402
from legoh.eval.curves import read_columns  # noqa: E402
from legoh.policies.embodiment import LEGACY_FEET, with_checkpoint_body  # noqa: E402
from legoh.policies.oracle import load_teacher  # noqa: E402
from legoh.policies.pretrained import shipped_oracle  # noqa: E402
from legoh.policies.student import build_student, make_student_env, state_shapes  # noqa: E402
from legoh.runs import file_lock  # noqa: E402
from legoh.threads import torch_threads  # noqa: E402
from legoh.train.unified import train_student  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "experiments" / "results" / "learn_student"
# the teacher while pretrained/<robot>_oracle.pt is not shipped: the hiking campaign's oracle
HIKING_ORACLE = {"h1": ROOT / "experiments/results/learn_hike/h1-s0/oracle.pt"}
S1_SHARE, S2_RATIO, S3_RATIO = 0.8, 0.8, 0.9


def run_dir(args) -> Path:
    if args.out:
        return Path(args.out)
    return OUT / f"{args.robot}-{args.algo}-s{args.seed}{'-' + args.tag if args.tag else ''}"


def resolve_teacher(robot: str, teacher: str) -> Path:
    """``--teacher``: a path, or ``pretrained``: the robot's shipped oracle, else (said in
    a printed line) the hiking campaign's oracle."""
    if teacher != "pretrained":
        return Path(teacher)
    shipped = shipped_oracle(robot)
    if shipped is not None:
        return shipped
    fallback = HIKING_ORACLE.get(robot)
    if fallback is None or not fallback.is_file():
        raise SystemExit(f"[learn_student] no pretrained/{robot}_oracle.pt and no hiking "
                         f"oracle for {robot!r}: pass --teacher PATH")
    print(f"[learn_student] no pretrained/{robot}_oracle.pt yet: the teacher is {fallback} "
          f"(the learn_hike campaign's oracle, as committed now)", flush=True)
    return fallback


def file_hash(path: Path) -> str:
    """The first 12 hex digits of the file's SHA-256: which teacher, whatever its path."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:12]


def shown(path: Path) -> str:
    """``path`` relative to the repository when inside it (the same on every clone)."""
    path = Path(path).resolve()
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


def student_config(args, teacher: Path, trail: str, more: list[str]):
    """The stage-2 config of this campaign (``more`` after its recipe, before the user's
    overrides)."""
    # the teacher's recipe (``--recipe``: learn_hike's reward preset and overrides) in
    # training and benchmark alike
    return compose_run(args.robot, args.seed, RECIPES[args.recipe][0], trail,
                       [f"algo={args.algo}", f"algo.oracle_checkpoint={teacher}",
                        *RECIPES[args.recipe][1], *more, *args.overrides])


def train(args) -> None:
    out = run_dir(args)
    out.mkdir(parents=True, exist_ok=True)
    (out / "snapshots").mkdir(exist_ok=True)
    teacher = resolve_teacher(args.robot, args.teacher)
    sha = file_hash(teacher)
    recipe = [f"algo.total_frames={args.frames}", f"algo.num_envs={args.envs}"]
    cfg = student_config(args, teacher, args.trail, recipe)
    shapes = state_shapes(build_student(cfg))
    walk_cfg, walk_overrides = walk_env_settings(cfg, "flat", False)
    walk_env = make_student_env(walk_cfg, args.walk_robots, shapes, evaluation=True,
                                **walk_overrides)
    frames_per_it = cfg.algo.num_envs * cfg.algo.steps_per_env
    session = Session(out, out / f"{cfg.algo.name}.pt", frames_per_it, args.minutes,
                      args.eval_every, [f"algo={args.algo}", f"teacher={shown(teacher)}",
                                        f"teacher_sha={sha}", f"recipe={args.recipe}",
                                        *recipe, *args.overrides])

    def on_iteration(it: int, stats: dict, policy) -> bool:
        due, stop = session.iteration_done(it)
        if due:
            torch.save({"iteration": it, "frames": it * frames_per_it,
                        "minutes": session.minutes, "policy": policy.state_dict(),
                        "teacher": str(teacher), "teacher_sha": sha},
                       out / "snapshots" / f"it{it:06d}.pt")
            row = {**session.stamp(it), **training_row(stats, cfg),
                   "loss_action": stats.get("distill/loss_action", float("nan"))}
            row.update({f"s1_{k}": v for k, v in walk_test(walk_env, policy).items()})
            session.add_row(row)
            write_summary(out, args)
            print(f"[learn_student] it {it} {row['minutes']:.1f} min: level "
                  f"{row['level_mean']:.2f}, imitation {row['loss_action']:.3f}, (s1) "
                  f"{row['s1_walked_share']:.2f} walk {row['s1_distance_m']:.1f} m", flush=True)
        session.resume_clock()
        return stop

    hint = " ".join(["python", *map(shlex.quote, sys.argv)])  # rerun: it resumes from out
    train_student(cfg, out, resume=session.resume, on_iteration=on_iteration, resume_hint=hint)
    walk_env.close()
    write_summary(out, args)


# ----------------------------------------------------------------------------- benchmark
def bench_config(args, teacher: Path):
    """learn_hike's benchmark (its ``bench_overrides``) with this campaign's student: the
    student's settings (``algo``, ``env.depth``) from the run's checkpoint when there is
    one, so a campaign run with, e.g., ``algo.net=paper`` is scored with the same network
    (and ``robot.camera``: a student sees through the camera it learned with)."""
    cfg = student_config(args, teacher, "hike", bench_overrides(args))
    ckpt = run_dir(args) / f"{cfg.algo.name}.pt"
    if ckpt.is_file():
        trained = torch.load(ckpt, map_location="cpu", weights_only=False)["config"]
        algo = {**trained["algo"], "oracle_checkpoint": str(teacher)}
        # the camera and the feet it learned with (a config that stored no feet: source)
        cfg = OmegaConf.merge(cfg, {"algo": algo, "env": {"depth": trained["env"]["depth"]},
                                    "robot": {"camera": trained["robot"]["camera"],
                                              "feet_collider": trained["robot"].get(
                                                  "feet_collider", LEGACY_FEET)}})
    elif Path(teacher).is_file():  # no run yet: its teacher's feet
        cfg = with_checkpoint_body(cfg, teacher)
    return cfg


def bench_policy(make_env, policy) -> dict:
    """learn_hike's benchmark row of ``policy`` in a fresh env of ``make_env`` (seeded: every
    policy, the teacher included, meets the same terrain, spawns and draws)."""
    env = make_env(0)
    try:
        with torch_threads(1):
            return bench_snapshot(env, policy)
    finally:
        env.close()


def score_teacher(cfg, make_env, path: Path, cache: dict, sha: str,
                  siblings: Path | None = None) -> dict | None:
    """The teacher's benchmark row, ``cache``d by its file's hash, the protocol
    (``cfg.eval``) and the benchmark's code version (``BENCHMARK_VERSION``); None when the
    file at ``path`` is no longer the one the snapshot learned from. ``siblings``: a folder
    of run folders (``experiments/results/learn_student``) whose ``teacher.json`` rows under
    the same key are taken, not scored again (a new arm of a teacher spent 8 min on it)."""
    protocol = OmegaConf.to_container(cfg.eval, resolve=True)
    digest = hashlib.sha256(json.dumps(protocol, sort_keys=True).encode()).hexdigest()[:8]
    key = f"{sha} {digest} v{BENCHMARK_VERSION}"
    for other in sorted(siblings.glob("*/teacher.json")) if siblings is not None else ():
        if key not in cache:
            cache.update({k: v for k, v in json.loads(other.read_text()).items() if k == key})
    if key in cache:
        return cache[key]["row"]
    if not Path(path).is_file() or file_hash(path) != sha:
        print(f"[learn_student] teacher {sha} ({path}) is gone or changed: its snapshots get "
              f"no ratio", flush=True)
        return None
    probe = make_env(0)
    actor = load_teacher(cfg, path, probe)[0]
    probe.close()
    t0 = time.perf_counter()
    row = bench_policy(make_env, actor)
    cache[key] = {"teacher": shown(path), "eval": protocol, "row": row}
    print(f"[learn_student] teacher {path} ({sha}): RandomMix 0-2 SR {row['d_sr']:.0f} %, "
          + ", ".join(f"{c} {row[f'sr_{c}']:.0f}" for c in CATEGORIES)
          + f" ({time.perf_counter() - t0:.0f} s)", flush=True)
    return row


def teacher_row(cfg, make_env, out: Path, snap: dict) -> dict | None:
    """:func:`score_teacher` for ``snap``'s teacher, through the run folder's
    ``teacher.json``, under a lock on it: ``--evaluate`` and ``--average`` started together
    each scored a teacher missing from it (5 min of a core each); the second now waits and
    takes the first's row."""
    cache_path = out / "teacher.json"
    with file_lock(out / ".teacher.lock"):
        cache = json.loads(cache_path.read_text()) if cache_path.exists() else {}
        row = score_teacher(cfg, make_env, Path(snap["teacher"]), cache, snap["teacher_sha"],
                            out.parent)
        cache_path.write_text(json.dumps(cache, indent=2))
    return row


def ratios(row: dict, teacher: dict | None) -> dict:
    """The teacher's SRs and the student's ratios to them (NaN where the teacher's is 0)."""
    def ratio(mine: float, theirs: float) -> float:
        return mine / theirs if theirs > 0 else float("nan")

    out = {"teacher_d_sr": float("nan") if teacher is None else teacher["d_sr"]}
    out["s2_ratio"] = ratio(row["d_sr"], out["teacher_d_sr"])
    for c in CATEGORIES:
        out[f"teacher_sr_{c}"] = float("nan") if teacher is None else teacher[f"sr_{c}"]
        out[f"s3_ratio_{c}"] = ratio(row[f"sr_{c}"], out[f"teacher_sr_{c}"])
    # NaN when any category has none: (s3) asks for all five
    out["s3_ratio"] = float(np.min([out[f"s3_ratio_{c}"] for c in CATEGORIES]))
    return out


def snapshot_from_checkpoint(out: Path, algo: str, student) -> Path | None:
    """The committed checkpoint as a snapshot (``snapshots/it<iteration>.pt``), unless one
    of its iteration is there: snapshots are not committed, so on a fresh clone the
    checkpoint is the one state of the run left to score. Its minutes come from
    ``clock.csv``, its teacher from the last row of ``sessions.csv``; ``student`` (the
    campaign's, built from its config) takes the checkpoint's weights."""
    ckpt_path = out / f"{algo}.pt"
    if not ckpt_path.is_file():
        return None
    ckpt = torch.load(ckpt_path, map_location="cpu", weights_only=False)
    it = int(ckpt["iteration"])
    path = out / "snapshots" / f"it{it:06d}.pt"
    if path.exists():
        return path
    with open(out / "clock.csv", newline="") as f:
        minutes = {int(float(r["iteration"])): float(r["minutes"]) for r in csv.DictReader(f)}
    with open(out / "sessions.csv", newline="") as f:
        recipe = dict(item.split("=", 1) for item in list(csv.DictReader(f))[-1]["recipe"].split()
                      if item.startswith("teacher"))
    algo_cfg = ckpt["config"]["algo"]
    student.navigation.load_state_dict(ckpt["models"]["navigation"])
    student.locomotion.load_state_dict(ckpt["models"]["locomotion"])
    path.parent.mkdir(exist_ok=True)
    torch.save({"iteration": it, "frames": it * algo_cfg["num_envs"] * algo_cfg["steps_per_env"],
                "minutes": minutes[it], "policy": student.policy.state_dict(),
                "teacher": str(ROOT / recipe["teacher"]), "teacher_sha": recipe["teacher_sha"]},
               path)
    print(f"[learn_student] {shown(ckpt_path)} (iteration {it}, {minutes[it]:.1f} min) -> "
          f"{shown(path)}", flush=True)
    return path


def evaluate_snapshots(args) -> None:
    """Score every snapshot not yet in bench.csv (at least ``--bench-every`` training
    minutes after the last scored one, and always the newest), and its teacher once. The
    committed checkpoint counts as a snapshot (:func:`snapshot_from_checkpoint`)."""
    out = run_dir(args)
    rows = read_rows(out / "bench.csv")
    teacher = resolve_teacher(args.robot, args.teacher)
    cfg = bench_config(args, teacher)
    student = build_student(cfg)
    snapshot_from_checkpoint(out, args.algo, student)
    if not any((out / "snapshots").glob("it*.pt")):
        print(f"[learn_student] no snapshots in {out / 'snapshots'}")
        return
    make_env = student_eval_env_fn(cfg, student)  # the student's sensors, its state primed
    for _, snap in snapshots_to_score(out, rows, args.bench_every):
        theirs = teacher_row(cfg, make_env, out, snap)
        student.policy.load_state_dict(snap["policy"])
        t0 = time.perf_counter()
        row = bench_policy(make_env, student.policy.eval())
        row = {"iteration": snap["iteration"], "frames": snap["frames"],
               "minutes": round(snap["minutes"], 2), **row, **ratios(row, theirs)}
        rows.append(row)
        rows.sort(key=lambda r: r["iteration"])
        write_rows(out / "bench.csv", rows)
        write_summary(out, args)
        print(f"[learn_student] bench it {row['iteration']} ({row['minutes']:.0f} min): "
              f"RandomMix 0-2 SR {row['d_sr']:.0f} % (s2 ratio {row['s2_ratio']:.2f}), "
              + ", ".join(f"{c} {row[f'sr_{c}']:.0f}" for c in CATEGORIES)
              + f" ({time.perf_counter() - t0:.0f} s)", flush=True)


def average_snapshots(args) -> None:
    """``--average K``: the mean of the newest K snapshots' weights (stochastic weight
    averaging: torch's ``swa_utils.AveragedModel``), saved as a checkpoint
    ``snapshots/avg<first>-<last>.pt`` (:func:`save_average`) and benchmarked as
    ``--evaluate`` scores a snapshot. A row in ``bench_average.csv`` (the span averaged, the
    SRs, the ratios), printed beside the snapshots of that span already in bench.csv:
    whether averaging steadies a student whose hiking swings from one snapshot to the
    next."""
    out = run_dir(args)
    paths = sorted((out / "snapshots").glob("it*.pt"))[-args.average:]
    if args.average < 2 or len(paths) < args.average:
        raise SystemExit(f"--average {args.average}: needs at least 2 snapshots, and "
                         f"{out / 'snapshots'} holds {len(paths)}")
    snaps = [torch.load(p, map_location="cpu", weights_only=False) for p in paths]
    if len({s["teacher_sha"] for s in snaps}) > 1:
        raise SystemExit(f"--average {args.average}: the snapshots {paths[0].name}.."
                         f"{paths[-1].name} learned from different teachers")
    teacher = resolve_teacher(args.robot, args.teacher)
    cfg = bench_config(args, teacher)
    student = build_student(cfg)
    averaged = torch.optim.swa_utils.AveragedModel(student.policy, use_buffers=True)
    for snap in snaps:
        student.policy.load_state_dict(snap["policy"])
        averaged.update_parameters(student.policy)
    make_env = student_eval_env_fn(cfg, student)
    theirs = teacher_row(cfg, make_env, out, snaps[-1])
    student.policy.load_state_dict(averaged.module.state_dict())
    first, last = snaps[0], snaps[-1]
    saved = save_average(out / f"{args.algo}.pt", student, [s["iteration"] for s in snaps],
                         out / "snapshots" / f"avg{first['iteration']:06d}-"
                                             f"{last['iteration']:06d}.pt")
    row = bench_policy(make_env, student.policy.eval())
    row = {"snapshots": len(snaps), "first_iteration": first["iteration"],
           "iteration": last["iteration"], "frames": last["frames"],
           "first_minutes": round(first["minutes"], 2), "minutes": round(last["minutes"], 2),
           **row, **ratios(row, theirs)}
    rows = read_rows(out / "bench_average.csv") + [row]
    write_rows(out / "bench_average.csv", rows)
    span = [r for r in read_rows(out / "bench.csv")
            if first["iteration"] <= r["iteration"] <= last["iteration"]]

    def line(name: str, r: dict) -> str:
        return (f"{name}: RandomMix 0-2 SR {r['d_sr']:.0f} % (s2 ratio {r['s2_ratio']:.2f}), "
                + ", ".join(f"{c} {r[f'sr_{c}']:.0f}" for c in CATEGORIES))

    print(f"[learn_student] mean of {len(snaps)} snapshots, {first['minutes']:.0f}-"
          f"{last['minutes']:.0f} min -> {shown(saved)}, {shown(out / 'bench_average.csv')}")
    print("  " + line("averaged", row))
    for r in span:
        print("  " + line(f"snapshot {r['minutes']:.0f} min", r))
    if span:
        mean = {k: float(np.mean([r[k] for r in span])) for k in span[0]}
        print("  " + line(f"mean of these {len(span)}", mean))


def save_average(template: Path, student, iterations: list[int], path: Path) -> Path:
    """The averaged ``student`` as a checkpoint of its run (``template``'s config, robot,
    layout and critic; no optimiser or RNG states, as a shipped student): ``mode=play`` and
    ``mode=eval`` take it like any checkpoint (``checkpoint=PATH``), ``ship_pretrained.py
    --checkpoint PATH`` ships it."""
    state = load_checkpoint(template)  # verified: a damaged template is refused
    state = {k: v for k, v in state.items() if k not in ("optimizers", "rng")}
    state["models"] = {**state["models"], "navigation": student.navigation.state_dict(),
                       "locomotion": student.locomotion.state_dict()}
    state["iteration"] = iterations[-1]
    state["extra"] = {**state.get("extra", {}), "averaged": iterations}
    return save_checkpoint(path, state)


# ----------------------------------------------------------------------------- records
def milestones(out: Path) -> dict:
    """First snapshot (frames, minutes) meeting each milestone, from the records."""
    found: dict[str, dict | None] = {"s1": None, "s2": None, "s3": None}
    for r in read_rows(out / "evals.csv"):
        if found["s1"] is None and r["s1_walked_share"] >= S1_SHARE:
            found["s1"] = {"frames": int(r["frames"]), "minutes": r["minutes"]}
    for r in read_rows(out / "bench.csv"):
        stamp = {"frames": int(r["frames"]), "minutes": r["minutes"]}
        if found["s2"] is None and r["s2_ratio"] >= S2_RATIO:  # NaN: not reached
            found["s2"] = stamp
        if found["s3"] is None and r["s3_ratio"] >= S3_RATIO:
            found["s3"] = stamp
    return found


def write_summary(out: Path, args) -> None:
    found = milestones(out)
    meta = {"robot": args.robot, "seed": args.seed, "algo": args.algo, "milestones": found,
            "criteria": {
                "s1": f">= {S1_SHARE:.0%} of {ROBOTS} robots walk >= 10 m toward the terminus "
                      "without falling, flat, from depth, randomisation off, 30 s",
                "s2": f"benchmark SR >= {S2_RATIO} x the teacher's on RandomMix levels 0-2, "
                      "randomisation on",
                "s3": f"benchmark SR >= {S3_RATIO} x the teacher's on each of the five "
                      "categories, levels 0-4"}}
    (out / "milestones.json").write_text(json.dumps(meta, indent=2))
    lines = [f"# learn_student: {args.algo} on {args.robot}, seed {args.seed}", "",
             *milestone_lines(found)]
    bench = read_rows(out / "bench.csv")
    if bench:
        b = bench[-1]
        lines += ["", f"Last benchmark (iteration {int(b['iteration'])}, {b['minutes']:.1f} "
                  "min), SR % student / teacher:", "",
                  f"- RandomMix 0-2: {b['d_sr']:.0f} / {b['teacher_d_sr']:.0f}"
                  + none(b["teacher_d_sr"])]
        lines += [f"- {c} 0-4: {b[f'sr_{c}']:.0f} / {b[f'teacher_sr_{c}']:.0f}"
                  + none(b[f"teacher_sr_{c}"]) for c in CATEGORIES]
    (out / "summary.md").write_text("\n".join(lines) + "\n")
    plot(out)


def none(teacher_sr: float) -> str:
    """The note of a summary line whose ratio is undefined."""
    if np.isnan(teacher_sr):
        return " (the teacher could not be scored: no ratio)"
    return " (the teacher never succeeds: no ratio)" if teacher_sr == 0 else ""


def plot(out: Path) -> None:
    """Training levels and falls per category, imitation loss, (s1) walk test, the
    benchmark's ratios to the teacher."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not (out / "evals.csv").exists():
        return
    e = read_evals(out)
    x = e["frames"] / 1e6
    fig, axes = plt.subplots(1, 5, figsize=(25, 4))
    per_it = e["frames"][-1] / max(e["iteration"][-1], 1)
    plot_training(axes[:2], out, per_it, CATEGORIES)
    t = read_columns(out / "train.csv")
    for key, style in (("distill/loss_action", "k"), ("distill/loss_latent", "k--"),
                       ("distill/loss_priv_latent", "k:")):  # algo.history_latent only
        if key in t:
            axes[2].plot(t["iteration"] * per_it / 1e6, smooth(t[key]), style, label=key)
    axes[2].set_yscale("log")
    axes[3].plot(x, 100 * e["s1_walked_share"], "k", label="% walking >= 10 m")
    axes[3].plot(x, 10 * e["s1_distance_m"], "k--", label="10 x m toward the terminus")
    axes[3].axhline(100 * S1_SHARE, color="k", lw=0.5)
    bench = read_rows(out / "bench.csv")
    if bench:
        bx = np.array([r["frames"] for r in bench]) / 1e6
        axes[4].plot(bx, [r["s2_ratio"] for r in bench], "k", lw=2, label="(s2) RandomMix 0-2")
        for i, c in enumerate(CATEGORIES):
            axes[4].plot(bx, [r[f"s3_ratio_{c}"] for r in bench], color=f"C{i}",
                         label=f"{c} 0-4")
        axes[4].axhline(S2_RATIO, color="k", lw=0.5)
        axes[4].axhline(S3_RATIO, color="k", lw=0.5, ls=":")
    mark_recipe_changes(out, axes)
    titles = ["training: mean terrain level per category (25-iteration mean)",
              "training: falls / ended episodes per category",
              "training: imitation losses (25-iteration mean)",
              "(s1) walk test from depth, flat, randomisation off",
              "benchmark SR / the teacher's (randomisation on)"]
    finish_figure(fig, axes, titles, out / "curve.png")


def make_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_campaign_arguments(parser, envs=32, scored="s2, s3")
    parser.add_argument("--algo", default="unified",
                        help="unified | unified_ct | ep_h | rma_b | ... (conf/algo)")
    parser.add_argument("--teacher", default="pretrained",
                        help="pretrained (else the learn_hike oracle) | PATH")
    parser.add_argument("--trail", default="hike", help="training trail")
    parser.add_argument("--recipe", choices=sorted(RECIPES), default="v2",
                        help="the teacher's hiking recipe (learn_hike --recipe): v2, the "
                             "shipped oracles' since 2026-12-06; v1, the oracles before")
    parser.add_argument("--average", type=int, default=0, metavar="K",
                        help="benchmark the mean of the newest K snapshots' weights")
    parser.add_argument("--compare", nargs="+", metavar="TAG",
                        help="draw these runs' walk tests side by side ('-': untagged)")
    return parser


def compare(args) -> Path:
    """``--compare TAG ...``: runs of ``--robot``, ``--algo`` and ``--seed`` by tag (``-``:
    the untagged campaign) or by folder, side by side (:func:`campaign.compare_runs`),
    written beside the first as ``<robot>-<algo>-s<seed>-compare-<names>.{png,md}``."""
    base = f"{args.robot}-{args.algo}-s{args.seed}"
    runs = [Path(t) if Path(t).is_dir() else OUT / (base if t == "-" else f"{base}-{t}")
            for t in args.compare]
    names = ["campaign" if t == "-" else Path(t).name for t in args.compare]
    return compare_runs(runs, runs[0].parent / f"{base}-compare-{'-'.join(names)}", "s1",
                        "16 robots, flat ground from depth, randomisation off, 30 s")


def main() -> None:
    args = make_parser().parse_intermixed_args()  # overrides may come between options
    if args.compare:
        return compare(args)
    if args.plot:
        return write_summary(run_dir(args), args)
    if args.evaluate:
        return evaluate_snapshots(args)
    if args.average:
        return average_snapshots(args)
    train(args)


if __name__ == "__main__":
    main()
