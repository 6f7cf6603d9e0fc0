"""Run a study's sweep (optional) and gather its jobs into the paper-style tables.

    python experiments/study.py ablation_temporal              # gather multirun/ablation_temporal
    python experiments/study.py plugin_hlm --run --frames 40000 --eval-runs 3

Studies are the sweeps in ``conf/experiment/`` (ablation_temporal, ablation_prior,
plugin_hlm, robots, benchmark). ``--run`` launches ``python run.py -m +experiment=<study>``
with the budget overrides; each job takes its teacher (the robot's shipped oracle, a given
``algo.oracle_checkpoint=...``, or one trained once per seed and shared: a job that finds
another one training it waits, then reads it), trains its student, and benchmarks it.
The tables (overall, then per trail category; mean ± std over the evaluation runs of each
method's jobs, as the paper's ± is over 5 evaluation runs) go to
``experiments/results/<study>/``.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from legoh.eval.study import STUDIES, study_table  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("study", choices=sorted(STUDIES))
    parser.add_argument("--run", action="store_true", help="run the sweep first")
    parser.add_argument("--frames", type=int, default=None, help="stage-2 frames per job")
    parser.add_argument("--oracle-frames", type=int, default=None,
                        help="frames of each seed's oracle (trained once, then reused)")
    parser.add_argument("--seeds", default=None, help="comma-separated seeds, e.g. 0,1")
    parser.add_argument("--trail", default=None, help="trail of every job (default: config)")
    parser.add_argument("--eval-runs", type=int, default=None,
                        help="evaluation runs of each job's benchmark (eval.runs; the "
                             "tables' std is over them)")
    parser.add_argument("--sweep-dir", default=None,
                        help="where the sweep's jobs are (default multirun/<study>)")
    args, overrides = parser.parse_known_args()  # the rest: Hydra overrides for every job

    sweep_dir = Path(args.sweep_dir or ROOT / "multirun" / args.study)
    if args.run:
        cmd = [sys.executable, str(ROOT / "run.py"), "-m", f"+experiment={args.study}",
               f"hydra.sweep.dir={sweep_dir}"]
        if args.frames:
            cmd.append(f"algo.total_frames={args.frames}")
        if args.oracle_frames:
            if args.study == "benchmark":  # its oracle jobs have no stage-1 budget key
                parser.error("--oracle-frames does not apply to the benchmark study (it trains "
                             "the oracle as one of its methods); use --frames")
            cmd.append(f"algo.oracle_frames={args.oracle_frames}")
        if args.seeds:
            cmd.append(f"seed={args.seeds}")
        if args.trail:
            cmd.append(f"trail={args.trail}")
        if args.eval_runs:
            cmd.append(f"eval.runs={args.eval_runs}")
        cmd += overrides
        print("[study]", " ".join(cmd), flush=True)
        subprocess.run(cmd, check=True, cwd=ROOT)
    paths = study_table(sweep_dir, ROOT / "experiments" / "results" / args.study, args.study)
    print(paths["markdown"].read_text(encoding="utf-8"))
    for name, path in paths.items():
        print(f"[study] {name}: {path}")


if __name__ == "__main__":
    main()
