"""Ship a trained policy as ``pretrained/<robot>_<stage>.pt`` with its benchmark and card.

    python experiments/ship_pretrained.py --robot h1 --run experiments/results/learn_hike/h1-s0
    python experiments/ship_pretrained.py --robot h1 --stage unified \
        --run experiments/results/learn_student/h1-unified-s0
    python experiments/ship_pretrained.py --robot h1 --rescore     # the shipped file, anew
    python experiments/ship_pretrained.py --robot g1 --stage unified --candidate \
        --run experiments/results/learn_student/g1-unified-s0-v2lag --checkpoint ...  # try

``--stage oracle`` (default) copies the run's ``oracle.pt`` (refused above 10 MB); a
stage-2 variant (``unified``, ``ep_h``, ...) copies ``<stage>.pt`` (or ``--checkpoint``, a
file of the run such as ``learn_student.py --average``'s ``snapshots/avg<first>-<last>.pt``;
its minutes are read at its iteration in the run's ``clock.csv``) without its optimiser and
RNG states (a third of a student's file; nobody resumes a shipped student's Adam) and
exports it as ``<robot>_<stage>.ts`` (TorchScript, ``mode=export``'s format). Then it
benchmarks the file with the hiking protocol (the five categories of ``trail=hike``, levels
0-4 x 5 variants, robots placed on their support 2-10 m of path from the terminus with the
category's obstacle ahead, randomisation on, 30 s; ``--robots`` per level, ``--runs`` runs;
benchmark protocol ``legoh.eval.protocol.PROTOCOL``, written into the card) and rewrites
``pretrained/README.md`` from every shipped card (``pretrained/<robot>_<stage>.json``):
frames, training minutes, the commit that trained it, the recipe, the protocol and the
table. ``--rescore`` only re-benchmarks a shipped file on this code's protocol.
``checkpoint=pretrained`` (under the matching ``algo``) and
``init=pretrained`` then pick the file.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import torch  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from campaign import git_commit  # noqa: E402
from learn_walk import compose_run  # noqa: E402

from legoh.checkpoint import save_checkpoint  # noqa: E402
from legoh.config.compose import compose_config  # noqa: E402
from legoh.eval.benchmark import evaluate  # noqa: E402
from legoh.eval.cli import build_actor, for_checkpoint  # noqa: E402
from legoh.eval.protocol import PROTOCOL, of_card, of_csv  # noqa: E402
from legoh.policies.pretrained import PRETRAINED_DIR, benchmark_protocol  # noqa: E402

MAX_BYTES = 10 * 2**20
SHIP_ROBOTS, SHIP_RUNS = 80, 2  # the shipping protocol's (a card's) robots per level, runs
RECIPES = {"oracle": "python experiments/learn_hike.py --robot {robot} (a campaign of runs; the "
                     "run folder's summary.md and curve.png)",
           "student": "python experiments/learn_student.py --robot {robot} --algo {stage} (a "
                      "campaign of runs from the shipped oracle; the run folder's summary.md "
                      "and curve.png)"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="h1")
    parser.add_argument("--stage", default="oracle",
                        help="oracle, or the stage-2 algo the run trained (unified, ep_h, ...)")
    parser.add_argument("--run", help="a learn_hike / learn_student run folder (required "
                                      "unless --main-job-only)")
    parser.add_argument("--checkpoint", help="ship this file of the run instead of "
                                             "<run>/<stage>.pt (e.g. an averaged snapshot)")
    parser.add_argument("--robots", type=int, default=SHIP_ROBOTS, help="robots per level and run")
    parser.add_argument("--runs", type=int, default=SHIP_RUNS)
    parser.add_argument("--recipe", help="how it was trained, when not the campaign script's "
                                         "default (e.g. a chain of warm-started runs)")
    parser.add_argument("--minutes", type=float,
                        help="training minutes, when the run folder has no clock.csv")
    parser.add_argument("--origin", help="what it started from (README line)")
    parser.add_argument("--main-job-only", action="store_true",
                        help="only (re)score the shipped oracle on the main job's protocol")
    parser.add_argument("--candidate", action="store_true",
                        help="score the run's checkpoint on the shipping protocol into "
                             "<run>/ship_protocol_<stem>/ beside the shipped file; pretrained/ "
                             "untouched (ship it after with the plain command)")
    parser.add_argument("--rescore", action="store_true",
                        help="only re-benchmark the shipped file on this code's protocol "
                             "(its card's table, protocol and, for an oracle, main_job)")
    args = parser.parse_args()
    card_path = PRETRAINED_DIR / f"{args.robot}_{args.stage}.json"
    if args.candidate:
        if not args.run:
            parser.error("--candidate needs --run (the run folder of the checkpoint)")
        candidate(args)
        return
    if args.rescore:
        rescore(args, card_path)
        return
    if args.main_job_only:
        card = json.loads(card_path.read_text())
        card["main_job"] = main_job_reference(args.robot)
        card_path.write_text(json.dumps(card, indent=2))
        print(json.dumps(card["main_job"]["rows"]["overall"]))
        return
    if not args.run:
        parser.error("--run is required (a learn_hike or learn_student run folder)")
    run = Path(args.run)
    src = Path(args.checkpoint) if args.checkpoint else run / f"{args.stage}.pt"
    dst = ship_file(src, args.robot, args.stage)
    state = torch.load(dst, map_location="cpu", weights_only=True)
    result = ship_benchmark(args, export=dst.with_suffix(".ts"))
    minutes = clock_minutes(run / "clock.csv", int(state["iteration"]), args.minutes)
    frames = int(state["iteration"]) * int(state["config"]["algo"]["num_envs"]) * int(
        state["config"]["algo"]["steps_per_env"])
    recipe = RECIPES["oracle" if args.stage == "oracle" else "student"]
    card = {"robot": args.robot, "stage": args.stage, "file": dst.name,
            "iteration": int(state["iteration"]), "frames": frames, "minutes": minutes,
            "run": str(run), "checkpoint": str(src), "commit": trained_by(run),
            "recipe": args.recipe or recipe.format(robot=args.robot, stage=args.stage),
            "origin": args.origin or ("from the learn_walk walker" if args.stage == "oracle"
                                      else f"distilled from `{args.robot}_oracle.pt`"),
            "megabytes": round(dst.stat().st_size / 2**20, 2), "protocol": PROTOCOL,
            "benchmark": Path(result["paths"]["markdown"]).read_text()}
    if args.stage == "oracle":
        card["main_job"] = main_job_reference(args.robot)
    card_path.write_text(json.dumps(card, indent=2))
    write_readme()
    print((PRETRAINED_DIR / "README.md").read_text())


def ship_benchmark(args, export: Path | None = None, checkpoint: str = "pretrained",
                   out: Path | None = None) -> dict:
    """Benchmark ``checkpoint`` (default the shipped ``pretrained/<robot>_<stage>.pt``) on
    the shipping protocol (``--robots`` per level, ``--runs`` runs, 5 variants a level,
    seed 2000) into ``out`` (default ``pretrained/<robot>_<stage>_eval``); a student is
    first exported to ``export`` when given."""
    cfg = compose_run(args.robot, 0, "walk", "hike", [
        f"algo={args.stage}", f"eval.robots={args.robots}", f"eval.runs={args.runs}",
        "eval.variants=5", "eval.levels=[0,1,2,3,4]", "eval.randomization=true",
        "eval.seed=2000"])
    cfg, _ = for_checkpoint(cfg, checkpoint)  # scored on its own feet
    policy, env_fn = build_actor(cfg, checkpoint)
    if args.stage != "oracle":
        if export is not None:
            from legoh.export import export_student
            export_student(policy, export, meta={"robot": args.robot, "algo": args.stage})
        policy = policy.policy
    return evaluate(cfg, policy, out or PRETRAINED_DIR / f"{args.robot}_{args.stage}_eval",
                    label=f"{args.robot}_{args.stage}", env_fn=env_fn)


def candidate_dir(run: Path, src: Path, args) -> Path:
    """``<run>/ship_protocol_<file stem>``, with ``-runs<N>`` / ``-robots<N>`` where those
    differ from a card's: a 4-run score is never read as the card's 2-run one."""
    more = "".join(f"-{k}{v}" for k, v, card in (("runs", args.runs, SHIP_RUNS),
                                                  ("robots", args.robots, SHIP_ROBOTS))
                   if v != card)
    return run / f"ship_protocol_{src.stem}{more}"


def candidate(args) -> Path:
    """``--candidate``: the run's checkpoint (or ``--checkpoint``) on the shipping protocol
    into ``<run>/ship_protocol_<file stem>/``, ``pretrained/`` untouched, and
    ``beside_shipped.md``: its SR per category beside the shipped file's and the shipped
    oracle's (the ratio issue 47's bar reads). Shipping it is then the plain command."""
    run = Path(args.run)
    src = Path(args.checkpoint) if args.checkpoint else run / f"{args.stage}.pt"
    out = candidate_dir(run, src, args)
    result = ship_benchmark(args, checkpoint=str(src), out=out)
    columns = {"candidate": result["paths"]["csv"],
               "shipped": PRETRAINED_DIR / f"{args.robot}_{args.stage}_eval" / "benchmark.csv",
               "teacher": PRETRAINED_DIR / f"{args.robot}_oracle_eval" / "benchmark.csv"}
    table = beside_shipped({k: v for k, v in columns.items() if Path(v).is_file()})
    path = out / "beside_shipped.md"
    path.write_text(f"**{src} on the shipping protocol, beside `pretrained/`**\n\n{table}",
                    encoding="utf-8")
    print(path.read_text())
    return path


def runs_of(path: Path) -> int | None:
    """The runs behind ``benchmark.csv`` ``path`` (its ``benchmark_runs.csv``), None when
    that file is not beside it."""
    runs = Path(path).with_name("benchmark_runs.csv")
    if not runs.is_file():
        return None
    with runs.open(newline="", encoding="utf-8") as f:
        return len({row["run"] for row in csv.DictReader(f)})


def beside_shipped(files: dict[str, Path]) -> str:
    """A Markdown table: each category's SR (mean ± std over runs) from each benchmark.csv
    of ``files``, each column with its runs, and the candidate's ratio to the teacher's
    where both are there on as many runs (a ratio across run counts mixes protocols)."""
    from legoh.eval.protocol import same_protocol
    from legoh.eval.study import read_rows

    same_protocol({name: of_csv(path) for name, path in files.items()})
    runs = {name: runs_of(path) for name, path in files.items()}
    rows: dict[str, dict[str, tuple[float, float]]] = {}
    for name, path in files.items():
        for cat, metrics in read_rows(path).items():
            rows.setdefault(cat, {})[name] = metrics["SR"]
    both = "candidate" in files and "teacher" in files
    ratio = both and runs["candidate"] == runs["teacher"]
    head = ["category", *(f"{n} SR (%)" + (f", {runs[n]} runs" if runs[n] else "")
                          for n in files)] + (["candidate / teacher"] if ratio else [])
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for cat, got in rows.items():
        cells = [cat] + [f"{got[n][0]:.2f} ± {got[n][1]:.2f}" if n in got else "–"
                         for n in files]
        if ratio:
            cells.append(f"{got['candidate'][0] / got['teacher'][0]:.2f}"
                         if got.get("teacher", (0,))[0] else "–")
        lines.append("| " + " | ".join(cells) + " |")
    if both and not ratio:
        lines.append(f"\nNo candidate / teacher ratio: {runs['candidate']} runs against "
                     f"{runs['teacher']}; score the teacher on as many (`--candidate "
                     f"--checkpoint pretrained/<robot>_oracle.pt --stage oracle --runs N`).")
    return "\n".join(lines) + "\n"


def rescore(args, card_path: Path) -> None:
    """``--rescore``: the shipped file's card gets this protocol's table (and, for an
    oracle, its main_job reference); the README is rewritten."""
    card = json.loads(card_path.read_text())
    result = ship_benchmark(args)
    print(f"[ship] {card_path.name}: protocol {of_card(card)} -> {PROTOCOL}")
    card.update(protocol=PROTOCOL, benchmark=Path(result["paths"]["markdown"]).read_text())
    if args.stage == "oracle":
        card["main_job"] = main_job_reference(args.robot)
    card_path.write_text(json.dumps(card, indent=2))
    write_readme()
    print(card["benchmark"])


def clock_minutes(clock: Path, iteration: int, default: float | None) -> float | None:
    """Training minutes at ``iteration`` (the last ``clock.csv`` row at or before it: an
    averaged snapshot ends before the run does), ``default`` without a clock."""
    if not clock.exists():
        return default
    with open(clock) as f:
        rows = [(float(r["iteration"]), float(r["minutes"])) for r in csv.DictReader(f)]
    before = [m for it, m in rows if it <= iteration]
    if not before:
        raise SystemExit(f"{clock} has no row at or before iteration {iteration}")
    return before[-1]


def ship_file(src: Path, robot: str, stage: str) -> Path:
    """Copy ``src`` to ``pretrained/<robot>_<stage>.pt``: whole for an oracle, without
    optimiser and RNG states for a student; refused above :data:`MAX_BYTES`."""
    state = torch.load(src, map_location="cpu", weights_only=False)
    if state["robot"] != robot:
        raise SystemExit(f"{src} was trained on robot {state['robot']!r}, not {robot!r}")
    if stage != "oracle":
        state = {k: v for k, v in state.items() if k not in ("optimizers", "rng")}
    PRETRAINED_DIR.mkdir(exist_ok=True)
    dst = save_checkpoint(PRETRAINED_DIR / f"{robot}_{stage}.pt", state)
    size = dst.stat().st_size
    if size > MAX_BYTES:
        dst.unlink()
        raise SystemExit(f"{src} ships as {size / 2**20:.1f} MB, above 10 MB")
    return dst


def main_job_reference(robot: str) -> dict:
    """The shipped file scored on the main job's own benchmark (``python run.py
    robot=<robot>``: its trail, eval protocol and seed), which the main job prints beside
    its own table (``legoh.app.print_beside_shipped``)."""
    cfg, _ = for_checkpoint(compose_config(f"robot={robot}"), "pretrained")
    actor = build_actor(cfg, "pretrained")[0]
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
    return git_commit()


def write_readme() -> None:
    lines = ["# Pretrained policies", "",
             "Written by `experiments/ship_pretrained.py` from each card "
             "(`<robot>_<stage>.json`). `checkpoint=pretrained` (eval, play; under "
             "`algo=unified` the student) and `init=pretrained` (train) pick the robot's "
             "file:", "", "```bash",
             "python run.py mode=play checkpoint=pretrained trail=hurdle",
             "python run.py mode=eval checkpoint=pretrained trail=randommix",
             "python run.py mode=play checkpoint=pretrained algo=unified trail=forest",
             "python run.py init=pretrained            # train on from the shipped oracle",
             "```", "",
             "A student also ships as TorchScript (`<robot>_<stage>.ts`, `mode=export`'s "
             "format: `torch.jit.load` is all it needs; inputs in `legoh/export.py`).", ""]
    for path in sorted(PRETRAINED_DIR.glob("*_*.json")):
        c = json.loads(path.read_text())
        stage = c.get("stage", "oracle")
        minutes = "n/a" if c["minutes"] is None else f"{c['minutes']:.0f}"
        origin = c.get("origin", "from the learn_walk walker")
        version = of_card(c)
        stale = ("" if version == PROTOCOL else f": not comparable with {PROTOCOL} figures; "
                 f"re-score with `python experiments/ship_pretrained.py --robot {c['robot']} "
                 f"--stage {stage} --rescore`")
        lines += [f"## `{c['file']}` ({c['robot'].upper()} {stage}, {c['megabytes']} MB)", "",
                  f"- {c['frames']:,} frames ({c['iteration']} iterations), {minutes} minutes "
                  f"of training on a 2-core CPU, {origin}",
                  f"- trained by commit `{c['commit']}` (its last session): {c['recipe']}; "
                  f"run folder `{c['run']}`",
                  f"- scored on benchmark protocol **{version}**{stale} (docs/metrics.md)",
                  "", c["benchmark"], ""]
    (PRETRAINED_DIR / "README.md").write_text("\n".join(lines))


if __name__ == "__main__":
    main()
