"""A hiking campaign resumes from what a session commits: the run folder's oracle.pt,
train.csv, clock.csv and evals.csv, without the git-ignored snapshots."""

import csv
import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TINY = ["--envs", "8", "--walk-robots", "2", "--eval-every", "100", "--frames", "10000000",
        "trail.variants=1", "trail.levels=2", "algo.steps_per_env=8", "algo.epochs=1",
        "collector.overlap=false"]


def _run(out: Path, minutes: float, *extra: str) -> str:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MUJOCO_GL": "egl"}
    done = subprocess.run([sys.executable, str(ROOT / "experiments/learn_hike.py"), "--out",
                           str(out), "--minutes", str(minutes), *TINY, *extra], env=env, cwd=ROOT,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout


def _last(path: Path) -> dict:
    with open(path) as f:
        return list(csv.DictReader(f))[-1]


def test_a_campaign_resumes_from_its_committed_files(tmp_path) -> None:
    first = tmp_path / "session1" / "h1-s0"
    _run(first, 0.15)
    clone = tmp_path / "session2" / "h1-s0"  # a fresh clone holds the committed files only
    clone.mkdir(parents=True)
    for name in ("oracle.pt", "train.csv", "clock.csv", "evals.csv", "sessions.csv"):
        shutil.copy(first / name, clone / name)
    it0, min0 = int(_last(clone / "clock.csv")["iteration"]), float(
        _last(clone / "clock.csv")["minutes"])
    out = _run(clone, 0.3, "env.curriculum.up=0.7")  # the second session changes the recipe
    assert "resumed from" in out
    rows = list(csv.DictReader(open(clone / "train.csv")))
    iters = [int(float(r["iteration"])) for r in rows]
    assert iters == list(range(1, len(iters) + 1)) and iters[-1] > it0  # one history
    clock = _last(clone / "clock.csv")
    assert int(clock["iteration"]) == iters[-1] and float(clock["minutes"]) > min0
    evals = list(csv.DictReader(open(clone / "evals.csv")))
    # at the start and at each stop (one row where a loaded machine's first iteration
    # already ran past the first session's budget)
    minutes = [float(r["minutes"]) for r in evals]
    assert len(evals) >= 2 and minutes == sorted(minutes) and minutes[-1] > min0
    # the warm start was the committed walker (init), the second session did not repeat it
    assert "init=" not in out.split("resumed from")[1]
    # each start is recorded with its recipe, and the change is found for the curves
    sys.path.insert(0, str(ROOT / "experiments"))
    from campaign import recipe_changes

    sessions = list(csv.DictReader(open(clone / "sessions.csv")))
    assert [int(r["iteration"]) for r in sessions] == [0, it0]
    assert str(ROOT) not in (clone / "sessions.csv").read_text()  # clones differ in path
    assert recipe_changes(clone) == [(float(sessions[1]["frames"]), "env.curriculum.up=0.7")]
    # two runs side by side against minutes: a picture and a row per walk test
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MUJOCO_GL": "egl"}
    subprocess.run([sys.executable, str(ROOT / "experiments/learn_hike.py"), "--compare",
                    str(first), str(clone)], env=env, cwd=ROOT, check=True, capture_output=True)
    stem = first.parent / "h1-s0-compare-h1-s0-h1-s0"
    table = stem.with_suffix(".md").read_text()
    first_evals = list(csv.DictReader(open(first / "evals.csv")))
    assert table.count("| h1-s0 |") == len(evals) + len(first_evals)
    assert stem.with_suffix(".png").stat().st_size > 10_000


def test_the_training_config_keeps_the_robots_reward_scales() -> None:
    """learn_hike trains with the hike preset and leaves a robot's reward_scales alone.
    Failed before with: the waypoint kernel at 1.0 for G1 (learn_hike gave the kernels as
    absolute env.rewards weights, over G1's x 2), half what its walker learned with."""
    sys.path.insert(0, str(ROOT / "experiments"))
    from learn_hike import make_parser, train_config

    from legoh.envs.mdp.rewards import preset_weights

    def weights(robot):
        _, cfg = train_config(make_parser().parse_args(["--robot", robot, "--init", "none"]))
        return preset_weights(cfg.env.reward_preset, dict(cfg.env.rewards),
                              dict(cfg.robot.table6_weights), dict(cfg.robot.reward_scales))

    g1, h1 = weights("g1"), weights("h1")
    assert g1["tracking_waypoint_vel"] == 2.0 and g1["tracking_lin_vel"] == 0.0
    assert h1["tracking_waypoint_vel"] == 1.0 and h1["tracking_lin_vel"] == 0.0


def test_each_ab_arm_leaves_out_one_change_of_recipe_v2() -> None:
    """``--arm``: every arm's training config differs from recipe v2's in its own keys
    only, and gets its own run folder."""
    sys.path.insert(0, str(ROOT / "experiments"))
    from learn_hike import ARMS, make_parser, run_dir, train_config
    from omegaconf import OmegaConf

    def flat(args):
        cfg = OmegaConf.to_container(train_config(args)[1], resolve=True)
        out = {}

        def walk(node, path=""):
            for k, v in node.items():
                if isinstance(v, dict):
                    walk(v, f"{path}{k}.")
                else:
                    out[f"{path}{k}"] = v
        walk(cfg)
        return out

    parse = make_parser().parse_args
    base = flat(parse(["--init", "none", "--arm", "v2"]))  # (h1-s0 holds the v1 campaign)
    expected = {"ground": {"env.height_reference"}, "clock": {"env.gait.yield_near"},
                "hike": {"env.reward_preset"}, "speed": {"env.command.speed"},
                "start": {"env.spawn_along"}, "mix": {"env.curriculum.lagging_mix"}, "v2": set(),
                "pay": {"env.gait.yield_pay"}, "terminate": {"env.reach_truncates"}}
    assert set(ARMS) == set(expected)
    for arm, keys in expected.items():
        args = parse(["--init", "none", "--arm", arm])
        arm_cfg = flat(args)
        changed = {k for k in base if arm_cfg.get(k) != base[k]}
        assert changed == keys, (arm, changed)
        assert run_dir(args).name == f"h1-s0-ab3-{arm}"


def test_a_v2_campaign_never_resumes_the_v1_campaigns_folder() -> None:
    """Failed before: ``learn_hike.py --robot h1 --seed 0`` (recipe v2 by default) ran in
    h1-s0, the v1 campaign's folder, and would have resumed its checkpoint under v2."""
    sys.path.insert(0, str(ROOT / "experiments"))
    from learn_hike import make_parser, run_dir

    parse = make_parser().parse_args
    assert run_dir(parse([])).name == "h1-s0-v2"
    assert run_dir(parse(["--recipe", "v1"])).name == "h1-s0"
    assert run_dir(parse(["--tag", "warm"])).name == "h1-s0-warm"
