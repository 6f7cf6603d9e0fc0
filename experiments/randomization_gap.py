"""How much of a student's shortfall against its teacher comes from Table 5's randomisation
(physics draws, pushes, action delay): both shipped policies of a robot scored on the same
levels and seeds with ``eval.randomization`` off and on.

    python experiments/randomization_gap.py --robot g1 [--levels 0 1] [--robots 160] [--runs 2]
    python experiments/randomization_gap.py --robot g1 --plot   # table and figure only

Each of the four evaluations is ``python run.py mode=eval checkpoint=pretrained`` (the
shipping protocol's seed 2000 and 5 variants a level) into
``experiments/results/randomization_gap/<robot>/<algo>-rand<bool>/``; ``table.md`` and
``gap.png`` are written beside them from their ``benchmark.csv``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from legoh.eval.study import read_rows  # noqa: E402

ALGOS = ("oracle", "unified")
ROWS = ("randommix", "ditch", "hurdle", "gap", "forest", "overall")


def folder(out: Path, algo: str, randomization: bool) -> Path:
    return out / f"{algo}-rand{str(randomization).lower()}"


def run(args, out: Path) -> None:
    levels = "[" + ",".join(str(lv) for lv in args.levels) + "]"
    for algo in ALGOS:
        for randomization in (False, True):
            subprocess.run(
                [sys.executable, str(ROOT / "run.py"), f"robot={args.robot}", f"algo={algo}",
                 "mode=eval", "checkpoint=pretrained", "trail=hike", f"eval.levels={levels}",
                 f"eval.robots={args.robots}", f"eval.runs={args.runs}", "eval.variants=5",
                 "eval.seed=2000", f"eval.randomization={str(randomization).lower()}",
                 "video=false", f"hydra.run.dir={folder(out, algo, randomization)}"],
                check=True)


def table(out: Path) -> dict:
    """{(algo, randomization): {row: (SR mean, SR std, FR mean)}} and table.md."""
    got = {}
    for algo in ALGOS:
        for randomization in (False, True):
            rows = read_rows(folder(out, algo, randomization) / "benchmark.csv")
            got[algo, randomization] = {r: (*rows[r]["SR"], rows[r]["FR"][0])
                                        for r in ROWS}
    head = ["row", "teacher SR, no rand.", "student SR, no rand.", "ratio",
            "teacher SR, rand.", "student SR, rand.", "ratio", "falls (%) t / s, no rand.",
            "falls (%) t / s, rand."]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name in ROWS:
        cells = [name]
        for randomization in (False, True):
            t, s = got["oracle", randomization][name], got["unified", randomization][name]
            cells += [f"{t[0]:.1f} ± {t[1]:.1f}", f"{s[0]:.1f} ± {s[1]:.1f}",
                      f"{s[0] / t[0]:.2f}" if t[0] else "–"]
        cells += [f"{got['oracle', r][name][2]:.1f} / {got['unified', r][name][2]:.1f}"
                  for r in (False, True)]
        lines.append("| " + " | ".join(cells) + " |")
    (out / "table.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    return got


def plot(got: dict, out: Path, robot: str) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    x = np.arange(len(ROWS))
    fig, ax = plt.subplots(figsize=(10, 3.5))
    for i, (algo, randomization) in enumerate(got):
        sr = [got[algo, randomization][n][0] for n in ROWS]
        err = [got[algo, randomization][n][1] for n in ROWS]
        label = f"{'teacher' if algo == 'oracle' else 'student'}, randomisation " \
                f"{'on' if randomization else 'off'}"
        ax.bar(x + (i - 1.5) * 0.2, sr, 0.2, yerr=err, label=label)
    ax.set_xticks(x, ROWS, fontsize=8)
    ax.set_ylabel("SR (%)")
    ax.set_title(f"{robot}: shipped student and teacher, randomisation off and on", fontsize=9)
    ax.set_ylim(0, 118)
    ax.legend(fontsize=7, ncol=4, loc="upper center")
    ax.grid(axis="y", alpha=0.3)
    path = out / "gap.png"
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robot", default="g1")
    parser.add_argument("--levels", type=int, nargs="+", default=[0, 1])
    parser.add_argument("--robots", type=int, default=160, help="robots per level")
    parser.add_argument("--runs", type=int, default=2)
    parser.add_argument("--plot", action="store_true", help="table and figure only")
    args = parser.parse_args()
    out = ROOT / "experiments" / "results" / "randomization_gap" / args.robot
    if not args.plot:
        run(args, out)
    got = table(out)
    print((out / "table.md").read_text())
    print(plot(got, out, args.robot))


if __name__ == "__main__":
    main()
