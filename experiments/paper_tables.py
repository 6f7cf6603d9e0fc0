"""The paper's study at CPU scale: our numbers beside the appendix's Tables 1, 2, 3, 4 and 8.

    python experiments/paper_tables.py                     # write paper_tables.md from the studies
    python experiments/paper_tables.py --run --frames 100000 --eval-runs 3 [--seeds 0]
                                       [--parallel 2] [--eval-robots 400] [--minutes 45]
    python experiments/paper_tables.py --park   # before a session ends inside a job
    python experiments/paper_tables.py --reopen h1-unified-seed0,h1-unified-seed1  # budget up

Each paper table is answered by one study of ours (``legoh.eval.paper.PAPER_TABLES``):
Table 1 by ``ablation_temporal`` (GRU vs causal transformer), Table 2 by ``ablation_prior``
(HLM vs vanilla VAE; our third row, no prior, has no paper column), Table 3 by
``plugin_hlm`` (EP-H vs EP-H + HLM), Table 4 by ``robots`` (H1 vs G1) and Table 8 by
``table8`` (EP-H vs RMA-B per trail category). ``--run`` first runs every job those studies
compare, each once (LEGO-H on H1 answers four tables; 8 jobs a seed, not 11), one at a
time: ``run.py`` with the campaign's recipe (:func:`job_recipe`: learn_student's hike map,
the teacher's reward recipe, ``--recipe``, and curriculum; from scratch; scored on all five
categories, levels 0-4), the robot's shipped oracle teaching (read-only), the same
``--frames`` and ``--eval-runs`` (the std of our cells is over those runs, as the paper's is
over its 5); Hydra overrides after the options go to every job (e.g. the fast loop). Each
finished job's record (config, benchmark, training log, and ``record.json``: frames,
minutes, seed, commit, teacher and its hash, protocol, recipe) is copied to
``experiments/results/paper_jobs/<robot>-<algo>-seed<seed>/`` and committed, so a sweep
longer than a session resumes on a fresh clone: a recorded job is skipped (one recorded
with other settings is refused), a killed one resumes from its checkpoint in
``multirun/paper/``, or on a fresh clone from ``paper_jobs/<job>/unfinished/``, where a
sweep parks it for committing: at the end of ``--minutes`` (a session's training window: no
job starts after it, a job training at it checkpoints and is parked) or with ``--park``.
``--reopen <job>,...`` sends recorded jobs back to training when a probe's rule raises the
budget: each record moves to ``paper_budget/<job>-<F>M/`` (kept as the budget's evidence),
and the job's checkpoint is parked, so the next ``--run --frames <more>`` resumes it.
The studies' tables are then written from the records, each once all its jobs are
recorded (until then it keeps its last complete table). Without ``--run`` the tables are
read from ``experiments/results/<study>/table.csv``; a study not run yet is listed with the
command that runs it.

Per metric the two methods are ordered in the paper and in ours (``ordering``: better,
worse, or a tie when the means lie within one std); "agree" says whether the orderings
match where both separate the methods. Writes experiments/results/paper_tables.md.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "experiments"))

from campaign import git_commit  # noqa: E402
from learn_hike import RECIPES  # noqa: E402

from legoh.eval.metrics import HIGHER_IS_BETTER, METRICS, column_title  # noqa: E402
from legoh.eval.paper import MAIN, PAPER_TABLES, PaperTable, ordering  # noqa: E402
from legoh.eval.study import read_study_csv, study_grid, study_table  # noqa: E402

RESULTS = ROOT / "experiments" / "results"
JOBS = RESULTS / "paper_jobs"  # each job's record, committed: a later session skips the job
BUDGET = RESULTS / "paper_budget"  # probes' records at a budget the study moved past
RUNS = ROOT / "multirun" / "paper"  # the jobs' run folders (checkpoints: not committed)
UNFINISHED = "unfinished"  # paper_jobs/<job>/unfinished/: a parked job (park), committed
# a session's training window for the sweep (the brief's ~90 minutes) and the jobs at once
# on this machine's 2 cores: what the page's command and its estimate of what is left assume
WINDOW_MINUTES, PARALLEL = 88, 2
RECORD = (".hydra/config.yaml", "benchmark.csv", "benchmark_runs.csv", "train.csv")
# Every job trains as learn_student's campaign does (the hike map, its teacher's reward
# recipe and curriculum) and is scored on all five categories, levels 0-4; no video.
# ``--recipe``: v2 (the shipped oracles' since 2026-12-06, the default camera) or v1 (the
# committed 600k-frame jobs': the v1 teachers, the 30-degree camera they learned with).
# Every job from scratch (init=none: the default would start LEGO-H from the shipped
# student and the baselines from nothing)
CAMERA = {"v1": ["robot.camera.pitch_deg=30"], "v2": []}


def job_recipe(recipe: str) -> list[str]:
    """The overrides every job of a sweep under ``recipe`` trains and is scored with."""
    preset, extra = RECIPES[recipe]
    return ["trail=hike", f"env.reward_preset={preset}", *extra, "eval.levels=[0,1,2,3,4]",
            "video=false", *CAMERA[recipe], "init=none"]


NAN = (float("nan"), float("nan"))


def cell(value: tuple[float, float]) -> str:
    mean, std = value
    return "–" if mean != mean else f"{mean:.2f} ± {std:.2f}"


def agreement(paper: str, ours: str) -> str:
    if "?" in (paper, ours):
        return "–"
    if "=" in (paper, ours):
        return "tie" if ours == "=" else "paper ties"
    return "yes" if paper == ours else "no"


def compare(spec: PaperTable, numbers: dict, ours: dict) -> tuple[list[str], dict[str, int]]:
    """Markdown rows of one (category's) comparison and the count of each agreement."""
    (a, b), labels = spec.columns, list(spec.columns.values())
    head = ["metric", f"paper {a}", f"ours {a}", f"paper {b}", f"ours {b}", "paper",
            "ours", "agree"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    counts: dict[str, int] = {}
    for metric in numbers[a]:
        p = (numbers[a][metric], numbers[b][metric])
        o = tuple(ours.get(label, {}).get(metric, NAN) for label in labels)
        po, oo = (ordering(*p, HIGHER_IS_BETTER[metric]), ordering(*o, HIGHER_IS_BETTER[metric]))
        agree = agreement(po, oo)
        counts[agree] = counts.get(agree, 0) + 1
        lines.append(f"| {column_title(metric)} | {cell(p[0])} | {cell(o[0])} | {cell(p[1])} "
                     f"| {cell(o[1])} | {po} | {oo} | {agree} |")
    return lines, counts


def study_frames(folder: Path) -> set[int]:
    """Stage-2 frames of the jobs behind a study's table (its ``summary.json``)."""
    path = folder / "summary.json"
    if not path.is_file():
        return set()
    groups = json.loads(path.read_text(encoding="utf-8")).get("groups", {})
    return {int(job["frames"]) for jobs in groups.values() for job in jobs if "frames" in job}


def study_command(frames: int | None, eval_runs: int, seeds: list[int], recipe: str = "v2",
                  eval_robots: int | None = None, tables: list[str] | None = None) -> str:
    """The ``--run`` command of a study with these settings, every one spelled out, so a
    page's reader reruns (or resumes) the same sweep."""
    parts = ["python experiments/paper_tables.py --run", f"--recipe {recipe}",
             f"--frames {frames or 'F'}", f"--eval-runs {eval_runs}"]
    if eval_robots is not None:
        parts.append(f"--eval-robots {eval_robots}")
    parts.append("--seeds " + ",".join(map(str, seeds)))
    if tables:
        parts.append("--tables " + " ".join(tables))
    return " ".join(parts)


def section(spec: PaperTable, frames: int | None, command: str) -> tuple[list[str], dict]:
    """A paper table's page section; ``command``: :func:`study_command` of the sweep."""
    path = RESULTS / spec.study / "table.csv"
    run = f"`{command}`"
    lines = [f"## {spec.title}", ""]
    if not path.is_file():
        return lines + [f"Not run yet: {run}.", ""], {}
    table = read_study_csv(path)
    lines += [f"Ours: `experiments/results/{spec.study}/` ({run}; its `table.md` says the "
              "frames, seeds and evaluation runs). Orderings: `>` the first column is "
              "better, `<` the second, `=` within one std.", ""]
    had = study_frames(RESULTS / spec.study)
    if frames and had and had != {frames}:
        lines += [f"**Not this budget**: the table's jobs trained {', '.join(map(str, had))} "
                  f"frames each, not {frames}; `--run` replaces it once its jobs are "
                  "recorded. Older tables predate the walking teacher: not evidence.", ""]
    total: dict[str, int] = {}
    groups = spec.numbers.items() if spec.per_category else [("overall", spec.numbers)]
    for category, numbers in groups:
        if spec.per_category:
            lines += [f"**{category}**", ""]
        rows, counts = compare(spec, numbers, table.get(category, {}))
        lines += rows + [""]
        for k, v in counts.items():
            total[k] = total.get(k, 0) + v
    lines += [summary_line(total), ""]
    return lines, total


def job_state(name: str, jobs: Path | None = None) -> tuple[str, int, float, dict]:
    """(state, frames trained, training minutes, ``{row: SR}``) of job ``name`` from what
    is committed under ``jobs`` (default :data:`JOBS`): ``recorded`` (its ``record.json``
    and benchmark), ``parked`` (``unfinished/``: its log's last iteration and minutes) or
    ``not started``."""
    from legoh.eval.study import read_rows

    folder = (jobs or JOBS) / name
    if (folder / "record.json").is_file() and (folder / "benchmark.csv").is_file():
        info = json.loads((folder / "record.json").read_text(encoding="utf-8"))
        rows = read_rows(folder / "benchmark.csv")
        return ("recorded", int(info["frames"]), float(info["minutes"]),
                {row: value["SR"][0] for row, value in rows.items()})
    parked = folder / UNFINISHED
    if (parked / "train.csv").is_file() and (parked / ".hydra" / "config.yaml").is_file():
        batch = batch_frames(parked / ".hydra" / "config.yaml")
        with open(parked / "train.csv", newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
        last = int(rows[-1]["iteration"]) if rows else 0
        return "parked", last * batch, training_minutes(rows, batch), {}
    return "not started", 0, 0.0, {}


PROGRESS_ROWS = ("overall", "randommix", "ditch", "hurdle", "gap", "forest")


def progress_section(seeds: list[int], frames: int | None, jobs: Path | None = None,
                     command: str | None = None) -> list[str]:
    """Where the sweep stands: every job of the six tables at ``seeds`` (and at the seeds
    of the jobs already under ``jobs``), its state (:func:`job_state`), and a recorded
    job's SR overall and per category, so a reader sees the study before its tables;
    ``command`` (:func:`study_command`): the one that goes on with it. Draws the jobs'
    training (:func:`curves_figure`) to ``curves.png`` beside them."""
    folder = jobs or JOBS
    on_disk = {int(p.name.rsplit("-seed", 1)[1]) for p in folder.glob("*-seed*")
               if p.name.rsplit("-seed", 1)[1].isdigit()}
    planned = planned_jobs(PAPER_TABLES, sorted(set(seeds) | on_disk), main=True)
    states = {name: job_state(name, folder) for name in planned}
    done = sum(state == "recorded" for state, *_ in states.values())
    budget = f"{frames / 1e6:g}M frames a job" if frames else "the budget its record states"
    lines = ["## Where the sweep stands", "",
             f"{done} of {len(planned)} jobs recorded at {budget}; a table is written once "
             "all its jobs are recorded. Parked jobs resume from `paper_jobs/<job>/"
             "unfinished/`. Training minutes on this machine's 2 cores (two jobs at once "
             "share them). SR (%) on protocol v2, one run of the job's robots a level."
             + (f" The sweep goes on with `{command} --parallel {PARALLEL} --minutes "
                f"{WINDOW_MINUTES}` (a session's window on both cores)." if command else ""),
             "",
             "| job | state | frames | training min | " + " | ".join(
                 f"SR {row}" for row in PROGRESS_ROWS) + " |",
             "|" + "---|" * (4 + len(PROGRESS_ROWS))]
    for name, (state, trained, minutes, sr) in states.items():
        cells = [f"{sr[row]:.1f}" if row in sr else "–" for row in PROGRESS_ROWS]
        lines.append(f"| {name} | {state} | {trained / 1e6:.2f}M | {minutes:.0f} | "
                     + " | ".join(cells) + " |")
    lines.append("")
    if frames:
        lines += [pace_line(list(states.values()), frames), ""]
    figure = folder / "curves.png"
    if curves_figure(list(states), figure, folder):
        lines += ["Each recorded or parked job in training (its `train.csv`):", "",
                  f"![the study's jobs in training]({figure.relative_to(folder.parent)})", ""]
    return lines


# the training numbers the sweep's figure sets side by side: (train.csv column, panel title)
CURVES = (("distill/loss_action", "imitation loss (actions)"),
          ("fell_frac", "falls (share of ended episodes)"),
          ("episode_metres", "metres an episode"), ("level_mean", "curriculum level"))


def job_log(name: str, jobs: Path | None = None) -> dict[str, np.ndarray] | None:
    """A recorded or parked job's training columns (``legoh.eval.curves.read_columns``)
    and frames, from its committed ``train.csv`` and config; None for a job with neither or
    with no row."""
    folder = (jobs or JOBS) / name
    for where in (folder, folder / UNFINISHED):
        log, config = where / "train.csv", where / ".hydra" / "config.yaml"
        if log.is_file() and config.is_file():
            break
    else:
        return None
    from legoh.eval.curves import read_columns

    cols = read_columns(log)
    if not cols:  # parked before its first iteration
        return None
    cols["frames"] = cols["iteration"] * batch_frames(config)
    return cols


def running_mean(y: np.ndarray, n: int) -> np.ndarray:
    """The mean of each ``n`` consecutive values of ``y`` that are logged: an iteration
    without an ended episode logs NaN falls and metres, which count as missing, not 0."""
    kernel = np.ones(max(1, min(n, len(y))))
    seen = np.isfinite(y)
    with np.errstate(invalid="ignore"):
        return (np.convolve(np.where(seen, y, 0.0), kernel, mode="valid")
                / np.convolve(seen, kernel, mode="valid"))


def curves_figure(names: list[str], out: Path, jobs: Path | None = None,
                  smooth: int = 100) -> list[str]:
    """The training numbers of the jobs ``names`` that have a log (recorded or parked),
    one colour a method, one line style a seed, each a running mean over ``smooth``
    iterations against frames; written to ``out``. Returns the jobs drawn."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    logs = {name: log for name in names if (log := job_log(name, jobs)) is not None}
    if not logs:
        return []
    methods = sorted({name.rsplit("-seed", 1)[0] for name in logs})
    colour = {m: plt.get_cmap("tab10")(i % 10) for i, m in enumerate(methods)}
    fig, axes = plt.subplots(1, len(CURVES), figsize=(4.2 * len(CURVES), 3.4))
    for ax, (key, title) in zip(axes, CURVES, strict=True):
        for name, log in logs.items():
            if key not in log:
                continue
            method, seed = name.rsplit("-seed", 1)
            mean = running_mean(log[key], smooth)
            ax.plot(log["frames"][len(log[key]) - len(mean):] / 1e6, mean, color=colour[method],
                    ls="-" if seed == "0" else "--", lw=1.1, label=f"{method} s{seed}")
        ax.set_title(title, fontsize=10)
        ax.set_yscale("log" if key == CURVES[0][0] else "linear")
        ax.set_xlabel("frames (M)", fontsize=9)
        ax.grid(alpha=0.3)
    # the legend of the panel with the most lines (a job may not log every column)
    axes[0].legend(*max((ax.get_legend_handles_labels() for ax in axes),
                        key=lambda drawn: len(drawn[0])), fontsize=7)
    fig.suptitle(f"the study's jobs in training (running mean of {smooth} iterations)")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return list(logs)


def pace_line(states: list[tuple], frames: int, window: float = WINDOW_MINUTES,
              parallel: int = PARALLEL) -> str:
    """Frames the sweep has left at ``frames`` a job, and the windows of ``window`` minutes
    they take at the pace of the jobs trained so far (their frames over their training
    minutes, ``parallel`` jobs at once): an estimate for planning sessions."""
    left = sum(max(0, frames - trained) for _, trained, *_ in states)
    trained = sum(t for _, t, *_ in states)
    minutes = sum(m for _, _, m, _ in states)
    text = f"Left: {left / 1e6:.1f}M frames"
    if trained and minutes:
        pace = trained / minutes  # frames a training minute, a job
        windows = left / (pace * parallel * window)
        text += (f"; at the pace so far ({pace / 1e3:.0f}k frames a training minute a job, "
                 f"{parallel} jobs at once) ~{windows:.0f} windows of {window:.0f} minutes "
                 "(plus each job's benchmark)")
    return text + "."


def summary_line(counts: dict[str, int]) -> str:
    told = counts.get("yes", 0) + counts.get("no", 0)
    return (f"Where both separate the methods the orderings agree in {counts.get('yes', 0)} "
            f"of {told} metrics; ours ties in {counts.get('tie', 0)}, the paper in "
            f"{counts.get('paper ties', 0)}; {counts.get('–', 0)} without a value.")


def planned_jobs(specs, seeds: list[int], main: bool = False,
                 only: list[str] | None = None) -> dict[str, tuple[str, str, int]]:
    """``{job: (robot, algo, seed)}``: every job the studies of ``specs`` (and with ``main``
    the main comparison's, :data:`MAIN`) compare, each once (LEGO-H on H1 is in five
    studies, EP-H in three). ``only``: keep the jobs named ``<robot>-<algo>`` in it (a
    budget probe runs LEGO-H alone before the rest may start at that budget)."""
    grids = [study_grid(spec.study) for spec in specs]
    if main:
        grids.append(main_grid())
    jobs = {}
    for grid in grids:
        for robot in grid["robot.name"]:
            for algo in grid["algo.name"]:
                for seed in seeds:
                    jobs.setdefault(f"{robot}-{algo}-seed{seed}", (robot, algo, seed))
    if only is not None:
        unknown = sorted(set(only) - {f"{r}-{a}" for r, a, _ in jobs.values()})
        if unknown:
            valid = sorted({f"{r}-{a}" for r, a, _ in jobs.values()})
            raise SystemExit(f"[paper_tables] --jobs {','.join(unknown)}: valid are "
                             f"{', '.join(valid)}")
        jobs = {k: v for k, v in jobs.items() if f"{v[0]}-{v[1]}" in only}
    return jobs


def unrecorded(grid: dict[str, list[str]], seeds: list[int]) -> list[str]:
    """The jobs of a study's ``grid`` at ``seeds`` with no record in ``paper_jobs/`` yet: its
    table waits for them, since a table from some of its jobs would replace a complete one
    (a sweep with ``--minutes`` leaves jobs to later sessions)."""
    return [f"{robot}-{algo}-seed{seed}" for robot in grid["robot.name"]
            for algo in grid["algo.name"] for seed in seeds
            if not (JOBS / f"{robot}-{algo}-seed{seed}" / "benchmark.csv").is_file()]


def main_grid() -> dict[str, list[str]]:
    """The main comparison's jobs: H1, its four students (the ``benchmark`` sweep's oracle
    job is stage 1: here the shipped oracle teaches every student)."""
    return {"robot.name": ["h1"], "algo.name": list(MAIN.methods.values())}


def main_section(command: str) -> list[str]:
    """The main comparison's page section: per category (overall first) each method's
    published value (where we have one) beside ours, and our ordering of LEGO-H against
    each baseline per metric. ``command``: :func:`study_command` of the sweep."""
    path = RESULTS / MAIN.study / "table.csv"
    lines = [f"## {MAIN.title}", ""]
    if not path.is_file():
        return lines + [f"Not run yet: `{command} --tables main`.", ""]
    table = read_study_csv(path)
    names = list(MAIN.methods)
    lines += [f"Ours: `experiments/results/{MAIN.study}/` (its `table.md` says the frames, "
              "seeds and evaluation runs). Published: Table 8's EP-H and RMA-B per category "
              "(its own protocol), Table 4's LEGO-H overall; `–` where the paper's value is "
              "not in our notes. Last column: our LEGO-H against each baseline (`>` LEGO-H "
              "better, `<` worse, `=` within one std).", ""]
    head = ["metric"] + [f"{who} {n}" for n in names for who in ("paper", "ours")] + [
        "ours: LEGO-H vs " + " / ".join(names[1:])]
    for category in ["overall", *[c for c in table if c != "overall"]]:
        ours = {n: table.get(category, {}).get(MAIN.methods[n], {}) for n in names}
        paper = MAIN.numbers.get(category, {})
        lines += [f"**{category}**", "", "| " + " | ".join(head) + " |",
                  "|" + "---|" * len(head)]
        for metric in METRICS:  # ours has DW and FR too: no paper column
            cells = [cell(c.get(n, {}).get(metric, NAN)) for n in names
                     for c in (paper, ours)]
            lead = ours[names[0]].get(metric, NAN)
            orders = [ordering(lead, ours[n].get(metric, NAN), HIGHER_IS_BETTER[metric])
                      for n in names[1:]]
            lines.append(f"| {column_title(metric)} | " + " | ".join(cells)
                         + f" | {' / '.join(orders)} |")
        lines.append("")
    return lines


def run_job(name: str, robot: str, algo: str, seed: int, frames: int, eval_runs: int,
            overrides: list[str], log: Path | None = None, recipe: str = "v2",
            eval_robots: int | None = None, deadline: float | None = None) -> Path | None:
    """Train and benchmark one job (``run.py`` in ``multirun/paper/<job>``, resumed from its
    checkpoint if a killed run left one there or :func:`park` left one in
    ``paper_jobs/<job>/unfinished/``), then copy its record to ``paper_jobs/<job>`` with
    ``record.json`` (:func:`write_record`). A job recorded already is skipped, unless it was
    run with other frames, evaluation runs or robots (``eval_robots``; None: not checked)
    or recipe: refused, naming them (a record without ``record.json`` predates it: recipe
    v1). ``deadline`` (``time.time()``; None: none) is the sweep's window: a job starts only
    before it, and one still training at it is stopped and parked (:func:`launch`,
    :func:`park_job`); None is returned for a job left for a later session. ``log``: the
    job's console goes to that file (parallel jobs), else to this one."""
    record = JOBS / name
    if (record / "benchmark.csv").is_file():
        want = {"algo.total_frames": frames, "eval.runs": eval_runs, "recipe": recipe}
        if eval_robots is not None:
            want["eval.robots"] = eval_robots
        recorded = recorded_settings(record)
        done = {k: recorded[k] for k in want}
        if done != want:
            raise SystemExit(
                f"[paper_tables] {record} was run with "
                + ", ".join(f"{k}={v}" for k, v in done.items()) + "; this sweep asks "
                + ", ".join(f"{k}={v}" for k, v in want.items())
                + ": move the record aside (git mv) or pass its settings")
        print(f"[paper_tables] {name}: recorded already ({record})", flush=True)
        return record
    out = RUNS / name
    if not (out / "benchmark.csv").is_file():
        if deadline is not None and time.time() > deadline:
            print(f"[paper_tables] {name}: not started, --minutes are spent (a later "
                  "session runs it)", flush=True)
            return None
        unpark(record / UNFINISHED, out, algo)
        robots = [] if eval_robots is None else [f"eval.robots={eval_robots}"]
        cmd = [sys.executable, str(ROOT / "run.py"), f"robot={robot}", f"algo={algo}",
               f"seed={seed}", *job_recipe(recipe), f"algo.total_frames={frames}",
               f"eval.runs={eval_runs}", *robots, *overrides, f"hydra.run.dir={out}"]
        checkpoint = out / f"{algo}.pt"
        if checkpoint.is_file():
            cmd.append(f"resume={checkpoint}")
        print("[paper_tables]", " ".join(cmd), flush=True)
        if not launch(cmd, log, deadline, lambda: trained_all(out, frames)):
            park_job(out, record / UNFINISHED, algo)
            return None
        print(f"[paper_tables] {name}: done", flush=True)
    for rel in RECORD:
        if (out / rel).is_file():
            (record / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(out / rel, record / rel)
    write_record(record, out / f"{algo}.pt", recipe)
    shutil.rmtree(record / UNFINISHED, ignore_errors=True)  # the finished record replaces it
    return record


def batch_frames(config: Path) -> int:
    """Frames an iteration collects (``num_envs`` x ``steps_per_env``) in the run whose
    Hydra ``config.yaml`` this is."""
    from omegaconf import OmegaConf

    algo = OmegaConf.load(config).algo
    return int(algo.num_envs) * int(algo.steps_per_env)


def training_minutes(rows: list[dict], batch: int) -> float:
    """Training minutes of a run's ``train.csv`` rows: each iteration's batch over its
    frames/s (evaluation excluded)."""
    return sum(batch / float(r["frames_per_s"]) for r in rows if r["frames_per_s"]) / 60


def trained_all(out: Path, frames: int) -> bool:
    """Whether the job in ``out`` has trained its ``frames`` (it is evaluating now): the
    last iteration of its ``train.csv`` against its config's batch, as run.py counts them."""
    log, config = out / "train.csv", out / ".hydra" / "config.yaml"
    if not (log.is_file() and config.is_file()):
        return False
    iterations = max(1, frames // batch_frames(config))
    with open(log, "rb") as f:
        f.seek(max(0, f.seek(0, 2) - 65536))  # the last rows are enough
        rows = [r for r in f.read().decode("utf-8", "replace").splitlines() if r.strip()]
    last = rows[-1].split(",", 1)[0] if rows else ""
    return last.isdigit() and int(last) >= iterations


# what a killed job needs to resume on a fresh clone: its checkpoint, the training log the
# resumed run appends to, and the config it ran with
PARKED = ("train.csv", ".hydra/config.yaml")


def launch(cmd: list[str], log: Path | None, deadline: float | None,
           evaluating: Callable[[], bool] | None = None) -> bool:
    """Run a job's ``cmd`` to its end (True), or until ``deadline`` (``time.time()``): then
    SIGTERM, on which run.py finishes its iteration and writes its checkpoint
    (``legoh.runs.GracefulStop``), and False. A job whose ``evaluating()`` is true at the
    deadline has trained all its frames and is scoring them: it runs to its end (True), as
    a SIGTERM would kill the benchmark and throw away up to half an hour of it. A failed
    job raises ``CalledProcessError``. ``log``: the console goes to that file, else to
    this one."""
    stream = None
    if log is not None:
        log.parent.mkdir(parents=True, exist_ok=True)
        stream = open(log, "a", encoding="utf-8")  # noqa: SIM115 (closed below)
    try:
        proc = subprocess.Popen(cmd, cwd=ROOT, stdout=stream,
                                stderr=None if stream is None else subprocess.STDOUT)
        try:
            proc.wait(None if deadline is None else max(0.0, deadline - time.time()))
        except subprocess.TimeoutExpired:
            if evaluating is not None and evaluating():
                print("[paper_tables] the window is spent while a job scores its last "
                      "checkpoint: waiting for its benchmark", flush=True)
                proc.wait()
            else:
                proc.send_signal(signal.SIGTERM)
                proc.wait()
                return False
    finally:
        if stream is not None:
            stream.close()
    if proc.returncode != 0:
        raise subprocess.CalledProcessError(proc.returncode, cmd)
    return True


def park_job(out: Path, dest: Path, algo: str) -> bool:
    """A job's checkpoint, train.csv and config from its run folder ``out`` to ``dest``
    (``paper_jobs/<job>/unfinished/``), to be committed (``git add -f``: results' ``*.pt``
    are ignored); the next session's ``--run`` resumes from it (:func:`unpark`). False
    when ``out`` has no checkpoint (stopped before its first one)."""
    if not (out / f"{algo}.pt").is_file():
        return False
    copy_parked(out, dest, algo)
    print(f"[paper_tables] {out.name}: parked in {dest} (commit it: git add -f {dest})",
          flush=True)
    return True


def park(runs: Path | None = None, jobs: Path | None = None) -> list[Path]:
    """:func:`park_job` for each unfinished job of ``runs`` (``multirun/paper/``: a
    checkpoint, no benchmark yet) into ``jobs/<job>/unfinished/`` (``paper_jobs/``), for a
    sweep stopped some other way than its ``--minutes``. Returns the folders written."""
    runs, jobs = runs or RUNS, jobs or JOBS
    from omegaconf import OmegaConf

    parked = []
    for out in sorted(p for p in runs.glob("*") if (p / ".hydra" / "config.yaml").is_file()):
        algo = OmegaConf.load(out / ".hydra" / "config.yaml").algo.name
        dest = jobs / out.name / UNFINISHED
        if not (out / "benchmark.csv").is_file() and park_job(out, dest, algo):
            parked.append(dest)
    return parked


def unpark(parked: Path, out: Path, algo: str) -> None:
    """A parked job (:func:`park`) back into its run folder ``out``, unless ``out`` holds a
    checkpoint of its own (a killed run of this session: newer)."""
    if (out / f"{algo}.pt").is_file() or not (parked / f"{algo}.pt").is_file():
        return
    copy_parked(parked, out, algo)
    print(f"[paper_tables] {out.name}: resumes from {parked}", flush=True)


def copy_parked(src: Path, dst: Path, algo: str) -> None:
    """The files a parked job keeps (its checkpoint and ``PARKED``) from ``src`` to ``dst``."""
    for rel in (f"{algo}.pt", *PARKED):
        if (src / rel).is_file():
            (dst / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src / rel, dst / rel)


# a finished run's scores: moved aside by reopen, so the run folder trains again
SCORED = ("benchmark.csv", "benchmark.md", "benchmark_runs.csv", "trajectories.png")


def reopen(names: list[str], runs: Path | None = None, jobs: Path | None = None,
           budget: Path | None = None) -> list[Path]:
    """Recorded jobs back to training at a higher budget (a probe's rule raised it). Each
    record ``jobs/<job>`` moves to ``budget/<job>-<F>M/`` (F: its frames in millions, with
    the run's learning curve and trajectories: the scores that raised the budget), the run
    folder's scores to its ``scored-<F>M/``, and its checkpoint is parked
    (:func:`park_job`), so the next ``--run --frames <more>`` resumes the job, here or on a
    fresh clone. Needs the run folder's checkpoint (``runs/<job>``; a record keeps none).
    Returns the budget folders written."""
    runs, jobs, budget = runs or RUNS, jobs or JOBS, budget or BUDGET
    from omegaconf import OmegaConf

    plan = []
    for name in names:  # check every job before moving any
        record, out = jobs / name, runs / name
        if not (record / "benchmark.csv").is_file():
            valid = sorted(p.parent.name for p in jobs.glob("*/benchmark.csv"))
            raise SystemExit(f"[paper_tables] --reopen {name}: {record} holds no finished "
                             f"record; valid are {valid}")
        cfg = OmegaConf.load(record / ".hydra" / "config.yaml")
        algo, frames = str(cfg.algo.name), int(cfg.algo.total_frames)
        if not (out / f"{algo}.pt").is_file():
            raise SystemExit(f"[paper_tables] --reopen {name}: no checkpoint {out / algo}.pt "
                             "to resume (records keep none: reopen where the job ran)")
        dest = budget / f"{name}-{frames / 1e6:.2f}M"
        if dest.exists():
            raise SystemExit(f"[paper_tables] --reopen {name}: {dest} exists already")
        plan.append((record, out, algo, frames, dest))
    moved = []
    for record, out, algo, frames, dest in plan:
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.move(record, dest)
        scored = out / f"scored-{frames / 1e6:.2f}M"
        scored.mkdir(exist_ok=True)
        for rel in SCORED:
            if (out / rel).is_file():
                shutil.move(out / rel, scored / rel)
        for rel in ("benchmark.md", "learning_curve.png", "trajectories.png"):
            for src in (out / rel, scored / rel):
                if src.is_file() and not (dest / rel).exists():
                    shutil.copy2(src, dest / rel)
        park_job(out, record / UNFINISHED, algo)
        print(f"[paper_tables] {record.name}: record at {frames} frames moved to {dest}; "
              f"its checkpoint parked to train on", flush=True)
        moved.append(dest)
    return moved


def recorded_settings(record: Path) -> dict:
    """A recorded job's frames, evaluation runs and robots, and recipe (``record.json``'s;
    v1 without one: those jobs predate it)."""
    from omegaconf import OmegaConf

    cfg = OmegaConf.load(record / ".hydra" / "config.yaml")
    info = record / "record.json"
    recipe = json.loads(info.read_text())["recipe"] if info.is_file() else "v1"
    return {"algo.total_frames": int(cfg.algo.total_frames), "eval.runs": int(cfg.eval.runs),
            "eval.robots": OmegaConf.select(cfg, "eval.robots"), "recipe": recipe}


def write_record(record: Path, checkpoint: Path, recipe: str) -> Path:
    """``record.json`` of a finished job: what a later session needs to trust it (frames,
    training minutes from ``train.csv``, seed, commit, the teacher and its hash, the
    benchmark protocol, the recipe)."""
    from omegaconf import OmegaConf

    from legoh.checkpoint import load_checkpoint
    from legoh.eval.protocol import PROTOCOL

    cfg = OmegaConf.load(record / ".hydra" / "config.yaml")
    with open(record / "train.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    minutes = training_minutes(rows, batch_frames(record / ".hydra" / "config.yaml"))
    teacher = Path(load_checkpoint(checkpoint)["extra"]["oracle"])
    info = {"job": record.name, "robot": str(cfg.robot.name), "algo": str(cfg.algo.name),
            "seed": int(cfg.seed), "frames": int(cfg.algo.total_frames),
            "minutes": round(minutes, 2), "commit": git_commit(), "recipe": recipe,
            "teacher": str(teacher.relative_to(ROOT)) if teacher.is_relative_to(ROOT)
            else str(teacher),
            "teacher_sha": hashlib.sha256(teacher.read_bytes()).hexdigest()[:12],
            "protocol": PROTOCOL, "eval": OmegaConf.to_container(cfg.eval, resolve=True)}
    path = record / "record.json"
    path.write_text(json.dumps(info, indent=2) + "\n", encoding="utf-8")
    return path


def run_jobs(jobs: dict[str, tuple[str, str, int]], frames: int, eval_runs: int,
             overrides: list[str], parallel: int = 1, recipe: str = "v2",
             eval_robots: int | None = None, minutes: float | None = None) -> None:
    """Every job of ``jobs``, ``parallel`` at a time (each console in
    ``multirun/paper/<job>.log`` when more than one): two training processes on these
    2 cores made ~1.6 x the frames of one (docs/oracle.md), so a sweep of 8 jobs finishes
    sooner two at a time. A failed job stops the sweep once the running ones end.
    ``minutes``: the sweep's window (a session's training time; None: no limit): no job
    starts after it, and the jobs still training at it are stopped and parked."""
    if parallel < 1:
        raise SystemExit(f"[paper_tables] --parallel {parallel}: valid is >= 1")
    if minutes is not None and minutes <= 0:
        raise SystemExit(f"[paper_tables] --minutes {minutes}: valid is > 0")
    deadline = None if minutes is None else time.time() + 60 * minutes
    each = {"frames": frames, "eval_runs": eval_runs, "overrides": overrides,
            "recipe": recipe, "eval_robots": eval_robots, "deadline": deadline}
    if parallel == 1:
        for name, job in jobs.items():
            run_job(name, *job, **each)
        return
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(parallel) as pool:  # threads: each only waits on its process
        futures = [pool.submit(run_job, name, *job, log=RUNS / f"{name}.log", **each)
                   for name, job in jobs.items()]
        for future in futures:
            future.result()  # a job's failure raises here, after the pool drained


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", action="store_true", help="run the studies first")
    parser.add_argument("--frames", type=int, default=None, help="stage-2 frames per job")
    parser.add_argument("--eval-runs", type=int, default=3)
    parser.add_argument("--eval-robots", type=int, default=None,
                        help="robots per evaluation run (eval.robots; recorded and checked "
                             "like --frames)")
    parser.add_argument("--minutes", type=float, default=None,
                        help="the sweep's window (a session's training time): no job starts "
                             "after it; jobs training at it checkpoint and are parked")
    parser.add_argument("--park", action="store_true",
                        help="copy unfinished jobs' checkpoints to paper_jobs/<job>/"
                             "unfinished/ to commit (a sweep stopped another way)")
    parser.add_argument("--reopen", default=None,
                        help="comma-separated recorded jobs (e.g. h1-unified-seed0) to train "
                             "on at a raised budget: record to paper_budget/, checkpoint parked")
    parser.add_argument("--seeds", default="0", help="training seeds of every study")
    parser.add_argument("--recipe", choices=sorted(RECIPES), default="v2",
                        help="the teachers' hiking recipe (learn_hike --recipe): v2, the "
                             "shipped oracles'; v1, the committed 600k-frame jobs'")
    parser.add_argument("--parallel", type=int, default=1,
                        help="jobs at once (2 on a 2-core machine: ~1.6x the frames)")
    names = [t.name for t in PAPER_TABLES] + ["main"]
    parser.add_argument("--tables", nargs="+", default=names, choices=names,
                        help="the tables whose studies --run runs (main: the main paper's "
                             "comparison; paper_tables.md always shows all six)")
    parser.add_argument("--jobs", default=None,
                        help="comma-separated <robot>-<algo> (e.g. h1-unified): run only "
                             "these of the chosen tables' jobs, and write no tables (a probe)")
    args, overrides = parser.parse_known_args()
    specs = [t for t in PAPER_TABLES if t.name in args.tables]
    if args.park:
        park()
        return
    if args.reopen:
        reopen(args.reopen.split(","))
        return
    seeds = [int(x) for x in args.seeds.split(",")]
    if args.run:
        if not args.frames:
            parser.error("--run needs --frames (the same stage-2 frames for every job)")
        main_too = "main" in args.tables
        only = None if args.jobs is None else args.jobs.split(",")
        run_jobs(planned_jobs(specs, seeds, main_too, only), args.frames, args.eval_runs,
                 overrides, args.parallel, args.recipe, args.eval_robots, args.minutes)
        if only is not None:  # a probe: the studies' tables wait for all their jobs
            return
        chosen = [(s.study, study_grid(s.study)) for s in specs]
        for study, grid in chosen + ([(MAIN.study, main_grid())] if main_too else []):
            missing = unrecorded(grid, seeds)
            if missing:  # a windowed sweep: its table keeps the last complete study's
                print(f"[paper_tables] {study}: table kept, waiting for "
                      f"{', '.join(missing)}", flush=True)
                continue
            study_table(JOBS, RESULTS / study, study,
                        select={**grid, "seed": [str(x) for x in seeds]})
    lines = ["# The paper's study at CPU scale", "",
             "Written by `experiments/paper_tables.py` from the studies' tables. The paper's "
             "numbers come from full training (Isaac Gym, thousands of robots, the paper "
             "preset); ours from CPU-scale runs (the small TC-ViTs preset, the shipped "
             "oracle teaching), so compare orderings, not values.", ""]
    command = study_command(args.frames, args.eval_runs, seeds, args.recipe, args.eval_robots)
    lines += progress_section(seeds, args.frames, command=command)
    lines += main_section(command)
    for spec in PAPER_TABLES:  # every table: --tables picks the studies run, not the page
        lines += section(spec, args.frames, command)[0]
    out = RESULTS / "paper_tables.md"
    out.write_text("\n".join(lines), encoding="utf-8")
    print("\n".join(lines))
    print(f"[paper_tables] {out}")


if __name__ == "__main__":
    main()
