"""A student campaign resumes from what a session commits (the run folder's unified.pt,
train.csv, clock.csv, evals.csv and sessions.csv, without the git-ignored snapshots), its
snapshots are benchmarked beside their teacher, and the teacher defaults to the shipped
oracle, else the hiking campaign's."""

import csv
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from omegaconf import OmegaConf

from legoh.checkpoint import load_checkpoint

ROOT = Path(__file__).resolve().parents[1]
TEACHER = ROOT / "experiments/results/learn_hike/h1-s0/oracle.pt"
TINY = ["--envs", "4", "--walk-robots", "2", "--eval-every", "100", "--frames", "10000000",
        "--teacher", str(TEACHER), "algo.net=small", "algo.steps_per_env=8", "algo.epochs=1",
        "algo.minibatches=2", "algo.distill_epochs=1", "algo.prior_pretrain_frames=32",
        "algo.prior_pretrain_steps=2"]
SMALL_MAP = ["trail.variants=1", "trail.levels=2"]  # training only: the benchmark needs 0-4


def _run(out: Path, *extra: str) -> str:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MUJOCO_GL": "egl"}
    done = subprocess.run([sys.executable, str(ROOT / "experiments/learn_student.py"), "--out",
                           str(out), *TINY, *extra], env=env, cwd=ROOT, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout


def _rows(path: Path) -> list[dict]:
    with open(path) as f:
        return list(csv.DictReader(f))


@pytest.mark.skipif(not TEACHER.is_file(), reason="no committed hiking oracle")
def test_a_student_campaign_resumes_from_its_committed_files(tmp_path) -> None:
    first = tmp_path / "session1" / "h1-unified-s0"
    _run(first, "--minutes", "0.1", *SMALL_MAP)
    clone = tmp_path / "session2" / "h1-unified-s0"  # a fresh clone: the committed files only
    clone.mkdir(parents=True)
    for name in ("unified.pt", "train.csv", "clock.csv", "evals.csv", "sessions.csv"):
        shutil.copy(first / name, clone / name)
    it0 = int(_rows(clone / "clock.csv")[-1]["iteration"])
    min0 = float(_rows(clone / "clock.csv")[-1]["minutes"])
    out = _run(clone, "--minutes", "0.2", *SMALL_MAP, "algo.lr=1e-4")  # a recipe change
    assert "resumed from" in out and "pre-trained" not in out.split("resumed from")[1]
    iters = [int(float(r["iteration"])) for r in _rows(clone / "train.csv")]
    assert iters == list(range(1, len(iters) + 1)) and iters[-1] > it0  # one history
    clock = _rows(clone / "clock.csv")[-1]
    assert int(clock["iteration"]) == iters[-1] and float(clock["minutes"]) > min0
    # a walk test at the start and at each stop, from depth on flat ground
    evals = _rows(clone / "evals.csv")
    minutes = [float(r["minutes"]) for r in evals]
    assert len(evals) >= 2 and minutes == sorted(minutes) and minutes[-1] > min0
    assert 0.0 <= float(evals[-1]["s1_walked_share"]) <= 1.0
    sys.path.insert(0, str(ROOT / "experiments"))
    from campaign import recipe_changes

    sessions = _rows(clone / "sessions.csv")
    assert [int(r["iteration"]) for r in sessions] == [0, it0]
    assert "teacher_sha=" in sessions[0]["recipe"]
    assert recipe_changes(clone) == [(float(sessions[1]["frames"]), "algo.lr=1e-4")]

    # the benchmark of the session's snapshot, its teacher scored once and cached
    bench = ["--bench-robots", "5", "eval.seconds=0.2"]
    out = _run(clone, "--evaluate", *bench)
    assert "teacher" in out and "bench it" in out
    row = _rows(clone / "bench.csv")[-1]
    assert int(row["iteration"]) == iters[-1]
    assert {"d_sr", "teacher_d_sr", "s2_ratio", "s3_ratio_gap"} <= set(row)
    cache = json.loads((clone / "teacher.json").read_text())
    assert len(cache) == 1 and "d_sr" in next(iter(cache.values()))["row"]
    meta = json.loads((clone / "milestones.json").read_text())
    assert set(meta["milestones"]) == {"s1", "s2", "s3"} and (clone / "curve.png").is_file()
    # the mean of the snapshots' weights, saved and scored like a snapshot (with session 1's
    # snapshots beside session 2's, as on the machine that ran both)
    for snap in (first / "snapshots").glob("it*.pt"):
        shutil.copy(snap, clone / "snapshots" / snap.name)
    snaps = sorted((clone / "snapshots").glob("it*.pt"))
    assert len(snaps) >= 2
    out = _run(clone, "--average", str(len(snaps)), *bench)
    assert f"mean of {len(snaps)} snapshots" in out and "averaged: RandomMix 0-2 SR" in out
    row = _rows(clone / "bench_average.csv")[-1]
    assert int(float(row["snapshots"])) == len(snaps) and {"d_sr", "s2_ratio"} <= set(row)
    policies = [torch.load(p, weights_only=False)["policy"] for p in snaps]
    saved = load_checkpoint(next((clone / "snapshots").glob("avg*.pt")), expect_robot="h1")
    assert saved["extra"]["averaged"] == [int(p.stem[2:]) for p in snaps]
    moved = 0
    for part, prefix in (("navigation", "module.0."), ("locomotion", "module.1.")):
        for key, value in saved["models"][part].items():
            if value.is_floating_point():
                mean = sum(p[prefix + key] for p in policies) / len(policies)
                torch.testing.assert_close(value, mean)
                moved += not torch.equal(policies[0][prefix + key], policies[-1][prefix + key])
    assert moved > 0  # the snapshots differ: the mean is not one of them
    with pytest.raises(AssertionError, match="needs at least 2 snapshots"):
        _run(clone, "--average", str(len(snaps) + 1), *bench)

    # a fresh clone has no snapshots: --evaluate scores the committed checkpoint. Failed
    # before with "no snapshots" (the H1 student's 45-minute state could not be scored)
    fresh = tmp_path / "session3" / "h1-unified-s0"
    fresh.mkdir(parents=True)
    for name in ("unified.pt", "train.csv", "clock.csv", "evals.csv", "sessions.csv",
                 "teacher.json"):
        shutil.copy(clone / name, fresh / name)
    out = _run(fresh, "--evaluate", *bench)
    assert "bench it" in out and out.count("RandomMix 0-2 SR") == 1  # the teacher cached
    row = _rows(fresh / "bench.csv")[-1]
    assert int(row["iteration"]) == iters[-1]
    assert float(row["minutes"]) == pytest.approx(float(clock["minutes"]), abs=0.01)
    assert row["teacher_d_sr"] == _rows(clone / "bench.csv")[-1]["teacher_d_sr"]
    # an A/B: two runs side by side, a picture and a row per walk test
    _run(first, "--compare", str(first), str(clone))
    stem = first.parent / "h1-unified-s0-compare-h1-unified-s0-h1-unified-s0"
    table = stem.with_suffix(".md").read_text()
    assert table.count("| h1-unified-s0 |") == len(evals) + len(_rows(first / "evals.csv"))
    assert stem.with_suffix(".png").stat().st_size > 10_000


def test_the_teacher_is_the_shipped_oracle_else_the_hiking_one(tmp_path, monkeypatch, capsys):
    sys.path.insert(0, str(ROOT / "experiments"))
    import learn_student

    monkeypatch.setattr("legoh.policies.pretrained.PRETRAINED_DIR", tmp_path)
    hiking = tmp_path / "hike.pt"
    hiking.write_bytes(b"an oracle")
    monkeypatch.setitem(learn_student.HIKING_ORACLE, "h1", hiking)
    assert learn_student.resolve_teacher("h1", "pretrained") == hiking
    assert "no pretrained/h1_oracle.pt yet" in capsys.readouterr().out
    (tmp_path / "h1_oracle.pt").write_bytes(b"shipped")
    assert learn_student.resolve_teacher("h1", "pretrained") == tmp_path / "h1_oracle.pt"
    assert learn_student.resolve_teacher("h1", "some/path.pt") == Path("some/path.pt")
    with pytest.raises(SystemExit, match="--teacher PATH"):
        learn_student.resolve_teacher("g1", "pretrained")


def test_the_students_reward_is_its_oracles() -> None:
    """Stage 2 trains on the hike preset with the robot's reward_scales, as learn_hike
    trains the oracle: the waypoint kernel 1.0 for H1 (as before) and 2.0 for G1."""
    sys.path.insert(0, str(ROOT / "experiments"))
    import learn_student

    from legoh.envs.mdp.rewards import preset_weights
    from legoh.policies.student import student_env_overrides

    for robot, kernel in (("h1", 1.0), ("g1", 2.0)):
        args = learn_student.make_parser().parse_args(["--robot", robot])
        cfg = learn_student.student_config(args, Path("teacher.pt"), "hike", [])
        rewards = student_env_overrides(cfg)["rewards"]
        weights = preset_weights(cfg.env.reward_preset, rewards, dict(cfg.robot.table6_weights),
                                 dict(cfg.robot.reward_scales))
        assert weights["tracking_waypoint_vel"] == kernel and weights["tracking_lin_vel"] == 0
    # the teacher's recipe (--recipe): v2 by default (the shipped oracles'), v1 selectable.
    # Failed before: always v1 (no --recipe)
    for recipe, preset, truncates in (("v2", "leap", True), ("v1", "hike", False)):
        args = learn_student.make_parser().parse_args(["--recipe", recipe])
        cfg = learn_student.student_config(args, Path("teacher.pt"), "hike", [])
        assert (cfg.env.reward_preset, cfg.env.reach_truncates) == (preset, truncates)
        assert str(cfg.trail.geometry).split(".")[-1] == recipe


def test_snapshots_are_scored_through_the_camera_they_learned_with(tmp_path) -> None:
    """A campaign trained with robot.camera.pitch_deg=55 is benchmarked through that camera
    even when --evaluate is run without the override (the snapshots load as plain state
    dicts: no checkpoint check would catch it). Failed before: scored at 30 degrees."""
    sys.path.insert(0, str(ROOT / "experiments"))
    import learn_student

    args = learn_student.make_parser().parse_args(["--robot", "h1", "--out", str(tmp_path)])
    trained = learn_student.student_config(args, Path("teacher.pt"), "hike",
                                           ["robot.camera.pitch_deg=55"])
    torch.save({"config": OmegaConf.to_container(trained, resolve=True)},
               tmp_path / f"{trained.algo.name}.pt")
    cfg = learn_student.bench_config(args, Path("teacher.pt"))
    assert cfg.robot.camera.pitch_deg == 55.0


def test_a_teacher_score_cached_by_older_benchmark_code_is_not_reused(tmp_path, capsys) -> None:
    """teacher.json entries carry the benchmark's version: an entry written under the old
    key (hash and protocol only, before BENCHMARK_VERSION) is stale, so the teacher is
    scored again (here its file is gone: no ratio). Failed before: the stale row came back."""
    sys.path.insert(0, str(ROOT / "experiments"))
    import hashlib

    import learn_student

    args = learn_student.make_parser().parse_args(["--robot", "h1", "--out", str(tmp_path)])
    cfg = learn_student.bench_config(args, Path("teacher.pt"))
    protocol = OmegaConf.to_container(cfg.eval, resolve=True)
    digest = hashlib.sha256(json.dumps(protocol, sort_keys=True).encode()).hexdigest()[:8]
    cache = {f"abc123 {digest}": {"row": {"d_sr": 71.0}}}  # an entry of the old code
    gone = tmp_path / "oracle.pt"
    assert learn_student.score_teacher(cfg, None, gone, cache, "abc123") is None
    assert "is gone or changed" in capsys.readouterr().out


def test_a_new_arm_takes_its_teachers_score_from_a_sibling_run(tmp_path) -> None:
    """A teacher scored under the same key (file hash, protocol, benchmark version) in
    another run folder is not scored again: its row comes from that folder's teacher.json.
    Failed before: the new arm re-benchmarked the teacher (here: make_env None raises)."""
    sys.path.insert(0, str(ROOT / "experiments"))
    import hashlib

    import learn_student

    args = learn_student.make_parser().parse_args(["--robot", "g1", "--out", str(tmp_path)])
    cfg = learn_student.bench_config(args, Path("teacher.pt"))
    protocol = OmegaConf.to_container(cfg.eval, resolve=True)
    digest = hashlib.sha256(json.dumps(protocol, sort_keys=True).encode()).hexdigest()[:8]
    key = f"abc123 {digest} v{learn_student.BENCHMARK_VERSION}"
    (tmp_path / "g1-old").mkdir()
    (tmp_path / "g1-old" / "teacher.json").write_text(json.dumps(
        {key: {"row": {"d_sr": 60.0}}, "other 00000000 v1": {"row": {"d_sr": 1.0}}}))
    cache: dict = {}
    row = learn_student.score_teacher(cfg, None, tmp_path / "oracle.pt", cache, "abc123",
                                      siblings=tmp_path)
    assert row == {"d_sr": 60.0} and list(cache) == [key]  # only the row it used
    other = tmp_path / "other.pt"
    other.write_bytes(b"another teacher")
    with pytest.raises(TypeError):  # no sibling has it: scored (here no env to score in)
        learn_student.score_teacher(cfg, None, other, {}, learn_student.file_hash(other),
                                    siblings=tmp_path)


def test_evaluate_and_average_started_together_score_the_teacher_once(tmp_path) -> None:
    """The second of two processes needing a teacher missing from ``teacher.json`` waits for
    the first's lock and takes the row it wrote. Failed before: each read the file at start
    and scored the teacher itself (here: make_env None raises)."""
    import threading

    sys.path.insert(0, str(ROOT / "experiments"))
    import hashlib

    import learn_student

    from legoh.runs import file_lock

    args = learn_student.make_parser().parse_args(["--robot", "h1", "--out", str(tmp_path)])
    cfg = learn_student.bench_config(args, Path("teacher.pt"))
    teacher = tmp_path / "oracle.pt"
    teacher.write_bytes(b"a teacher")
    sha = learn_student.file_hash(teacher)
    protocol = OmegaConf.to_container(cfg.eval, resolve=True)
    digest = hashlib.sha256(json.dumps(protocol, sort_keys=True).encode()).hexdigest()[:8]
    key = f"{sha} {digest} v{learn_student.BENCHMARK_VERSION}"
    out = tmp_path / "run"
    out.mkdir()
    got: list = []
    with file_lock(out / ".teacher.lock"):  # the first process, scoring
        second = threading.Thread(target=lambda: got.append(learn_student.teacher_row(
            cfg, None, out, {"teacher": str(teacher), "teacher_sha": sha})))
        second.start()
        second.join(timeout=0.5)
        assert second.is_alive()  # waits for the first
        (out / "teacher.json").write_text(json.dumps({key: {"row": {"d_sr": 66.0}}}))
    second.join(timeout=10)
    assert got == [{"d_sr": 66.0}]
