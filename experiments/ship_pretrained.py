"""Ship a trained oracle as ``pretrained/<robot>_oracle.pt`` with its benchmark and card.

    python experiments/ship_pretrained.py --robot h1 --run experiments/results/learn_hike/h1-s0

Copies the run's ``oracle.pt`` (refused above 10 MB), benchmarks it with the hiking protocol
(the five categories of ``trail=hike``, levels 0-4, robots placed 2-10 m of path from the
terminus, randomisation on, 30 s; ``--robots`` per level, ``--runs`` runs) and rewrites
``pretrained/README.md`` from every shipped card (``pretrained/<robot>_oracle.json``):
frames, training minutes, the commit that trained it, the recipe and the table.
``checkpoint=pretrained`` and ``init=pretrained`` then pick the file.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import torch  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from learn_walk import compose_run  # noqa: E402

from legoh.config.compose import compose_config  # noqa: E402
from legoh.eval.benchmark import evaluate, make_eval_env  # noqa: E402
from legoh.policies.oracle import load_oracle_actor  # noqa: E402
from legoh.policies.pretrained import PRETRAINED_DIR, benchmark_protocol  # noqa: E402

MAX_BYTES = 10 * 2**20


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="h1")
    parser.add_argument("--run", help="a learn_hike run folder (required unless --main-job-only)")
    parser.add_argument("--robots", type=int, default=80, help="robots per level and run")
    parser.add_argument("--runs", type=int, default=2)
    parser.add_argument("--main-job-only", action="store_true",
                        help="only (re)score the shipped file on the main job's protocol")
    args = parser.parse_args()
    card_path = PRETRAINED_DIR / f"{args.robot}_oracle.json"
    if args.main_job_only:
        card = json.loads(card_path.read_text())
        card["main_job"] = main_job_reference(args.robot)
        card_path.write_text(json.dumps(card, indent=2))
        print(json.dumps(card["main_job"]["rows"]["overall"]))
        return
    if not args.run:
        parser.error("--run is required (a learn_hike run folder)")
    run = Path(args.run)
    src = run / "oracle.pt"
    if src.stat().st_size > MAX_BYTES:
        raise SystemExit(f"{src} is {src.stat().st_size / 2**20:.1f} MB, above 10 MB")
    state = torch.load(src, map_location="cpu", weights_only=False)
    dst = PRETRAINED_DIR / f"{args.robot}_oracle.pt"
    PRETRAINED_DIR.mkdir(exist_ok=True)
    shutil.copyfile(src, dst)
    cfg = compose_run(args.robot, 0, "walk", "hike", [
        f"eval.robots={args.robots}", f"eval.runs={args.runs}", "eval.variants=2",
        "eval.levels=[0,1,2,3,4]", "eval.randomization=true", "eval.seed=2000"])
    env = make_eval_env(cfg)
    actor = load_oracle_actor(cfg, "pretrained", env)
    env.close()
    result = evaluate(cfg, actor, PRETRAINED_DIR / f"{args.robot}_oracle_eval",
                      label=f"{args.robot}_oracle")
    clock = run / "clock.csv"
    minutes = float(clock.read_text().strip().splitlines()[-1].split(",")[1]) if (
        clock.exists()) else None
    frames = int(state["iteration"]) * int(state["config"]["algo"]["num_envs"]) * int(
        state["config"]["algo"]["steps_per_env"])
    card = {"robot": args.robot, "file": dst.name, "iteration": int(state["iteration"]),
            "frames": frames, "minutes": minutes, "run": str(run),
            "commit": trained_by(run),
            "recipe": f"python experiments/learn_hike.py --robot {args.robot} (a campaign of "
                      "runs; the run folder's summary.md and curve.png)",
            "megabytes": round(dst.stat().st_size / 2**20, 2),
            "benchmark": Path(result["paths"]["markdown"]).read_text(),
            "main_job": main_job_reference(args.robot)}
    card_path.write_text(json.dumps(card, indent=2))
    write_readme()
    print((PRETRAINED_DIR / "README.md").read_text())


def main_job_reference(robot: str) -> dict:
    """The shipped file scored on the main job's own benchmark (``python run.py
    robot=<robot>``: its trail, eval protocol and seed), which the main job prints beside
    its own table (``legoh.app.print_beside_shipped``)."""
    cfg = compose_config(f"robot={robot}")
    env = make_eval_env(cfg)
    actor = load_oracle_actor(cfg, "pretrained", env)
    env.close()
    with tempfile.TemporaryDirectory() as tmp:
        result = evaluate(cfg, actor, tmp, label=f"{robot}_oracle")
    rows = {**result["rows"], **result["levels"]}
    return {"protocol": benchmark_protocol(cfg),
            "rows": {name: {m: list(v) for m, v in row.items()} for name, row in rows.items()
                     if name == "overall" or name.startswith("level")}}


def trained_by(run: Path) -> str:
    """The commit of the campaign's last session (``sessions.csv``), else this checkout's."""
    sessions = run / "sessions.csv"
    if sessions.exists():
        with open(sessions) as f:
            rows = list(csv.DictReader(f))
        if rows and rows[-1]["commit"] not in ("", "unknown", "unrecorded"):
            return rows[-1]["commit"]
    return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                          text=True).stdout.strip()


def write_readme() -> None:
    lines = ["# Pretrained policies", "",
             "Written by `experiments/ship_pretrained.py` from each card "
             "(`<robot>_oracle.json`). `checkpoint=pretrained` (eval, play) and "
             "`init=pretrained` (train) pick the robot's file:", "", "```bash",
             "python run.py mode=play checkpoint=pretrained trail=hurdle",
             "python run.py mode=eval checkpoint=pretrained trail=randommix",
             "python run.py init=pretrained            # train on from the shipped oracle",
             "```", ""]
    for path in sorted(PRETRAINED_DIR.glob("*_oracle.json")):
        c = json.loads(path.read_text())
        minutes = "n/a" if c["minutes"] is None else f"{c['minutes']:.0f}"
        lines += [f"## `{c['file']}` ({c['robot'].upper()} oracle, {c['megabytes']} MB)", "",
                  f"- {c['frames']:,} frames ({c['iteration']} iterations), {minutes} minutes "
                  f"of training on a 2-core CPU, from the learn_walk walker",
                  f"- trained by commit `{c['commit']}` (its last session): {c['recipe']}; "
                  f"run folder `{c['run']}`", "", c["benchmark"], ""]
    (PRETRAINED_DIR / "README.md").write_text("\n".join(lines))


if __name__ == "__main__":
    main()
