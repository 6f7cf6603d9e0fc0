"""How much of a student's shortfall against its teacher comes from Table 5's randomisation
(physics draws, pushes, action delay): both shipped policies of a robot scored on the same
levels and seeds with ``eval.randomization`` off and on.

    python experiments/randomization_gap.py --robot g1 [--levels 0 1] [--robots 160] [--runs 2]
    python experiments/randomization_gap.py --robot g1 --blind  # + the teacher blind to physics
    python experiments/randomization_gap.py --robot g1 --plot   # table and figure only

Each of the four evaluations is ``python run.py mode=eval checkpoint=pretrained`` (the
shipping protocol's seed 2000 and 5 variants a level) into
``experiments/results/randomization_gap/<robot>/<algo>-rand<bool>/``; ``table.md`` and
``gap.png`` are written beside them from their ``benchmark.csv``. ``--blind`` adds one
evaluation (the four are kept): the teacher under the randomisation with its privileged
input showing every robot the nominal physics draw
(``env.randomization.observe_physics=false``) into ``oracle-blind/``: what knowing the
draws is worth to it, the information its student cannot read.
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


BLIND = "oracle-blind"  # the teacher under Table 5, blind to its robot's physics draw


def run(args, out: Path) -> None:
    levels = "[" + ",".join(str(lv) for lv in args.levels) + "]"
    arms = [(BLIND, "oracle", True, ["env.randomization.observe_physics=false"])] \
        if args.blind else [(folder(out, algo, randomization).name, algo, randomization, [])
                            for algo in ALGOS for randomization in (False, True)]
    for name, algo, randomization, extra in arms:
        subprocess.run(
            [sys.executable, str(ROOT / "run.py"), f"robot={args.robot}", f"algo={algo}",
             "mode=eval", "checkpoint=pretrained", "trail=hike", f"eval.levels={levels}",
             f"eval.robots={args.robots}", f"eval.runs={args.runs}", "eval.variants=5",
             "eval.seed=2000", f"eval.randomization={str(randomization).lower()}", *extra,
             "video=false", f"hydra.run.dir={out / name}"],
            check=True)


def sr_falls(path: Path) -> dict:
    """{row: (SR mean, SR std, FR mean)} of one evaluation's ``benchmark.csv``."""
    rows = read_rows(path)
    return {r: (*rows[r]["SR"], rows[r]["FR"][0]) for r in ROWS}


def table(out: Path) -> dict:
    """{(algo, randomization): {row: (SR mean, SR std, FR mean)}} (and ``BLIND`` when
    ``--blind`` ran) and table.md."""
    got = {(algo, randomization): sr_falls(folder(out, algo, randomization) / "benchmark.csv")
           for algo in ALGOS for randomization in (False, True)}
    if (out / BLIND / "benchmark.csv").is_file():
        got[BLIND] = sr_falls(out / BLIND / "benchmark.csv")
    head = ["row", "teacher SR, no rand.", "student SR, no rand.", "ratio",
            "teacher SR, rand.", "student SR, rand.", "ratio", "falls (%) t / s, no rand.",
            "falls (%) t / s, rand."]
    if BLIND in got:
        head += ["teacher blind to physics: SR, rand.", "its falls (%)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name in ROWS:
        cells = [name]
        for randomization in (False, True):
            t, s = got["oracle", randomization][name], got["unified", randomization][name]
            cells += [f"{t[0]:.1f} ± {t[1]:.1f}", f"{s[0]:.1f} ± {s[1]:.1f}",
                      f"{s[0] / t[0]:.2f}" if t[0] else "–"]
        cells += [f"{got['oracle', r][name][2]:.1f} / {got['unified', r][name][2]:.1f}"
                  for r in (False, True)]
        if BLIND in got:
            b = got[BLIND][name]
            cells += [f"{b[0]:.1f} ± {b[1]:.1f}", f"{b[2]:.1f}"]
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
    width = 0.8 / len(got)
    for i, arm in enumerate(got):
        sr = [got[arm][n][0] for n in ROWS]
        err = [got[arm][n][1] for n in ROWS]
        label = "teacher blind to physics, randomisation on" if arm == BLIND else \
            f"{'teacher' if arm[0] == 'oracle' else 'student'}, randomisation " \
            f"{'on' if arm[1] else 'off'}"
        ax.bar(x + (i - (len(got) - 1) / 2) * width, sr, width, yerr=err, label=label)
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
    parser.add_argument("--blind", action="store_true",
                        help="only the teacher blind to the physics draws (randomisation on)")
    args = parser.parse_args()
    out = ROOT / "experiments" / "results" / "randomization_gap" / args.robot
    if not args.plot:
        run(args, out)
    got = table(out)
    print((out / "table.md").read_text())
    print(plot(got, out, args.robot))


if __name__ == "__main__":
    main()
