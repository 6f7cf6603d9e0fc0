"""The paper's study at CPU scale: our numbers beside the appendix's Tables 1, 2, 3, 4 and 8.

    python experiments/paper_tables.py                     # write paper_tables.md from the studies
    python experiments/paper_tables.py --run --frames 100000 --eval-runs 3 [--seeds 0]

Each paper table is answered by one study of ours (``legoh.eval.paper.PAPER_TABLES``):
Table 1 by ``ablation_temporal`` (GRU vs causal transformer), Table 2 by ``ablation_prior``
(HLM vs vanilla VAE; our third row, no prior, has no paper column), Table 3 by
``plugin_hlm`` (EP-H vs EP-H + HLM), Table 4 by ``robots`` (H1 vs G1) and Table 8 by
``table8`` (EP-H vs RMA-B per trail category). ``--run`` runs the studies first, each with
``experiments/study.py --run`` (every job of a study: the robot's shipped oracle as its
teacher, read-only, the same stage-2 frames, ``--eval-runs`` evaluation runs; the std of
our cells is over those runs, as the paper's is over its 5). Without ``--run`` the tables
are read from ``experiments/results/<study>/table.csv``; a study not run yet is listed with
the command that runs it.

Per metric the two methods are ordered in the paper and in ours (``ordering``: better,
worse, or a tie when the means lie within one std); "agree" says whether the orderings
match where both separate the methods. Writes experiments/results/paper_tables.md.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from legoh.eval.metrics import HIGHER_IS_BETTER, column_title  # noqa: E402
from legoh.eval.paper import PAPER_TABLES, PaperTable, ordering  # noqa: E402
from legoh.eval.study import read_study_csv  # noqa: E402

RESULTS = ROOT / "experiments" / "results"
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


def section(spec: PaperTable, frames: int | None, eval_runs: int) -> tuple[list[str], dict]:
    path = RESULTS / spec.study / "table.csv"
    run = (f"`python experiments/study.py {spec.study} --run --frames {frames or 'F'} "
           f"--eval-runs {eval_runs}`")
    lines = [f"## {spec.title}", ""]
    if not path.is_file():
        return lines + [f"Not run yet: {run}.", ""], {}
    table = read_study_csv(path)
    lines += [f"Ours: `experiments/results/{spec.study}/` ({run}; its `table.md` says the "
              "frames, seeds and evaluation runs). Orderings: `>` the first column is "
              "better, `<` the second, `=` within one std.", ""]
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


def summary_line(counts: dict[str, int]) -> str:
    told = counts.get("yes", 0) + counts.get("no", 0)
    return (f"Where both separate the methods the orderings agree in {counts.get('yes', 0)} "
            f"of {told} metrics; ours ties in {counts.get('tie', 0)}, the paper in "
            f"{counts.get('paper ties', 0)}; {counts.get('–', 0)} without a value.")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", action="store_true", help="run the studies first")
    parser.add_argument("--frames", type=int, default=None, help="stage-2 frames per job")
    parser.add_argument("--eval-runs", type=int, default=3)
    parser.add_argument("--seeds", default="0", help="training seeds of every study")
    parser.add_argument("--tables", nargs="+", default=[t.name for t in PAPER_TABLES],
                        choices=[t.name for t in PAPER_TABLES])
    args, overrides = parser.parse_known_args()
    specs = [t for t in PAPER_TABLES if t.name in args.tables]
    if args.run:
        for spec in specs:
            cmd = [sys.executable, str(ROOT / "experiments" / "study.py"), spec.study, "--run",
                   "--eval-runs", str(args.eval_runs), "--seeds", args.seeds]
            if args.frames:
                cmd += ["--frames", str(args.frames)]
            print("[paper_tables]", " ".join(cmd), flush=True)
            subprocess.run(cmd + overrides, check=True, cwd=ROOT)
    lines = ["# The paper's study at CPU scale", "",
             "Written by `experiments/paper_tables.py` from the studies' tables. The paper's "
             "numbers come from full training (Isaac Gym, thousands of robots, the paper "
             "preset); ours from CPU-scale runs (the small TC-ViTs preset, the shipped "
             "oracle teaching), so compare orderings, not values.", ""]
    for spec in specs:
        lines += section(spec, args.frames, args.eval_runs)[0]
    out = RESULTS / "paper_tables.md"
    out.write_text("\n".join(lines), encoding="utf-8")
    print("\n".join(lines))
    print(f"[paper_tables] {out}")


if __name__ == "__main__":
    main()
