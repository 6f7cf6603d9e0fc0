"""Write docs/results.md from the committed results: the shipped policies' benchmarks beside
the paper's numbers, the learning campaigns' milestones and curves, filmstrips, and the
shipped hiker zero-shot on a long "hill" trail.

    python experiments/results_page.py            # the page, from what is committed (seconds)
    python experiments/results_page.py --hill     # first film + benchmark the shipped H1 oracle
                                                  # on a hill trail (experiments/results/hill/)
    python experiments/results_page.py --hill --stage unified   # its student (hill/unified/)
    python experiments/results_page.py --hill --robot g1 [--stage unified]   # G1's (hill/g1/)
    python experiments/results_page.py --demo forest   # first the README's GIF (docs/img/)

Nothing on the page is typed by hand: every number is read from a file under
``pretrained/`` or ``experiments/results/`` (a missing one leaves its section out).
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import re
import sys
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from legoh.eval.metrics import METRICS, column_title  # noqa: E402
from legoh.eval.paper import TABLE4, TABLE8  # noqa: E402
from legoh.eval.protocol import of_csv  # noqa: E402

PAGE = ROOT / "docs" / "results.md"
RESULTS = ROOT / "experiments" / "results"
PRETRAINED = ROOT / "pretrained"
HILL = RESULTS / "hill"
CATEGORIES = ("randommix", "ditch", "hurdle", "gap", "forest")


def rel(path: Path) -> str:
    """``path`` as a link from docs/."""
    return os.path.relpath(path, PAGE.parent)


def read_table(path: Path) -> dict[str, dict[str, tuple[float, float]]]:
    """A benchmark.csv as ``{row: {metric: (mean, std)}}``."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return {r["category"]: {m: (float(r[f"{column_title(m)} mean"]),
                                float(r[f"{column_title(m)} std"])) for m in METRICS}
            for r in rows}


def cell(value: tuple[float, float] | None) -> str:
    if value is None:
        return "-"
    mean, std = value
    return "n/a" if mean != mean else f"{mean:.1f} ± {std:.1f}"


def shipped_section() -> list[str]:
    lines = ["## The shipped policies", "",
             "Each `pretrained/<robot>_oracle.pt` is scored by `experiments/ship_pretrained.py` "
             "with the hiking protocol (robots placed 2-10 m of path from the terminus, "
             "randomisation on, 30 s, levels 0-4 of each category; "
             "[metrics.md](metrics.md)). The paper publishes no oracle numbers: beside ours "
             "stand its Table 8 baselines (depth students EP-H and RMA-B, 256 robots, 5 "
             "runs) and its Table 4 LEGO-H rows, as the nearest published reference. Our "
             "protocol is CPU-sized (fewer robots and runs), so read the orderings, not the "
             "decimals.", ""]
    cards = sorted(PRETRAINED.glob("*_oracle.json"))
    if not cards:
        return lines + ["No policy is shipped yet.", ""]
    for path in cards:
        card = json.loads(path.read_text())
        robot = card["robot"]
        table = read_table(PRETRAINED / f"{robot}_oracle_eval" / "benchmark.csv")
        minutes = "n/a" if card.get("minutes") is None else f"{card['minutes']:.0f}"
        lines += [f"### {robot.upper()} oracle (`pretrained/{card['file']}`)", "",
                  f"{card['frames']:,} frames, {minutes} minutes of training on a 2-core "
                  f"CPU (commit `{card['commit']}`, run `{card['run']}`).", "",
                  "| Category | SR ours | SR EP-H (paper) | SR RMA-B (paper) | TC ours | "
                  "TR ours | TTF (s) ours | T2R (s) ours | FR ours |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for cat in CATEGORIES:
            if cat not in table:
                continue
            ours, paper = table[cat], TABLE8[cat]
            lines.append(f"| {cat} | {cell(ours['SR'])} | {cell(paper['EP-H']['SR'])} | "
                         f"{cell(paper['RMA-B']['SR'])} | {cell(ours['TC'])} | "
                         f"{cell(ours['TR'])} | {cell(ours['TTF'])} | {cell(ours['T2R'])} | "
                         f"{cell(ours['FR'])} |")
        if "overall" in table:
            ref = TABLE4.get(robot, {})
            lines += ["", f"Overall: SR {cell(table['overall']['SR'])} % (paper, LEGO-H on "
                          f"{robot.upper()}, Table 4: {cell(ref.get('SR'))} %), TC "
                          f"{cell(table['overall']['TC'])} % ({cell(ref.get('TC'))}), T2R "
                          f"{cell(table['overall']['T2R'])} s ({cell(ref.get('T2R'))})."]
        levels = [k for k in table if k.startswith("level")]
        if levels:
            lines += ["", "By level (all categories): " + ", ".join(
                f"{k} SR {table[k]['SR'][0]:.0f} %" for k in levels) + "."]
        pic = PRETRAINED / f"{robot}_oracle_eval" / "trajectories.png"
        if pic.exists():
            lines += ["", f"![{robot} trajectories]({rel(pic)})"]
        lines.append("")
    return lines + students_section()


def students_section() -> list[str]:
    """Each shipped student (``pretrained/<robot>_<algo>.json``, not an oracle) beside its
    robot's shipped oracle on the same protocol, and the paper's LEGO-H (Table 4)."""
    lines = []
    for path in sorted(PRETRAINED.glob("*_*.json")):
        card = json.loads(path.read_text())
        if card.get("stage", "oracle") == "oracle":
            continue
        robot, stage = card["robot"], card["stage"]
        mine = read_table(PRETRAINED / f"{robot}_{stage}_eval" / "benchmark.csv")
        mine_csv = PRETRAINED / f"{robot}_{stage}_eval" / "benchmark.csv"
        teacher_csv = PRETRAINED / f"{robot}_oracle_eval" / "benchmark.csv"
        teacher = read_table(teacher_csv) if teacher_csv.exists() else {}
        if teacher and of_csv(teacher_csv) != of_csv(mine_csv):  # never side by side
            print(f"[results] {robot} {stage} scored on protocol {of_csv(mine_csv)}, its "
                  f"oracle on {of_csv(teacher_csv)}: the oracle's column is left out")
            teacher = {}
        minutes = "n/a" if card.get("minutes") is None else f"{card['minutes']:.0f}"
        lines += [f"### {robot.upper()} student, {stage} (`pretrained/{card['file']}`)", "",
                  f"{card['frames']:,} frames, {minutes} minutes of stage-2 training on a "
                  f"2-core CPU, {card.get('origin', '')} (commit `{card['commit']}`, run "
                  f"`{card['run']}`). SR beside the shipped oracle (the line above says "
                  "which one taught it) on the hiking protocol (robots per level and runs "
                  "as each card says):", "",
                  "| Category | SR student | SR shipped oracle | TC student | TR student | "
                  "FR student |", "|---|---|---|---|---|---|"]
        for cat in [*CATEGORIES, "overall"]:
            if cat in mine:
                theirs = teacher.get(cat, {}).get("SR", (float("nan"), 0.0))
                lines.append(f"| {cat} | {cell(mine[cat]['SR'])} | {cell(theirs)} | "
                             f"{cell(mine[cat]['TC'])} | {cell(mine[cat]['TR'])} | "
                             f"{cell(mine[cat]['FR'])} |")
        ref = TABLE4.get(robot, {})
        lines += ["", f"The paper's LEGO-H on {robot.upper()} (Table 4, full training): SR "
                      f"{cell(ref.get('SR'))} %.", ""]
    return lines


def milestone_text(stones: dict, first_frames: int) -> str:
    """Each milestone's frames and minutes; one met at a run's first evaluation (at
    ``first_frames``) was met by the weights it started from (a warm start), not learned in
    0 frames."""
    parts = []
    for name, hit in stones.items():
        if hit is None:
            text = "not reached"
        elif hit["frames"] <= first_frames:
            text = "met at the first evaluation"
        else:
            text = f"{hit['frames'] / 1e6:.1f}M frames / {hit['minutes']:.0f} min"
        parts.append(f"({name}) {text}")
    return "; ".join(parts)


def campaigns_section() -> list[str]:
    lines = ["## Learning campaigns", "",
             "Frames and training minutes (2-core CPU) to each milestone, from each run's "
             "`milestones.json`; criteria in its `summary.md`. A warm-started run meets some "
             "milestones at its first evaluation, with the weights it started from.", "",
             "| Run | Milestones | Curve |", "|---|---|---|"]
    runs = sorted((RESULTS / "learn_walk").glob("*/milestones.json")) + sorted(
        (RESULTS / "learn_hike").glob("*/milestones.json")) + sorted(
        (RESULTS / "learn_student").glob("*/milestones.json"))
    for path in runs:
        meta = json.loads(path.read_text())
        curve = path.parent / "curve.png"
        name = f"{path.parent.parent.name}/{path.parent.name}"
        link = f"[curve]({rel(curve)})" if curve.exists() else "-"
        evals = path.parent / "evals.csv"
        first = 0  # no evaluation logged: no milestone can read as met at the first
        if evals.is_file():
            with open(evals) as f:
                first = int(float(next(csv.DictReader(f), {"frames": 0})["frames"]))
        lines.append(f"| `{name}` | {milestone_text(meta['milestones'], first)} | {link} |")
    lines.append("")
    for path in runs:
        if path.parent.parent.name != "learn_walk" and (path.parent / "curve.png").exists():
            lines += [f"![{path.parent.name}]({rel(path.parent / 'curve.png')})", ""]
    return lines


def averages_section() -> list[str]:
    """Each student run's ``bench_average.csv`` (``learn_student.py --average K``): the mean
    of K snapshots' weights beside the mean of the benchmarked snapshots it spans."""
    paths = sorted((RESULTS / "learn_student").glob("*/bench_average.csv"))
    if not paths:
        return []
    cols = ("d_sr", *(f"sr_{c}" for c in CATEGORIES))
    lines = ["## Averaged student snapshots", "",
             "SR % of the mean of K snapshots' weights (`learn_student.py --average K`) and, "
             "in brackets, the mean of the snapshots benchmarked within its span "
             "(`bench.csv`, where the run has one); same benchmark, same seeds.", "",
             "| Run | K | Minutes | RandomMix 0-2 | " + " | ".join(
                 "RandomMix" if c == "randommix" else c.capitalize() for c in CATEGORIES) + " |",
             "|---|---|---|---|" + "---|" * len(CATEGORIES)]
    for path in paths:
        bench = path.parent / "bench.csv"  # absent where no snapshot was benchmarked
        snaps = list(csv.DictReader(bench.open(newline=""))) if bench.is_file() else []
        with open(path, newline="") as f:
            for row in csv.DictReader(f):
                lo, hi = float(row["first_iteration"]), float(row["iteration"])
                span = [r for r in snaps if lo <= float(r["iteration"]) <= hi]
                cells = [f"{float(row[c]):.0f}" + (
                    f" ({sum(float(r[c]) for r in span) / len(span):.0f})" if span else "")
                    for c in cols]
                lines.append(f"| `{path.parent.name}` | {float(row['snapshots']):.0f} | "
                             f"{float(row['first_minutes']):.0f}-{float(row['minutes']):.0f} | "
                             + " | ".join(cells) + " |")
    return lines + [""]


def films_section() -> list[str]:
    strips = sorted(RESULTS.glob("**/*_filmstrip.png")) + sorted(
        PRETRAINED.glob("**/*_filmstrip.png"))
    strips = [s for s in strips if HILL not in s.parents]
    if not strips:
        return []
    lines = ["## Filmstrips", "", "Every strip has its MP4 beside it.", ""]
    for strip in strips:
        video = strip.with_name(strip.name.replace("_filmstrip.png", ".mp4"))
        label = strip.relative_to(ROOT).as_posix()
        lines += [f"**`{label}`**" + (f" ([video]({rel(video)}))" if video.exists() else ""),
                  "", f"![{strip.stem}]({rel(strip)})", ""]
    return lines


def hill_section() -> list[str]:
    """Each robot's shipped oracle on the hill trail (H1 first), and beside it each shipped
    student filmed there (``--hill [--robot R] --stage unified``)."""
    robots = sorted(p.stem for p in (ROOT / "conf" / "robot").glob("*.yaml"))
    bases = [hill_dir(robot, "oracle") for robot in ("h1", *(r for r in robots if r != "h1"))]
    folders = [d for base in bases for d in (base, *sorted(p for p in base.glob("*")
                                                           if p.is_dir() and p not in bases))]
    summaries = [json.loads(p.read_text()) for p in (d / "summary.json" for d in folders)
                 if p.exists()]
    if not summaries:
        return []
    lines = ["## Zero-shot on a hill trail", ""]
    for s in summaries:
        stage = s.get("stage", "oracle")
        out = hill_dir(s["robot"], stage)
        who = "oracle" if stage == "oracle" else f"{stage} student (from depth)"
        lines += [f"The shipped {s['robot'].upper()} {who} on `trail=hill` (level "
                  f"{s['level']}: {s['length_m']:.0f} m of chained RandomMix, Ditch, Hurdle, "
                  "Gap and Forest over a hillside, never seen in training), from the trail "
                  f"start, {s['seconds']:.0f} s. The filmed robot walked "
                  f"{s['film_distance_m']:.1f} m toward the terminus and "
                  f"{'fell' if s['film_fell'] else 'did not fall'}; over {s['robots']} "
                  f"robots: {s['mean_distance_m']:.1f} m on average, "
                  f"{s['fell_share'] * 100:.0f} % fell, {s['reached_share'] * 100:.0f} % "
                  "reached the terminus. Written by `python experiments/results_page.py "
                  f"--hill{'' if s['robot'] == 'h1' else ' --robot ' + s['robot']}"
                  f"{'' if stage == 'oracle' else ' --stage ' + stage}`.", "",
                  f"[video]({rel(out / 'hill.mp4')})", "",
                  f"![hill filmstrip]({rel(out / 'hill_filmstrip.png')})", "",
                  f"![hill trajectories]({rel(out / 'trajectories.png')})", ""]
    return lines


def study_section() -> list[str]:
    """The paper's study at CPU scale: each of ``paper_tables.md``'s tables by its title and
    its agreement line, with a link to the tables themselves (the page stays a summary)."""
    path = RESULTS / "paper_tables.md"
    if not path.exists():
        return []
    lines = ["## The paper's study at CPU scale", "",
             f"From [`{rel(path)}`]({rel(path)}) (`python experiments/paper_tables.py`): our "
             "jobs beside the appendix's tables, per metric; compare the orderings, not the "
             "values. Each table and how many orderings agree:", ""]
    title, older, progress = None, "", []
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("## "):
            title, older = line[3:], ""
        elif title == "Where the sweep stands":
            # the sweep's state, as the tables page has it, links made relative to this page
            progress.append(re.sub(r"\]\(([^)]+)\)",
                                   lambda m: f"]({rel(path.parent / m.group(1))})", line))
        elif line.startswith("**Not this budget**") and title is not None:
            older = " (an older budget's table: " + line.split(": ", 1)[1].split(";")[0] + ")"
        elif line.startswith("Where both separate") and title is not None:
            lines += [f"- **{title}**{older}: {line[0].lower()}{line[1:]}"]
            title = None
    if progress:
        lines += ["", "### Where the sweep stands", *progress]
    return lines + [""]


def write_page() -> Path:
    lines = ["# Results", "",
             "Written by `python experiments/results_page.py` from the committed results; "
             "do not edit by hand.", ""]
    for section in (shipped_section, hill_section, study_section, campaigns_section,
                    averages_section, films_section):
        lines += section()
    PAGE.write_text("\n".join(lines))
    return PAGE


def hill_dir(robot: str, stage: str) -> Path:
    """Where the hill trail's film and benchmark of a shipped policy go: ``hill/`` for H1's
    oracle (as first committed), ``hill/<stage>/`` for its student (``unified``, ...);
    another robot's under ``hill/<robot>/`` the same way."""
    base = HILL if robot == "h1" else HILL / robot
    return base if stage == "oracle" else base / stage


def film_hill(robot: str, level: int, robots: int, seconds: float | None = None,
              stage: str = "oracle") -> None:
    """The shipped policy of ``stage`` (``oracle``, or a student: ``unified``) from the start
    of a hill trail: a video of robot 0 (a student's with its depth view beside), and every
    robot's path over the map (the benchmark's trajectories picture). ``seconds`` defaults
    to the benchmark's time per metre of path (``from_start_seconds``)."""
    from legoh.config.compose import compose_config
    from legoh.eval.benchmark import evaluate, from_start_seconds, make_eval_env
    from legoh.eval.cli import build_actor, for_checkpoint
    from legoh.play import render_policy_video

    cfg = compose_config(f"robot={robot}", "trail=hill", f"eval.robots={robots}",
                         "eval.runs=1", "eval.variants=1", f"eval.levels=[{level}]",
                         "eval.spawn_remaining=null",
                         *([] if stage == "oracle" else [f"algo={stage}"]))
    cfg, _ = for_checkpoint(cfg, "pretrained")  # its own feet (and a student's camera)
    env = make_eval_env(cfg)
    length = float(env.trails_t.length.max())  # m of expert path, start to terminus
    env.close()
    seconds = from_start_seconds(length) if seconds is None else float(seconds)
    cfg.eval.seconds = seconds
    policy, env_fn = build_actor(cfg, "pretrained")  # what mode=play and mode=eval load
    actor = policy.policy if env_fn is not None else policy
    out = hill_dir(robot, stage)
    out.mkdir(parents=True, exist_ok=True)
    film = render_policy_video(cfg, actor, out / "hill.mp4", level=level,
                               student=policy if env_fn is not None else None)
    result = evaluate(cfg, actor, out, label=f"{robot}_{stage} on hill", env_fn=env_fn)
    overall = result["rows"]["overall"]
    summary = {"robot": robot, "stage": stage, "level": level, "seconds": seconds,
               "robots": robots, "length_m": length, "film_distance_m": film["distance"],
               "film_fell": film["fell"], "mean_distance_m": overall["DW"][0],
               "fell_share": overall["FR"][0] / 100.0, "reached_share": overall["SR"][0] / 100.0}
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    print(json.dumps(summary, indent=2))


def film_demo(robot: str, trail: str, width: int = 360, every: int = 3) -> Path:
    """The README's picture: the shipped oracle as ``python run.py mode=play
    checkpoint=pretrained trail=<trail>`` films it, as a GIF (``width`` px wide, every
    ``every``-th frame) in docs/img/."""
    import imageio.v3 as iio
    from PIL import Image

    from legoh.config.compose import compose_config
    from legoh.eval.cli import build_actor, for_checkpoint
    from legoh.play import render_policy_video

    cfg = compose_config(f"robot={robot}", f"trail={trail}", "mode=play",
                         "checkpoint=pretrained")
    cfg, _ = for_checkpoint(cfg, "pretrained")  # its own feet, as mode=play films it
    actor, _ = build_actor(cfg, "pretrained")  # what mode=play loads
    out = RESULTS / "demo" / f"{robot}_{trail}.mp4"
    film = render_policy_video(cfg, actor, out)
    frames = iio.imread(film["video"])[::every]
    height = int(round(frames.shape[1] * width / frames.shape[2]))
    # a 96-colour palette per frame, no dithering: ~3 MB for a 12 s walk (dithered, 10 MB)
    small = [Image.fromarray(f).resize((width, height), Image.LANCZOS).quantize(
        colors=96, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE) for f in frames]
    gif = ROOT / "docs" / "img" / f"demo_{robot}_{trail}.gif"
    small[0].save(gif, save_all=True, append_images=small[1:], loop=0, optimize=True,
                  duration=int(round(1000.0 * every / 25.0)))  # play films 25 fps
    print(f"{gif}: robot 0 walked {film['distance']:.1f} m, "
          f"{'fell' if film['fell'] else 'did not fall'}")
    return gif


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hill", action="store_true", help="film the hill trail first")
    parser.add_argument("--demo", metavar="TRAIL", help="film the README's GIF on TRAIL")
    parser.add_argument("--robot", default="h1")
    parser.add_argument("--level", type=int, default=1, help="the hill trail's level")
    parser.add_argument("--robots", type=int, default=16)
    parser.add_argument("--stage", default="oracle",
                        help="--hill: the shipped policy, oracle or a student (unified)")
    parser.add_argument("--seconds", type=float, default=None,
                        help="--hill: the horizon (default: 3 s a metre of the trail's path, "
                             "the benchmark's own: 192 s for level 1's 64 m)")
    args = parser.parse_args()
    if args.hill:
        film_hill(args.robot, args.level, args.robots, args.seconds, args.stage)
    if args.demo:
        film_demo(args.robot, args.demo)
    print(f"wrote {write_page()}")


if __name__ == "__main__":
    main()
