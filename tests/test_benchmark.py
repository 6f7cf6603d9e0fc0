"""Benchmark protocol: the eval config group, a tiny evaluation end to end, its files."""

import copy
import csv
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from hydra.errors import ConfigCompositionException
from tensordict.nn import TensorDictModule

from legoh import keys
from legoh.checkpoint import CheckpointError, make_payload, save_checkpoint
from legoh.envs.hiking_env import make_env
from legoh.envs.mdp.events import randomizing
from legoh.eval.benchmark import (
    OVERALL,
    compare,
    eval_env_settings,
    evaluate,
    from_start_seconds,
    make_eval_env,
    rollout_level,
    run_config,
)
from legoh.eval.cli import build_actor, main
from legoh.eval.metrics import METRICS, column_title, distance_walked
from legoh.eval.plots import plot_trajectories
from legoh.eval.protocol import PROTOCOL, ProtocolMismatch, machine, of_csv
from legoh.eval.study import read_overall
from legoh.modules.actor_critic import OracleInputDims
from tests.conftest import compose_config

TINY = ("trail=flat", "trail.levels=1", "trail.variants=1", "eval.robots=2", "eval.seconds=1",
        "eval.levels=[0]", "eval.variants=1", "eval.runs=1")


def test_default_protocol_is_quick() -> None:
    ev = compose_config().eval
    assert ev.seconds == 30.0 and ev.runs >= 2 and list(ev.levels) == [0, 1, 2]
    assert list(ev.spawn_remaining) == [2.0, 10.0] and ev.tc_radius == 0.3
    assert ev.randomization is True


def test_table8_is_the_papers_protocol() -> None:
    ev = compose_config("eval=table8").eval
    assert (ev.robots, ev.seconds, list(ev.levels), ev.variants, ev.runs) == (
        256, 30.0, [0, 1, 2, 3, 4], 5, 5)
    assert list(ev.categories) == []
    assert (list(ev.spawn_remaining), ev.tc_radius, ev.randomization) == ([2.0, 10.0], 0.3,
                                                                          True)


def test_mistyped_eval_key_is_named() -> None:
    with pytest.raises(ConfigCompositionException, match="robtos"):
        compose_config("eval.robtos=3")


def test_run_config_seeds_runs_and_checks_levels() -> None:
    cfg = compose_config(*TINY, "eval.seed=7", "eval.variants=3")
    run = run_config(cfg, 2)
    assert run.seed == 9 and run.trail.variants == 3 and list(run.trail.categories) == ["flat"]
    with pytest.raises(ValueError, match="eval.levels"):
        run_config(compose_config(*TINY, "eval.levels=[0,1]"), 0)


def test_the_runs_seed_rules_the_evaluation_unless_eval_seed_is_set() -> None:
    """``seed=987654`` seeds the evaluation's terrain and env; ``eval.seed`` still wins.

    Failed before with: run 0 seeded 0 for seed=987654 (eval.seed's default 0 ruled)."""
    assert run_config(compose_config(*TINY, "seed=987654"), 0).seed == 987654
    from legoh.eval.benchmark import eval_seed

    assert eval_seed(compose_config(*TINY, "seed=987654")) == (987654, "seed")
    assert eval_seed(compose_config(*TINY, "seed=987654", "eval.seed=3")) == (3, "eval.seed")


def test_eval_env_settings_spawn_along_the_trail_and_randomise() -> None:
    """Failed before with: KeyError 'spawn_remaining' (every robot at the trail start, 22 m
    from the terminus) and no randomisation in an evaluation."""
    _, _, env = eval_env_settings(compose_config(*TINY), 0)
    rand = env["randomization"]
    assert env["spawn_remaining"] == [2.0, 10.0]
    assert (rand.enabled, rand.start_after_steps, rand.delay_after_steps) == (True, 0, 0)
    _, _, old = eval_env_settings(compose_config(*TINY, "eval.spawn_remaining=null",
                                                 "eval.randomization=false"), 0)
    assert old["spawn_remaining"] is None and old["randomization"].enabled is False


def test_eval_robots_stand_on_waypoints_with_the_path_left_in_range() -> None:
    """The evaluation env puts each robot on an expert waypoint with 2-10 m of path left to
    the terminus, its goal index at the next waypoint, randomisation already drawing."""
    env = make_eval_env(compose_config(*TINY, "eval.robots=8"))
    try:
        td = env.reset()
        t, tile = env.trails, td[keys.TILE].numpy()
        goal = td[keys.WAYPOINT].numpy()
        assert (goal >= 1).all() and (goal <= t.count[tile] - 1).all()
        left = t.length[tile] - t.cum_length[tile, goal - 1]
        assert ((left >= 2.0 - 1e-9) & (left <= 10.0 + 1e-9)).all()
        offset = np.abs(td[keys.BASE_POS][:, :2].numpy() - t.waypoints[tile, goal - 1])
        assert (offset <= env.cfg.spawn_noise + 1e-6).all()
        assert randomizing(env) and env.action_delay.delay.max() <= 1
    finally:
        env.close()


def test_a_from_the_start_evaluation_starts_every_robot_at_the_trail_start() -> None:
    """``eval.spawn_remaining=null`` (the hill trail's protocol): every robot on its trail's
    start pad, none along the trail.

    Failed before with: training's ``env.spawn_along`` (0.5) reached the evaluation env, so
    about half the robots started mid-trail (goal index > 0), some a few metres from the
    terminus: the hill trail's films and DW / reach shares mixed both starts."""
    env = make_eval_env(compose_config(*TINY, "eval.robots=16", "eval.spawn_remaining=null"))
    try:
        td = env.reset()
        tile = td[keys.TILE].numpy()
        assert (td[keys.WAYPOINT].numpy() == 0).all()
        start = env.trails.start[tile][:, :2]
        assert np.abs(td[keys.BASE_POS][:, :2].numpy() - start).max() < 1e-6
    finally:
        env.close()


def test_a_from_start_horizon_gives_the_benchmarks_time_per_metre() -> None:
    """The hill trail's horizon is the benchmark's own slack per metre of path: its longest
    spawn (10 m left) gets exactly the protocol's 30 s, and a trail twice as long twice that;
    the hill's 64 m get 192 s (it was a fixed 90 s: 1.1 x a flawless walk)."""
    protocol = compose_config().eval
    longest = max(protocol.spawn_remaining)
    assert from_start_seconds(longest) == pytest.approx(protocol.seconds)
    assert from_start_seconds(2 * longest) == pytest.approx(2 * protocol.seconds)
    assert from_start_seconds(64.0) == pytest.approx(192.0)


def test_the_walk_test_starts_every_robot_at_the_trail_start() -> None:
    """learn_walk's walk test (the campaigns' (s1)): every robot at its trail start.

    Failed before with: KeyError 'spawn_along' (training's share of mid-trail spawns, 0.5
    under recipe v2, reached the walk test: its metres walked mixed starts 2-20 m from the
    terminus)."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
    from learn_walk import walk_env_settings

    run, overrides = walk_env_settings(compose_config(*TINY), "flat", randomize=False)
    assert overrides["spawn_along"] == 0.0
    env = make_env(run, num_envs=16, evaluation=True, **overrides)
    try:
        assert (env.reset()[keys.WAYPOINT].numpy() == 0).all()
    finally:
        env.close()


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> tuple:
    cfg = compose_config(*TINY)
    actor, _ = build_actor(cfg)
    out = tmp_path_factory.mktemp("eval")
    return cfg, actor, evaluate(cfg, actor, out, label="untrained", progress=False)


def test_evaluation_writes_the_tables_and_picture(tiny: tuple) -> None:
    _, _, result = tiny
    paths = result["paths"]
    assert {p.name for p in paths.values()} == {"benchmark.md", "benchmark.csv",
                                                "benchmark_runs.csv", "trajectories.png"}
    with open(paths["csv"], encoding="utf-8", newline="") as f:
        table = list(csv.reader(f))
    assert table[0] == ["category"] + [f"{column_title(m)} {s}" for m in METRICS
                                       for s in ("mean", "std")] + ["protocol"]
    assert {row[-1] for row in table[1:]} == {PROTOCOL} and result["protocol"] == PROTOCOL
    assert [row[0] for row in table[1:]] == ["flat", OVERALL, "level 0"]  # per level too
    with open(paths["runs_csv"], encoding="utf-8", newline="") as f:
        runs = list(csv.DictReader(f))  # each run's own values, what a study pools
    sr = column_title("SR")
    assert [(r["run"], r["category"]) for r in runs] == [("0", "flat"), ("0", OVERALL),
                                                         ("0", "level 0")]
    assert float(runs[1][sr]) == pytest.approx(float(table[2][1]))  # one run: its mean
    md = paths["markdown"].read_text(encoding="utf-8")
    assert "| flat |" in md and "| overall |" in md and "| level 0 |" in md
    assert f"benchmark protocol {PROTOCOL}" in md
    assert f"scored on {machine()}" in md and "torch kernels" in machine()  # which CPU
    assert of_csv(paths["csv"]) == of_csv(paths["runs_csv"]) == PROTOCOL
    assert paths["trajectories"].read_bytes()[:4] == b"\x89PNG"


def test_evaluation_results_are_per_category_and_bounded(tiny: tuple) -> None:
    _, _, result = tiny
    assert list(result["rows"]) == ["flat", OVERALL] and list(result["levels"]) == ["level 0"]
    overall = result["rows"][OVERALL]
    assert set(overall) == set(METRICS)
    for m in ("TTF", "T2R"):  # episodes last at most eval.seconds (NaN: no fall / reach)
        assert np.isnan(overall[m][0]) or 0.0 < overall[m][0] <= 1.0 + 1e-9
    assert 0.0 <= overall["FR"][0] <= 100.0
    assert 0.0 <= overall["SR"][0] <= 100.0 and overall["SR"][1] == 0.0  # one run: std 0
    assert 0 < result["steps"] <= 50  # 1 s at 50 Hz, stopped once every robot is done


def test_untrained_policy_walks_about_nowhere(tiny: tuple) -> None:
    """DW on a real evaluation: 1 s of an untrained policy moves the base by centimetres
    (a fall would move it by about 1 m), and the CSV carries the column."""
    _, _, result = tiny
    mean, std = result["rows"][OVERALL]["DW"]
    assert np.isfinite(mean) and abs(mean) < 0.5 and std == 0.0
    assert read_overall(result["paths"]["csv"])["DW"] == pytest.approx(mean)


def test_dw_of_a_standing_robot_is_zero_and_matches_its_path(tiny: tuple) -> None:
    """Zero actions hold the default pose: each robot's DW is ~0 and is exactly
    distance_walked of its recorded path's first and last points."""
    cfg = tiny[0]
    env = make_eval_env(cfg)
    try:
        zero = TensorDictModule(lambda obs: torch.zeros(env.action_spec.shape),
                                in_keys=[keys.PROPRIO], out_keys=[keys.ACTION])
        rec = rollout_level(env, zero, 0)
        goal = env.trails.terminus[rec.tile]
    finally:
        env.close()
    walked = rec.outcomes.distance
    assert np.isfinite(walked).all() and np.abs(walked).max() < 0.1
    start, end = np.array([p[0] for p in rec.paths]), np.array([p[-1] for p in rec.paths])
    np.testing.assert_allclose(walked, distance_walked(start, end, goal))


def test_a_csv_from_before_dw_still_reads(tmp_path: Path) -> None:
    cols = [m for m in METRICS if m != "DW"]
    path = tmp_path / "benchmark.csv"
    path.write_text(",".join(["category"] + [f"{column_title(m)} mean" for m in cols])
                    + "\noverall," + ",".join(["1.0"] * len(cols)) + "\n", encoding="utf-8")
    got = read_overall(path)
    assert got["SR"] == 1.0 and np.isnan(got["DW"])


def test_compare_puts_policies_side_by_side(tiny: tuple) -> None:
    _, _, result = tiny
    rows = compare({"trained": result, "untrained": result})
    assert list(rows) == ["trained", "untrained"]
    assert rows["trained"] == result["rows"][OVERALL]
    assert compare({"a": result}, row="level 0")["a"] == result["levels"]["level 0"]
    with pytest.raises(KeyError, match="ditch"):
        compare({"a": result}, row="ditch")


def test_compare_refuses_results_of_two_protocols(tiny: tuple) -> None:
    """A result of another protocol (here one from before the protocol was named: v1) is
    never set beside this one: the error names both versions."""
    _, _, result = tiny
    old = {k: v for k, v in result.items() if k != "protocol"}
    with pytest.raises(ProtocolMismatch, match=f"v1: old; {PROTOCOL}: new"):
        compare({"new": result, "old": old})


def test_cli_loads_the_checkpoint_actor(tiny: tuple, tmp_path: Path) -> None:
    cfg, actor, _ = tiny
    actor = copy.deepcopy(actor)
    with torch.no_grad():
        for p in actor.parameters():
            p.add_(0.5)
    env = make_eval_env(cfg)
    layout = OracleInputDims.from_spec(env.observation_spec).as_layout()
    env.close()
    path = save_checkpoint(tmp_path / "oracle.pt", make_payload(
        models={"actor": actor}, iteration=1, robot=cfg.robot.name, layout=layout))
    loaded, _ = build_actor(cfg, str(path))
    for a, b in zip(actor.state_dict().values(), loaded.state_dict().values(), strict=True):
        assert torch.equal(a, b)
    with pytest.raises(CheckpointError, match="robot"):
        build_actor(compose_config(*TINY, "robot=g1"), str(path))


def test_cli_without_checkpoint_warns_and_evaluates(tmp_path: Path) -> None:
    with pytest.warns(UserWarning, match="untrained"):
        result = main(compose_config(*TINY), tmp_path)
    assert result["label"] == "untrained" and (tmp_path / "benchmark.csv").exists()


def test_plot_refuses_mismatched_inputs(tiny: tuple, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="one entry per robot"):
        plot_trajectories(None, [0, 0], [np.zeros((3, 3))], ["fell"], tmp_path / "x.png")
    with pytest.raises(ValueError, match="unknown outcome"):
        plot_trajectories(None, [0], [np.zeros((3, 3))], ["won"], tmp_path / "x.png")
