"""The benchmark protocol (``conf/eval``): robots on fixed levels, the paper's tables.

For each run r (terrain and env seeded with ``s + r``, ``s`` = ``eval.seed`` when set, else
the run's ``seed``: :func:`eval_seed`) an evaluation env is built
once: ``eval.robots`` robots spread round-robin over the trail's categories, the terminus
reach radius of evaluation (0.89 m), episodes of ``eval.seconds``, curriculum off, each
robot spawned on an expert waypoint with ``eval.spawn_remaining`` m of path left (null: at
the trail start), Table 5's randomisation on from the first step unless
``eval.randomization=false`` (:func:`eval_randomization`). For each level in
``eval.levels`` every robot is put on that level (a random one of ``eval.variants``
variants each) and the deterministic policy runs until every robot has ended its first
episode (reach, fall or timeout; only the first episode counts, ``docs/metrics.md``), at
most ``seconds / dt`` steps. A run's metrics pool the robots of all its levels, per
category and overall, and per level; tables give mean ± std over runs.

Files written to ``out_dir`` per evaluation: ``benchmark.md`` and ``benchmark.csv`` (per
category and overall, then per level: rows ``level <l>``; mean and std over runs),
``benchmark_runs.csv`` (the same rows, each run's own values: what a study pools) and
``trajectories.png`` (first run, hardest level, one panel per category).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf
from torchrl.envs import EnvBase
from torchrl.envs.utils import ExplorationType, set_exploration_type
from tqdm import tqdm

from legoh import keys
from legoh.config.env import RandomizationConfig, from_first_step
from legoh.config.eval import EvalConfig
from legoh.eval.metrics import (
    SIGNALS,
    TC_RADIUS,
    RobotOutcomes,
    aggregate,
    distance_walked,
    robot_outcomes,
    summarize,
    to_markdown,
    write_csv,
    write_runs_csv,
)
from legoh.eval.plots import outcome_labels, plot_trajectories
from legoh.eval.protocol import LEGACY, machine, protocol_of, same_protocol
from legoh.policies.student import make_student_env, state_shapes
from legoh.threads import torch_threads

OVERALL = "overall"
# Bumped by a change that moves the scores of the same policy under the same ``eval``
# settings (spawns, randomisation draws, metric definitions): a score cached under another
# version (learn_student's teacher.json) is stale. 2: the randomisation drawn from the
# first step (``from_first_step``). 3: protocol v2's spawns (``legoh.eval.protocol``).
BENCHMARK_VERSION = 3


@dataclasses.dataclass(frozen=True)
class LevelRecord:
    """All robots' first episodes on one level of one run."""

    level: int
    outcomes: RobotOutcomes  # per robot, (N,) each
    category: np.ndarray  # (N,) category names
    tile: np.ndarray  # (N,) tile index of each robot's first episode
    paths: list[np.ndarray]  # N arrays (T_n, 3): torso path, start first, world frame, m
    steps: int  # policy steps simulated


def eval_seed(cfg: DictConfig) -> tuple[int, str]:
    """The evaluation's base seed and where it came from: ``eval.seed`` when set, else the
    run's ``seed`` (``seed=987654 mode=eval`` used to equal ``seed=0``: eval.seed was 0)."""
    if cfg.eval.seed is None:
        return int(cfg.seed), "seed"
    return int(cfg.eval.seed), "eval.seed"


def run_config(cfg: DictConfig, run: int) -> DictConfig:
    """The config of run ``run``: seed :func:`eval_seed` ``+ run``, the eval's variants and
    categories in the trail. Levels must exist in the trail (they set the difficulty)."""
    ev = cfg.eval
    bad = [lv for lv in ev.levels if not 0 <= lv < cfg.trail.levels]
    if bad:
        raise ValueError(f"eval.levels {list(ev.levels)}: {bad} not in the trail's levels "
                         f"0..{cfg.trail.levels - 1} (set trail.levels)")
    trail = {"variants": ev.variants}
    if ev.categories:
        trail["categories"] = list(ev.categories)
    return OmegaConf.merge(cfg, {"seed": eval_seed(cfg)[0] + run, "trail": trail})


def eval_randomization(cfg: DictConfig) -> RandomizationConfig:
    """The env's Table 5 randomisation during an evaluation: ``eval.randomization`` turns
    it on or off; the policy under test is trained, so its schedule is open from the
    first step (physics draws, pushes and action delays)."""
    return from_first_step(OmegaConf.to_object(cfg.env.randomization),
                           enabled=bool(cfg.eval.randomization))


def eval_env_settings(cfg: DictConfig, run: int) -> tuple[DictConfig, int, dict]:
    """(config, robots, env overrides) of run ``run``'s evaluation env: curriculum off,
    episodes of ``eval.seconds``, spawns ``eval.spawn_remaining`` m of path from the
    terminus without xy jitter (protocol v2: a robot starts on its waypoint, on its support,
    the obstacle ahead; ``spawns.trail_spawn``), :func:`eval_randomization` (the evaluation
    reach radius comes with ``evaluation``). With ``eval.spawn_remaining`` null every robot
    starts at the trail start: training's ``env.spawn_along`` share is off."""
    ev = cfg.eval
    curriculum = dataclasses.replace(OmegaConf.to_object(cfg.env.curriculum), enabled=False)
    spawn = None if ev.spawn_remaining is None else [float(x) for x in ev.spawn_remaining]
    return (run_config(cfg, run), ev.robots,
            {"episode_length_s": float(ev.seconds), "curriculum": curriculum,
             "spawn_remaining": spawn, "spawn_noise": 0.0,
             # no robot of a from-the-start evaluation (the hill trail) starts mid-trail
             "spawn_along": 0.0, "randomization": eval_randomization(cfg)})


def from_start_seconds(length_m: float) -> float:
    """The horizon of a from-the-start evaluation (``eval.spawn_remaining=null``, the hill
    trail) over ``length_m`` of expert path: the benchmark's own time per metre, its episode
    over its longest spawn (30 s for 10 m: 3 s/m, 2.4 x a flawless walk at the 0.8 m/s
    command), so a long trail gets the slack a benchmark robot gets (64 m: 192 s)."""
    protocol = EvalConfig()
    return protocol.seconds / max(protocol.spawn_remaining) * float(length_m)


def student_eval_env_fn(cfg: DictConfig, student) -> Callable[[int], EnvBase]:
    """The env factory of a student's evaluation: run ``run``'s evaluation env with the
    student's sensors (depth) and its recurrent state primed."""
    shapes = state_shapes(student)

    def make(run: int) -> EnvBase:
        run_cfg, num_envs, overrides = eval_env_settings(cfg, run)
        return make_student_env(run_cfg, num_envs, shapes, evaluation=True, **overrides)

    return make


def make_eval_env(cfg: DictConfig, run: int = 0):
    """The evaluation env of run ``run`` (curriculum off, evaluation reach radius)."""
    from legoh.envs.hiking_env import make_env

    run_cfg, robots, overrides = eval_env_settings(cfg, run)
    return make_env(run_cfg, num_envs=robots, evaluation=True, **overrides)


def rollout_level(env, actor, level: int, tc_radius: float = TC_RADIUS) -> LevelRecord:
    """Every robot on ``level``; step the deterministic ``actor`` until each robot has ended
    its first episode (at most the env's ``max_steps``, where it is truncated). TC counts
    the expert waypoints ahead of each robot's spawn (its first goal index up to, not
    including, the terminus) passed within ``tc_radius`` m."""
    n = env.num_envs
    env.set_level(level)
    td = env.reset()
    start = td[keys.BASE_POS].cpu().numpy().copy()
    tile = td[keys.TILE].cpu().numpy().copy()
    count = td[keys.WAYPOINT_COUNT].cpu().numpy().copy()
    first = td[keys.WAYPOINT].cpu().numpy().copy()  # the goal index each robot starts with
    progress_start = td[keys.PROGRESS].cpu().numpy().astype(float)
    signals = {s: [] for s in (*SIGNALS, "done")}
    pos = []
    ended = np.zeros(n, dtype=bool)
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        for _ in range(env.max_steps):
            td, root = env.step_and_maybe_reset(actor(td))
            nxt = td["next"]
            for s in SIGNALS:
                signals[s].append(nxt[keys.INFO, s].cpu().numpy().copy())
            done = nxt[keys.DONE].reshape(n).cpu().numpy().copy()
            signals["done"].append(done)
            pos.append(nxt[keys.BASE_POS].cpu().numpy().copy())
            ended |= done
            if ended.all():
                break
            td = root
    arr = {k: np.stack(v) for k, v in signals.items()}  # (T, N)
    t_len = len(pos)
    last = np.where(arr["done"].any(axis=0), arr["done"].argmax(axis=0), t_len - 1)
    track = np.concatenate([start[None], np.stack(pos)])  # (T + 1, N, 3)
    paths = [track[: last[i] + 2, i] for i in range(n)]
    ahead = [env.trails.waypoints[tile[i], first[i]: count[i] - 1] for i in range(n)]
    walked = distance_walked(start, track[last + 1, np.arange(n)], env.trails.terminus[tile])
    out = robot_outcomes(dt=env.dt, distance=walked, progress_start=progress_start,
                         paths=paths, waypoints=ahead, tc_radius=tc_radius, **arr)
    names = np.asarray(env.terrain.categories)[env.category.cpu().numpy()]
    return LevelRecord(level=level, outcomes=out, category=names, tile=tile, paths=paths,
                       steps=t_len)


def _concat(outs: list[RobotOutcomes]) -> RobotOutcomes:
    return RobotOutcomes(**{f.name: np.concatenate([getattr(o, f.name) for o in outs])
                            for f in dataclasses.fields(RobotOutcomes)})


def run_metrics(records: list[LevelRecord]) -> dict[str, dict[str, float]]:
    """One run's metrics, robots of all levels pooled: per category, ``"overall"``, and
    per level (``"level <l>"``)."""
    out = _concat([r.outcomes for r in records])
    cats = np.concatenate([r.category for r in records])
    levels = np.concatenate([np.full(len(r.category), r.level) for r in records])
    rows = {str(c): aggregate(out, cats == c) for c in dict.fromkeys(cats.tolist())}
    rows[OVERALL] = aggregate(out)
    rows.update({f"level {lv}": aggregate(out, levels == lv) for lv in
                 dict.fromkeys(levels.tolist())})
    return rows


def plot_run(env, records: list[LevelRecord], path: Path, title: str) -> Path:
    """Trajectories of the hardest evaluated level: per category, the robots on its most
    used tile."""
    rec = max(records, key=lambda r: r.level)
    labels = outcome_labels(rec.outcomes.success, rec.outcomes.fall)
    keep = np.zeros(len(rec.tile), dtype=bool)
    for c in dict.fromkeys(rec.category.tolist()):
        tiles, counts = np.unique(rec.tile[rec.category == c], return_counts=True)
        keep |= (rec.category == c) & (rec.tile == tiles[counts.argmax()])
    ids = np.flatnonzero(keep)
    return plot_trajectories(env.terrain, rec.tile[ids], [rec.paths[i] for i in ids],
                             labels[ids], path, title=title)


def evaluate(cfg: DictConfig, actor, out_dir: str | Path, label: str = "policy",
             progress: bool = True, env_fn: Callable[[int], EnvBase] | None = None) -> dict:
    """Run the protocol ``cfg.eval`` with ``actor`` (a TensorDict policy writing
    ``"action"``; its deterministic mode is used) and write the tables and picture.

    ``env_fn(run)`` builds run ``run``'s env when the policy needs more than the plain
    evaluation env (a depth student: depth on, recurrent state primed); it must start from
    :func:`eval_env_settings`.

    Returns:
        ``{"label", "rows": {category..., "overall": {metric: (mean, std)}},
        "levels": {"level <l>": ...}, "runs": [per-run rows], "paths": {"markdown",
        "csv", "runs_csv", "trajectories"}, "wall_s", "steps", "protocol"}``; every file
        names the protocol (``legoh.eval.protocol.PROTOCOL``).
    """
    ev = cfg.eval
    seed, source = eval_seed(cfg)
    print(f"[legoh] evaluating {label} with seed {seed} (from {source}; runs use seeds "
          f"{seed}..{seed + ev.runs - 1})")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = {"trajectories": out_dir / "trajectories.png"}
    runs, steps, t0 = [], 0, time.perf_counter()
    bar = tqdm(total=ev.runs * len(ev.levels), desc=f"eval {label}", disable=not progress)
    was_training = getattr(actor, "training", False)
    if was_training:
        actor.eval()
    try:
        with torch_threads(1):
            for r in range(ev.runs):
                env = env_fn(r) if env_fn is not None else make_eval_env(cfg, r)
                try:
                    records = []
                    for level in ev.levels:
                        bar.set_postfix(run=r, level=level)
                        records.append(rollout_level(env, actor, int(level),
                                                     float(ev.tc_radius)))
                        steps += records[-1].steps
                        bar.update()
                    runs.append(run_metrics(records))
                    if r == 0:
                        plot_run(env, records, paths["trajectories"],
                                 f"{label}: {cfg.trail.name}, run 0")
                finally:
                    env.close()
    finally:
        bar.close()
        if was_training:
            actor.train()
    protocol = protocol_of(cfg)
    names = list(runs[0])
    is_level = [k.startswith("level ") for k in names]
    summary = {k: summarize([run[k] for run in runs]) for k in names}
    rows = {k: summary[k] for k, lv in zip(names, is_level, strict=True) if not lv}
    levels = {k: summary[k] for k, lv in zip(names, is_level, strict=True) if lv}
    title = (f"{label} on {cfg.trail.name} ({cfg.robot.name}): {ev.robots} robots x "
             f"{ev.seconds:g} s, levels {list(ev.levels)} x {ev.variants} variants, "
             f"{ev.runs} run(s), mean ± std over runs, benchmark protocol {protocol}; "
             f"scored on {machine()}")
    paths["markdown"] = out_dir / "benchmark.md"
    paths["markdown"].write_text(to_markdown(rows, "Category", title) + "\n"
                                 + to_markdown(levels, "Level", "Per level"), encoding="utf-8")
    paths["csv"] = write_csv(out_dir / "benchmark.csv", {**rows, **levels}, label="category",
                             protocol=protocol)
    paths["runs_csv"] = write_runs_csv(out_dir / "benchmark_runs.csv", runs, protocol=protocol)
    return {"label": label, "rows": rows, "levels": levels, "runs": runs, "paths": paths,
            "wall_s": time.perf_counter() - t0, "steps": steps, "protocol": protocol}


def compare(results: Mapping[str, dict], row: str = OVERALL
            ) -> dict[str, dict[str, tuple[float, float]]]:
    """Rows of a methods table: ``{label: summary of row}`` (``row``: ``"overall"``, a
    category name or ``"level <l>"``), for :func:`legoh.eval.metrics.to_markdown`. Raises
    ``ProtocolMismatch`` when the results were scored on different protocols."""
    same_protocol({label: r.get("protocol", LEGACY) for label, r in results.items()})
    table = {}
    for label, result in results.items():
        merged = {**result["rows"], **result.get("levels", {})}
        if row not in merged:
            raise KeyError(f"{label!r} has no row {row!r}; it has {sorted(merged)}")
        table[label] = merged[row]
    return table
