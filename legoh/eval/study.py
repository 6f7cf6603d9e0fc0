"""Studies: gather a multirun sweep's jobs into one paper-style table (mean ± std over seeds).

A sweep (``python run.py -m +experiment=<study>``) leaves one folder per job, each with its
composed config (``.hydra/config.yaml``), its benchmark (``benchmark.csv``, written by
:func:`legoh.eval.benchmark.evaluate`) and its training log (``train.csv``). Jobs are grouped
by a config key (the method: ``algo.name``; or ``robot.name``); each job's overall benchmark
row (already a mean over its evaluation runs) is one sample, and the table gives mean ± std
over the group's jobs (seeds).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from legoh.eval.metrics import METRICS, column_title, summarize, to_markdown, write_csv

STUDIES = {  # study -> the config key that names a row of its table
    "ablation_temporal": "algo.name",
    "ablation_prior": "algo.name",
    "plugin_hlm": "algo.name",
    "robots": "robot.name",
    "benchmark": "algo.name",
}


def read_overall(path: str | Path, row: str = "overall") -> dict[str, float]:
    """The mean of each metric in ``row`` of a ``benchmark.csv``; NaN for a metric the file
    lacks (one written before DW existed), so old sweeps still gather."""
    with Path(path).open(newline="", encoding="utf-8") as f:
        for rec in csv.DictReader(f):
            if rec["category"] == row:
                return {m: float(rec.get(f"{column_title(m)} mean", "nan")) for m in METRICS}
    raise KeyError(f"{path} has no row {row!r}")


def training_rate(path: str | Path) -> tuple[float, int]:
    """(median frames/s over iterations, iterations) from a ``train.csv``."""
    with Path(path).open(newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    rates = [float(r["frames_per_s"]) for r in rows[1:] or rows]  # the first one warms up
    return float(np.median(rates)), len(rows)


def gather(sweep_dir: str | Path, group_by: str = "algo.name") -> dict[str, list[dict]]:
    """``{label: [job, ...]}`` for every finished job (one with a benchmark) of a sweep.

    A job is ``{"dir", "seed", "metrics", "frames", "frames_per_s"}``; jobs without a
    ``benchmark.csv`` (unfinished) are skipped.
    """
    groups: dict[str, list[dict]] = {}
    for cfg_path in sorted(Path(sweep_dir).glob("*/.hydra/config.yaml")):
        job = cfg_path.parent.parent
        bench = job / "benchmark.csv"
        if not bench.is_file():
            continue
        cfg = OmegaConf.load(cfg_path)
        label = str(OmegaConf.select(cfg, group_by))
        rate, iters = training_rate(job / "train.csv") if (job / "train.csv").is_file() \
            else (float("nan"), 0)
        groups.setdefault(label, []).append({
            "dir": str(job), "seed": int(cfg.seed), "metrics": read_overall(bench),
            "frames": int(cfg.algo.total_frames), "frames_per_s": rate,
            "iterations": iters})
    if not groups:
        raise FileNotFoundError(f"no finished jobs (with benchmark.csv) under {sweep_dir}")
    return groups


def study_table(sweep_dir: str | Path, out_dir: str | Path, study: str,
                group_by: str | None = None) -> dict[str, Path]:
    """Write ``table.md``, ``table.csv`` and ``summary.json`` for a sweep to ``out_dir``."""
    group_by = group_by or STUDIES.get(study, "algo.name")
    groups = gather(sweep_dir, group_by)
    rows = {label: summarize([j["metrics"] for j in jobs]) for label, jobs in groups.items()}
    seeds = sorted({j["seed"] for jobs in groups.values() for j in jobs})
    frames = sorted({j["frames"] for jobs in groups.values() for j in jobs})
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    title = (f"{study}: mean ± std over seeds {seeds} (stage-2 frames per job: "
             f"{', '.join(map(str, frames))})")
    lines = [to_markdown(rows, "Method" if group_by == "algo.name" else "Robot", title), "",
             "| Method | jobs | training frames/s (median) |", "|---|---|---|"]
    for label, jobs in groups.items():
        rate = np.nanmedian([j["frames_per_s"] for j in jobs])
        lines.append(f"| {label} | {len(jobs)} | {rate:.0f} |")
    paths = {"markdown": out / "table.md", "csv": out / "table.csv",
             "summary": out / "summary.json", "plot": plot_study(rows, out / "table.png", title)}
    paths["markdown"].write_text("\n".join(lines) + "\n", encoding="utf-8")
    write_csv(paths["csv"], rows, label=group_by)
    paths["summary"].write_text(json.dumps({"study": study, "group_by": group_by,
                                            "groups": groups}, indent=2), encoding="utf-8")
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
