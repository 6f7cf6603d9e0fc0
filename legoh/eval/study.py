"""Studies: gather a multirun sweep's jobs into paper-style tables, overall and per trail
category, mean ± std over evaluation runs.

A sweep (``python run.py -m +experiment=<study>``) leaves one folder per job, each with its
composed config (``.hydra/config.yaml``), its benchmark (``benchmark.csv``, written by
:func:`legoh.eval.benchmark.evaluate`: per category and overall, the mean and sample std of
each metric over the job's ``eval.runs`` evaluation runs) and its training log
(``train.csv``). Jobs are grouped by a config key (the method: ``algo.name``; or
``robot.name``). A group's row pools the evaluation runs of all its jobs (seeds): the
paper's ± is over its 5 evaluation runs, not over training seeds, so one job's row is its
own benchmark row, and several jobs' rows are the mean and sample std over all their runs:
taken from the runs' own values where every job kept them (``benchmark_runs.csv``:
:func:`read_runs`), else rebuilt from each job's run count, mean and std (:func:`pool`,
exact unless a metric is NaN in some of a job's runs).
"""

from __future__ import annotations

import csv
import json
import math
import os
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from legoh.eval.metrics import METRICS, column_title, summarize, to_markdown
from legoh.eval.protocol import of_csv, same_protocol

STUDIES = {  # study -> the config key that names a row of its table
    "ablation_temporal": "algo.name",
    "ablation_prior": "algo.name",
    "plugin_hlm": "algo.name",
    "robots": "robot.name",
    "benchmark": "algo.name",
    "table8": "algo.name",
}


def read_rows(path: str | Path) -> dict[str, dict[str, tuple[float, float]]]:
    """Every category row (and ``overall``) of a ``benchmark.csv``: ``{row: {metric: (mean,
    std over its runs)}}``; per-level rows are left out. NaN for a metric the file lacks (one
    written before DW existed), so old sweeps still gather."""
    rows = {}
    with Path(path).open(newline="", encoding="utf-8") as f:
        for rec in csv.DictReader(f):
            if rec["category"].startswith("level "):
                continue
            rows[rec["category"]] = {m: (float(rec.get(f"{column_title(m)} mean", "nan")),
                                         float(rec.get(f"{column_title(m)} std", "nan")))
                                     for m in METRICS}
    if "overall" not in rows:
        raise KeyError(f"{path} has no row 'overall'")
    return rows


def read_runs(path: str | Path) -> dict[str, list[dict[str, float]]]:
    """Every category row (and ``overall``) of a ``benchmark_runs.csv``: ``{row: [{metric:
    value} per run]}``, runs in order; per-level rows left out."""
    rows: dict[str, list[dict[str, float]]] = {}
    with Path(path).open(newline="", encoding="utf-8") as f:
        for rec in csv.DictReader(f):
            if not rec["category"].startswith("level "):
                rows.setdefault(rec["category"], []).append(
                    {m: float(rec[column_title(m)]) for m in METRICS})
    return rows


def read_overall(path: str | Path, row: str = "overall") -> dict[str, float]:
    """The mean of each metric in ``row`` of a ``benchmark.csv``."""
    rows = read_rows(path)
    if row not in rows:
        raise KeyError(f"{path} has no row {row!r}")
    return {m: mean for m, (mean, _) in rows[row].items()}


def pool(samples: list[tuple[int, float, float]]) -> tuple[float, float, int]:
    """(mean, sample std, runs) over the runs of several jobs, each given as (runs, mean,
    sample std over them): exact for the pooled runs, since each job's std (ddof=1, as
    :func:`legoh.eval.metrics.summarize` gives it) and mean fix its sum of squares. Jobs
    with a NaN mean (no run had the metric: T2R with no success) are left out; a NaN std
    with one run counts as 0."""
    kept = [(n, m, 0.0 if n == 1 or math.isnan(s) else s) for n, m, s in samples
            if n > 0 and not math.isnan(m)]
    total = sum(n for n, _, _ in kept)
    if total == 0:
        return float("nan"), float("nan"), 0
    mean = sum(n * m for n, m, _ in kept) / total
    squares = sum((n - 1) * s**2 + n * (m - mean) ** 2 for n, m, s in kept)
    return mean, (math.sqrt(squares / (total - 1)) if total > 1 else 0.0), total


def training_rate(path: str | Path) -> tuple[float, int]:
    """(median frames/s over iterations, iterations) from a ``train.csv``."""
    with Path(path).open(newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    rates = [float(r["frames_per_s"]) for r in rows[1:] or rows]  # the first one warms up
    return float(np.median(rates)), len(rows)


def study_grid(study: str) -> dict[str, list[str]]:
    """The jobs a study compares, from its sweep (``conf/experiment/<study>.yaml``): ``{config
    key: values}`` for each swept config group but the seed (``algo`` -> ``algo.name``), and
    the default for the groups it leaves alone (``robot.name``: h1). A folder of jobs from
    several studies (``experiments/paper_tables.py``) is filtered by it (:func:`gather`)."""
    from legoh.config.compose import CONF_DIR, compose_config

    params = OmegaConf.load(Path(CONF_DIR) / "experiment" / f"{study}.yaml").hydra.sweeper.params
    grid = {f"{group}.name": [v.strip() for v in str(values).split(",")]
            for group, values in params.items() if group != "seed"}
    defaults = compose_config()
    for group in ("robot", "algo"):
        grid.setdefault(f"{group}.name", [str(OmegaConf.select(defaults, f"{group}.name"))])
    return grid


def gather(sweep_dir: str | Path, group_by: str = "algo.name",
           select: dict[str, list[str]] | None = None) -> dict[str, list[dict]]:
    """``{label: [job, ...]}`` for every finished job (one with a benchmark) of a sweep;
    with ``select`` (:func:`study_grid`), only the jobs whose config has one of the listed
    values for each key.

    A job is ``{"dir", "seed", "runs", "rows", "run_rows", "metrics", "frames",
    "frames_per_s", "iterations"}``: ``rows`` every category row of its benchmark
    (:func:`read_rows`), ``run_rows`` its runs' own values (:func:`read_runs`; None for a
    job written before ``benchmark_runs.csv``), ``metrics`` the overall means, ``runs`` its
    ``eval.runs``, ``protocol`` its benchmark's protocol. Jobs without a ``benchmark.csv``
    (unfinished) are skipped; jobs scored on two protocols raise ``ProtocolMismatch``.
    """
    groups: dict[str, list[dict]] = {}
    for cfg_path in sorted(Path(sweep_dir).glob("*/.hydra/config.yaml")):
        job = cfg_path.parent.parent
        bench = job / "benchmark.csv"
        if not bench.is_file():
            continue
        cfg = OmegaConf.load(cfg_path)
        if select and any(str(OmegaConf.select(cfg, key)) not in values
                          for key, values in select.items()):
            continue
        label = str(OmegaConf.select(cfg, group_by))
        rate, iters = training_rate(job / "train.csv") if (job / "train.csv").is_file() \
            else (float("nan"), 0)
        rows = read_rows(bench)
        runs_csv = job / "benchmark_runs.csv"
        groups.setdefault(label, []).append({
            "dir": str(job), "seed": int(cfg.seed),
            "runs": int(OmegaConf.select(cfg, "eval.runs", default=1)), "rows": rows,
            "run_rows": read_runs(runs_csv) if runs_csv.is_file() else None,
            "metrics": {m: mean for m, (mean, _) in rows["overall"].items()},
            "frames": int(cfg.algo.total_frames), "frames_per_s": rate,
            "iterations": iters, "protocol": of_csv(bench)})
    if not groups:
        raise FileNotFoundError(f"no finished jobs (with benchmark.csv) under {sweep_dir}")
    same_protocol({j["dir"]: j["protocol"] for jobs in groups.values() for j in jobs})
    return groups


def group_row(jobs: list[dict], row: str) -> dict[str, tuple[float, float]] | None:
    """Row ``row`` (a category or ``overall``) of a group: each metric pooled over the
    evaluation runs of its jobs, from the runs' own values where every job has them, else
    by :func:`pool`; None when no job has that row."""
    have = [j for j in jobs if row in j["rows"]]
    if not have:
        return None
    if all(j.get("run_rows") and row in j["run_rows"] for j in have):
        return summarize([run for j in have for run in j["run_rows"][row]])
    return {m: pool([(j["runs"], *j["rows"][row][m]) for j in have])[:2] for m in METRICS}


def study_rows(groups: dict[str, list[dict]]) -> dict[str, dict[str, dict]]:
    """``{row: {label: {metric: (mean, std)}}}``: ``overall`` first, then each category
    in the order the jobs' benchmarks list them."""
    names = ["overall"]
    for jobs in groups.values():
        for job in jobs:
            names += [r for r in job["rows"] if r not in names]
    table = {}
    for name in names:
        rows = {label: group_row(jobs, name) for label, jobs in groups.items()}
        table[name] = {label: row for label, row in rows.items() if row is not None}
    return table


def write_study_csv(path: Path, table: dict[str, dict[str, dict]], label: str) -> Path:
    """One CSV of every row: ``label``, ``category``, then each metric's mean and std."""
    header = [label, "category"] + [f"{column_title(m)} {s}" for m in METRICS
                                    for s in ("mean", "std")]
    with path.open("w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(header)
        for category, rows in table.items():
            for name, stats in rows.items():
                w.writerow([name, category, *(repr(float(v)) for m in METRICS
                                              for v in stats[m])])
    return path


def read_study_csv(path: str | Path) -> dict[str, dict[str, dict[str, tuple[float, float]]]]:
    """A study's ``table.csv`` (:func:`write_study_csv`) back as ``{category: {label:
    {metric: (mean, std)}}}``; a table written before per-category rows (no ``category``
    column) gives its rows as ``overall``."""
    table: dict[str, dict[str, dict[str, tuple[float, float]]]] = {}
    with Path(path).open(newline="", encoding="utf-8") as f:
        reader = csv.DictReader(f)
        label = reader.fieldnames[0]
        for rec in reader:
            row = {m: (float(rec.get(f"{column_title(m)} mean", "nan")),
                       float(rec.get(f"{column_title(m)} std", "nan"))) for m in METRICS}
            table.setdefault(rec.get("category", "overall"), {})[rec[label]] = row
    return table


def study_table(sweep_dir: str | Path, out_dir: str | Path, study: str,
                group_by: str | None = None,
                select: dict[str, list[str]] | None = None) -> dict[str, Path]:
    """Write ``table.md`` (overall, then one table per trail category), ``table.csv`` (every
    row), ``table.png`` (overall) and ``summary.json`` for a sweep (its jobs in ``select``,
    all by default) to ``out_dir``."""
    group_by = group_by or STUDIES.get(study, "algo.name")
    groups = gather(sweep_dir, group_by, select)
    table = study_rows(groups)
    seeds = sorted({j["seed"] for jobs in groups.values() for j in jobs})
    frames = sorted({j["frames"] for jobs in groups.values() for j in jobs})
    runs = {label: sum(j["runs"] for j in jobs) for label, jobs in groups.items()}
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    name = "Method" if group_by == "algo.name" else "Robot"
    title = (f"{study}: mean ± std over evaluation runs (per row: "
             f"{', '.join(f'{k} {v}' for k, v in runs.items())}; training seeds {seeds}; "
             f"stage-2 frames per job: {', '.join(map(str, frames))})")
    lines = [to_markdown(table["overall"], name, title), ""]
    for category, rows in table.items():
        if category != "overall":
            lines += [to_markdown(rows, name, f"{study}, category {category}"), ""]
    lines += [f"| {name} | jobs | evaluation runs | training frames/s (median) |",
              "|---|---|---|---|"]
    for label, jobs in groups.items():
        rate = np.nanmedian([j["frames_per_s"] for j in jobs])
        lines.append(f"| {label} | {len(jobs)} | {runs[label]} | {rate:.0f} |")
    paths = {"markdown": out / "table.md", "csv": out / "table.csv",
             "summary": out / "summary.json",
             "plot": plot_study(table["overall"], out / "table.png", title)}
    paths["markdown"].write_text("\n".join(lines) + "\n", encoding="utf-8")
    write_study_csv(paths["csv"], table, group_by)
    # job folders relative to the summary's own: the same file on every clone
    portable = {label: [{**j, "dir": os.path.relpath(j["dir"], out)} for j in jobs]
                for label, jobs in groups.items()}
    paths["summary"].write_text(json.dumps({"study": study, "group_by": group_by,
                                            "groups": portable}, indent=2), encoding="utf-8")
    return paths


def plot_study(rows, path: Path, title: str, metrics=("TR", "TC", "TTF", "SR")) -> Path:
    """Bars of mean ± std per method, one panel per metric."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = list(rows)
    fig, axes = plt.subplots(1, len(metrics), figsize=(3.2 * len(metrics), 3.2))
    for ax, m in zip(axes, metrics, strict=True):
        mean = [rows[k][m][0] for k in labels]
        std = [rows[k][m][1] for k in labels]
        ax.bar(range(len(labels)), np.nan_to_num(mean), yerr=np.nan_to_num(std), capsize=4,
               color=[f"C{i}" for i in range(len(labels))])
        ax.set_xticks(range(len(labels)), labels, rotation=20, fontsize=8)
        ax.set_title(column_title(m), fontsize=10)
        ax.grid(axis="y", alpha=0.3)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
