"""What the learn_* campaigns share: a run folder's training clock across sessions and its
records (CSV rows, the sessions' recipes, the training log), for ``learn_hike.py`` and
``learn_student.py``.

A campaign is one command run again, session after session, on a fresh clone holding the
previous session's committed files (checkpoint, train.csv, clock.csv, evals.csv,
sessions.csv). :class:`Session` continues its clock from the checkpoint's iteration: the
minute ``clock.csv`` recorded for it, so the time a killed session spent after its last
checkpoint is not counted twice, and evaluation time is never counted.
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import time
from pathlib import Path

import numpy as np
import torch

from legoh.eval.curves import read_columns

ROOT = Path(__file__).resolve().parents[1]


class Session:
    """One session of a campaign in run folder ``out``: its records up to the checkpoint,
    its training clock (minutes, evaluation excluded) and when to evaluate and stop.

    Args:
        out: the run folder. checkpoint: the run's checkpoint (``oracle.pt``,
            ``unified.pt``): where the session resumes from when it exists.
        frames_per_iteration: env steps an iteration. minutes: this session's training
            budget. eval_every: training minutes between evaluations (the first session
            evaluates at its first iteration). recipe: the overrides, for ``sessions.csv``.
    """

    def __init__(self, out: Path, checkpoint: Path, frames_per_iteration: int, minutes: float,
                 eval_every: float, recipe: list[str]) -> None:
        self.out, self.checkpoint, self.frames_per_it = out, checkpoint, frames_per_iteration
        self.eval_every = 60.0 * eval_every
        it = (int(torch.load(checkpoint, map_location="cpu", weights_only=False)["iteration"])
              if checkpoint.exists() else 0)
        # a killed run: its records up to its checkpoint
        self.rows = [r for r in read_rows(out / "evals.csv") if r["iteration"] <= it]
        # the training clock of every iteration (clock.csv), so a resumed run continues from
        # its checkpoint's minute, not from the last evaluation's
        clocks = [r for r in read_rows(out / "clock.csv") if r["iteration"] <= it]
        write_rows(out / "clock.csv", clocks or [{"iteration": 0, "minutes": 0.0}])
        start = (clocks[-1]["minutes"] if clocks else
                 (self.rows[-1]["minutes"] if self.rows else 0.0))
        record_session(out, it, it * frames_per_iteration, start, recipe)
        self.start_iteration, self.train_s = it, 60.0 * start
        self.next_eval = self.train_s + (self.eval_every if self.rows else 0.0)
        self.end = self.train_s + 60.0 * minutes
        self.tick = time.perf_counter()

    @property
    def resume(self) -> str | None:
        """The checkpoint to resume from, None for a campaign's first session."""
        return str(self.checkpoint) if self.checkpoint.exists() else None

    def iteration_done(self, it: int) -> tuple[bool, bool]:
        """Count the time since the last call as training (and log it to ``clock.csv``);
        (evaluate now, stop now). Call :meth:`resume_clock` after the evaluation."""
        self.train_s += time.perf_counter() - self.tick
        with open(self.out / "clock.csv", "a") as f:
            f.write(f"{it},{self.train_s / 60.0:.4f}\n")
        stop = self.train_s >= self.end
        due = self.train_s >= self.next_eval or stop
        if due:
            self.next_eval += self.eval_every
        return due, stop

    def resume_clock(self) -> None:
        """Training time counts again from now (an evaluation's time is not training)."""
        self.tick = time.perf_counter()

    @property
    def minutes(self) -> float:
        return self.train_s / 60.0

    def stamp(self, it: int) -> dict:
        """Where iteration ``it`` stands: iteration, frames, training minutes."""
        return {"iteration": it, "frames": it * self.frames_per_it,
                "minutes": round(self.minutes, 2)}

    def add_row(self, row: dict) -> None:
        """An evaluation's row, appended to ``evals.csv``."""
        self.rows.append(row)
        write_rows(self.out / "evals.csv", self.rows)


def add_campaign_arguments(parser: argparse.ArgumentParser, envs: int, scored: str) -> None:
    """The options every campaign takes (``--envs``' default; ``scored``: the milestones
    ``--evaluate`` scores), and its Hydra overrides."""
    parser.add_argument("--robot", default="h1")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--minutes", type=float, default=85.0, help="training minutes now")
    parser.add_argument("--frames", type=int, default=500_000_000, help="frame budget")
    parser.add_argument("--envs", type=int, default=envs, help="algo.num_envs")
    parser.add_argument("--eval-every", type=float, default=6.0, help="training minutes")
    parser.add_argument("--tag", default="", help="suffix of the run folder (a variant)")
    parser.add_argument("--out", default="", help="run folder (default: experiments/results/"
                        "<campaign>/<robot>[-<algo>]-s<seed>[-tag])")
    parser.add_argument("--walk-robots", type=int, default=16, help="robots of the walk test")
    parser.add_argument("--plot", action="store_true", help="redraw curve and summary")
    parser.add_argument("--evaluate", action="store_true",
                        help=f"benchmark the snapshots not yet scored ({scored})")
    parser.add_argument("--bench-robots", type=int, default=80, help="robots per level")
    parser.add_argument("--bench-every", type=float, default=10.0,
                        help="training minutes between benchmarked snapshots")
    parser.add_argument("overrides", nargs="*", help="Hydra overrides")


def training_row(stats: dict, cfg) -> dict:
    """An iteration's training scalars for ``evals.csv``: episode length (s), falls among
    ended episodes, mean level, randomisation strength, level and falls per category."""
    return {"train_episode_s": stats["episode_frames"] * cfg.sim.dt * cfg.sim.decimation,
            "train_fell": stats["fell_frac"], "level_mean": stats["level_mean"],
            "randomization": stats.get("randomization", float("nan")),
            **{k: v for k, v in stats.items() if k.split("/")[0] in ("level", "fell")}}


def snapshots_to_score(out: Path, rows: list[dict], bench_every: float):
    """(path, snapshot) of each snapshot in ``out/snapshots`` not yet in ``rows`` (the
    scored ones), at least ``bench_every`` training minutes from every scored one (so a gap
    before the newest scored snapshot is filled too), and always the newest."""
    done = {int(r["iteration"]) for r in rows}
    scored = [r["minutes"] for r in rows]
    snaps = sorted((out / "snapshots").glob("it*.pt"))
    for i, path in enumerate(snaps):
        snap = torch.load(path, map_location="cpu", weights_only=True)
        newest = i == len(snaps) - 1
        far = all(abs(snap["minutes"] - m) >= bench_every for m in scored)
        if snap["iteration"] in done or not (far or newest):
            continue
        scored.append(snap["minutes"])
        yield path, snap


def milestone_lines(found: dict) -> list[str]:
    """summary.md's line per milestone: frames and minutes, or not reached."""
    return [f"- ({k}) " + ("not reached" if m is None else
                           f"{m['frames']:,} frames, {m['minutes']:.1f} min")
            for k, m in found.items()]


def finish_figure(fig, axes, titles: list[str], path: Path) -> None:
    """Titles, frames (M) on x, grids and legends; saved to ``path`` and closed."""
    import matplotlib.pyplot as plt

    for ax, title in zip(axes, titles, strict=True):
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("frames (M)")
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def git_commit() -> str:
    """This checkout's commit (short hash), or ``unknown`` outside a git repository."""
    return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                          capture_output=True, text=True).stdout.strip() or "unknown"


def record_session(out: Path, iteration: int, frames: int, minutes: float,
                   overrides: list[str]) -> None:
    """One row of ``sessions.csv`` per (re)start: where it started, the commit and the
    recipe (its overrides), so the curves can mark where a campaign's recipe changed."""
    commit = git_commit()
    path = out / "sessions.csv"
    new = not path.exists()
    with open(path, "a", newline="") as f:
        w = csv.writer(f)
        if new:
            w.writerow(["iteration", "frames", "minutes", "commit", "recipe"])
        # paths relative to the repository: each session runs on its own clone
        recipe = " ".join(overrides).replace(f"{ROOT}/", "")
        w.writerow([iteration, frames, round(minutes, 2), commit, recipe])


def recipe_changes(out: Path) -> list[tuple[float, str]]:
    """(frames, what changed) for each session whose recipe differs from the one before."""
    path = out / "sessions.csv"
    if not path.exists():
        return []
    with open(path) as f:
        rows = list(csv.DictReader(f))
    changes, before = [], None
    for r in rows:
        recipe = set(r["recipe"].split())
        if before is not None and recipe != before:
            changes.append((float(r["frames"]), " ".join(sorted(recipe - before))))
        before = recipe
    return changes


def mark_recipe_changes(out: Path, axes) -> None:
    """A vertical line on every axis where a session changed the recipe, the change
    written on the first."""
    for frames, what in recipe_changes(out):
        for ax in axes:
            ax.axvline(frames / 1e6, color="grey", ls="-.", lw=1)
        axes[0].annotate(what.replace(" ", "\n"), (frames / 1e6, axes[0].get_ylim()[1]),
                         fontsize=6, va="top", ha="right", color="grey")


def plot_training(axes, out: Path, frames_per_iteration: float, categories) -> None:
    """From ``train.csv`` (25-iteration means): the mean terrain level per category on
    ``axes[0]``, the falls among ended episodes per category and the randomisation strength
    on ``axes[1]``, against frames (M)."""
    t = read_columns(out / "train.csv")
    hole = np.flatnonzero(np.diff(t["iteration"]) > 1) + 1  # a session's rows lost
    t = {k: np.insert(v, hole, np.nan) for k, v in t.items()}  # NaN x: the line breaks
    tx = t["iteration"] * frames_per_iteration / 1e6
    for i, c in enumerate(categories):
        if f"level/{c}" in t:
            axes[0].plot(tx, smooth(t[f"level/{c}"]), color=f"C{i}", label=c)
            axes[1].plot(tx, smooth(t[f"fell/{c}"]), color=f"C{i}")
    axes[0].plot(tx, smooth(t["level_mean"]), "k--", label="all")
    if "randomization" in t:
        axes[1].plot(tx, t["randomization"], "k:", label="randomisation strength")


def read_rows(path: Path) -> list[dict]:
    """A CSV of numbers as rows of ints and floats ([] when the file does not exist). An
    integer cell stays an int: read as floats, a resumed run wrote its ``clock.csv`` and
    ``evals.csv`` back with iterations as ``2989.0``."""
    if not path.exists():
        return []
    with open(path) as f:
        return [{k: int(v) if v.lstrip("-").isdigit() else float(v) for k, v in r.items()}
                for r in csv.DictReader(f)]


def write_rows(path: Path, rows: list[dict]) -> None:
    """Rows to CSV, the union of their keys as columns (a missing cell: nan)."""
    fields = list(dict.fromkeys(k for r in rows for k in r))
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields, restval="nan")
        w.writeheader()
        w.writerows(rows)


def smooth(y: np.ndarray, k: int = 25) -> np.ndarray:
    """Running mean over ``k`` iterations, NaNs skipped."""
    k = max(1, min(k, len(y)))
    ok = np.isfinite(y)
    num = np.convolve(np.where(ok, y, 0.0), np.ones(k), "same")
    den = np.convolve(ok.astype(float), np.ones(k), "same")
    return np.where(den > 0, num / np.maximum(den, 1e-9), np.nan)


def compare_runs(runs: list[Path], stem: Path, test: str, test_title: str) -> Path:
    """One picture and table of several runs of a campaign script (A/B of a recipe or a
    loop): each walk test (``evals.csv``, columns ``<test>_walked_share``,
    ``<test>_distance_m``, ``<test>_fall_rate``) against training minutes and against
    frames (a faster loop shows on the first, a sample-efficiency cost on the second), the
    mean training level and training falls. Written as ``stem.{png,md}``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from learn_walk import read_evals

    missing = [str(r) for r in runs if not (r / "evals.csv").exists()]
    if missing:
        raise SystemExit(f"--compare: no evals.csv in {', '.join(missing)}")
    benches = [read_rows(r / "bench.csv") for r in runs]
    scored = all(rows and "d_sr" in rows[0] for rows in benches)
    by_category = all((r / "train.csv").exists() and (r / "clock.csv").exists() for r in runs)
    rows_needed = 1 + scored + by_category
    fig, grid = plt.subplots(rows_needed, 4, figsize=(20, 4 * rows_needed), squeeze=False)
    axes = grid[0]
    lines = ["| run | minutes | frames (M) | walking >= 10 m (%) | m toward the terminus | "
             "falls in the test (%) | mean level | training falls (%) | randomisation |",
             "|---|---|---|---|---|---|---|---|---|"]
    for i, run in enumerate(runs):
        e, c = read_evals(run), f"C{i}"
        for ax, x in ((axes[0], e["minutes"]), (axes[1], e["frames"] / 1e6)):
            ax.plot(x, 100 * e[f"{test}_walked_share"], color=c, label=run.name)
            ax.plot(x, 10 * e[f"{test}_distance_m"], "--", color=c)
        axes[2].plot(e["minutes"], e["level_mean"], color=c, label=run.name)
        axes[3].plot(e["minutes"], 100 * e["train_fell"], color=c, label=run.name)
        for j in range(len(e["minutes"])):
            lines.append(f"| {run.name} | {e['minutes'][j]:.1f} | {e['frames'][j] / 1e6:.2f} | "
                         f"{100 * e[f'{test}_walked_share'][j]:.0f} | "
                         f"{e[f'{test}_distance_m'][j]:.1f} | "
                         f"{100 * e[f'{test}_fall_rate'][j]:.0f} | {e['level_mean'][j]:.2f} | "
                         f"{100 * e['train_fell'][j]:.0f} | {e['randomization'][j]:.2f} |")
    panels = [("training minutes", f"({test}) walk test: % walking >= 10 m (dashed: 10 x m)"),
              ("frames (M)", f"({test}) the same against frames"),
              ("training minutes", "training: mean level"),
              ("training minutes", "training: falls / ended episodes (%)")]
    label_panels(axes, panels)
    for ax in axes[:2]:
        ax.axhline(80, color="k", lw=0.5)
    if scored:
        lines += bench_panels(grid[1], runs, benches)
    if by_category:
        lines += category_panels(grid[-1], runs)
    fig.tight_layout()
    fig.savefig(stem.with_suffix(".png"), dpi=90)
    plt.close(fig)
    stem.with_suffix(".md").write_text(
        f"# {', '.join(r.name for r in runs)}\n\nEach walk test ({test_title}) against "
        "training minutes" + (", then each benchmark (SR %, levels 0-4 unless said; the "
                              "teacher's in brackets)" if scored else "") + ".\n\n"
        + "\n".join(lines) + "\n", encoding="utf-8")
    print(stem.with_suffix(".md").read_text(encoding="utf-8"))
    return stem


BENCH_CATEGORIES = ("randommix", "ditch", "hurdle", "gap", "forest")


def category_panels(axes, runs: list[Path], smooth: int = 30) -> list[str]:
    """The training row of :func:`compare_runs`, from each run's train.csv against frames
    (an A/B compares per frame: its arms' minutes differ with what shares the cores): Gap
    and Hurdle training level (solid) and falls of their ended episodes (dotted), and the
    same for Ditch and Forest; a moving mean over ``smooth`` iterations. Returns the
    table's lines (means over the last ``smooth`` iterations)."""
    from legoh.eval.curves import read_columns

    def mean(x: np.ndarray) -> np.ndarray:
        x = np.where(np.isfinite(x), x, np.nan)
        kernel = np.ones(min(smooth, len(x)))
        valid = np.convolve(np.isfinite(x), kernel, "same")
        return np.convolve(np.nan_to_num(x), kernel, "same") / np.maximum(valid, 1)

    lines = ["", "| run | minutes | frames (M) | " + " | ".join(
        f"level {c} | fell {c} (%)" for c in BENCH_CATEGORIES) + " |",
        "|---|---|---" + "|---|---" * len(BENCH_CATEGORIES) + "|"]
    pairs = (("gap", "hurdle"), ("ditch", "forest"))
    for i, run in enumerate(runs):
        cols = read_columns(run / "train.csv")
        clock = dict(zip(*[read_columns(run / "clock.csv")[k] for k in ("iteration",
                                                                        "minutes")],
                         strict=True))
        minutes = np.array([clock.get(it, np.nan) for it in cols["iteration"]])
        evals = read_columns(run / "evals.csv")  # frames per iteration from the walk tests
        frames = cols["iteration"] * evals["frames"][-1] / evals["iteration"][-1] / 1e6
        for ax, cats in zip(axes, pairs, strict=False):
            for cat, style in zip(cats, ("-", ":"), strict=True):
                if f"level/{cat}" in cols:
                    ax.plot(frames, mean(cols[f"level/{cat}"]), style, color=f"C{i}",
                            label=f"{run.name} {cat}")
        for ax, cats in zip(axes[2:], pairs, strict=False):
            for cat, style in zip(cats, ("-", ":"), strict=True):
                if f"fell/{cat}" in cols:
                    ax.plot(frames, 100 * mean(cols[f"fell/{cat}"]), style, color=f"C{i}",
                            label=f"{run.name} {cat}")
        last = [(np.nanmean(cols.get(f"level/{c}", [np.nan])[-smooth:]),
                 100 * np.nanmean(cols.get(f"fell/{c}", [np.nan])[-smooth:]))
                for c in BENCH_CATEGORIES]
        lines.append(f"| {run.name}, training | {np.nanmax(minutes):.1f} | "
                     f"{np.nanmax(frames):.2f} | " + " | ".join(
            f"{lv:.2f} | {fl:.0f}" for lv, fl in last) + " |")
    label_panels(axes, [("frames (M)", "training level: gap (solid), hurdle (dotted)"),
                        ("frames (M)", "training level: ditch (solid), forest (dotted)"),
                        ("frames (M)", "training falls (%): gap, hurdle"),
                        ("frames (M)", "training falls (%): ditch, forest")])
    return lines


def bench_panels(axes, runs: list[Path], benches: list[list[dict]]) -> list[str]:
    """The benchmark row of :func:`compare_runs`: RandomMix 0-2 SR against minutes and
    frames (the teacher's dashed), Ditch SR and the five categories' mean SR against
    frames; returns the table's lines."""
    lines = ["", "| run | minutes | frames (M) | RandomMix 0-2 | "
             + " | ".join(BENCH_CATEGORIES) + " |", "|---" * (4 + len(BENCH_CATEGORIES)) + "|"]
    for i, (run, rows) in enumerate(zip(runs, benches, strict=True)):
        c = f"C{i}"
        minutes = np.array([r["minutes"] for r in rows])
        frames = np.array([r["frames"] for r in rows]) / 1e6
        d_sr = np.array([r["d_sr"] for r in rows])
        cats = np.array([[r.get(f"sr_{k}", np.nan) for k in BENCH_CATEGORIES] for r in rows])
        for ax, x in ((axes[0], minutes), (axes[1], frames)):
            ax.plot(x, d_sr, "o-", color=c, label=run.name)
            if "teacher_d_sr" in rows[0]:
                ax.plot(x, [r["teacher_d_sr"] for r in rows], "--", color=c, lw=0.8)
        axes[2].plot(frames, cats[:, 1], "o-", color=c, label=run.name)
        axes[3].plot(frames, cats.mean(1), "o-", color=c, label=run.name)
        for j, r in enumerate(rows):
            def cell(key: str, r=r) -> str:
                own, theirs = r.get(key, np.nan), r.get(f"teacher_{key}", np.nan)
                return f"{own:.0f}" + ("" if theirs != theirs else f" ({theirs:.0f})")
            lines.append(f"| {run.name} | {minutes[j]:.1f} | {frames[j]:.2f} | {cell('d_sr')} | "
                         + " | ".join(cell(f"sr_{k}") for k in BENCH_CATEGORIES) + " |")
    panels = [("training minutes", "benchmark: RandomMix 0-2 SR (%) (dashed: teacher)"),
              ("frames (M)", "benchmark: RandomMix 0-2 SR (%) against frames"),
              ("frames (M)", "benchmark: Ditch SR (%), levels 0-4"),
              ("frames (M)", "benchmark: mean SR of the five categories (%)")]
    label_panels(axes, panels)
    return lines


def label_panels(axes, panels: list[tuple[str, str]]) -> None:
    """Each axis its (x label, title) from ``panels``, a grid and a legend."""
    for ax, (xlabel, title) in zip(axes, panels, strict=True):
        ax.set_title(title, fontsize=9)
        ax.set_xlabel(xlabel)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
