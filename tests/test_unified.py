"""Stage 2 end to end at tiny budgets: the oracle trained once and reused, a DAgger
iteration per student family, resume, refusal of a foreign checkpoint, the benchmark of a
student, and a study table gathered from real job folders."""

import itertools
import shutil
from pathlib import Path

import pytest
import torch
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from legoh import keys
from legoh.app import export
from legoh.checkpoint import CheckpointError, load_checkpoint
from legoh.config import validate
from legoh.eval.benchmark import evaluate, student_eval_env_fn
from legoh.eval.cli import build_actor
from legoh.eval.metrics import METRICS
from legoh.eval.study import STUDIES, study_table
from legoh.export import load_exported
from legoh.modules.actor_critic import LOC
from legoh.train.teacher import ensure_oracle, oracle_artefact_dir
from legoh.train.unified import train_student
from tests.conftest import CONF_DIR, compose_config

TINY = ("trail=flat", "algo.num_envs=4", "algo.steps_per_env=8", "algo.total_frames=64",
        "algo.oracle_frames=512", "algo.minibatches=2", "algo.epochs=1",
        "algo.prior_pretrain_frames=32", "algo.prior_pretrain_steps=2",
        "eval.robots=2", "eval.seconds=1.0", "eval.levels=[0]", "eval.runs=1",
        "eval.variants=1")


@pytest.fixture(scope="module")
def artefacts(tmp_path_factory):
    return tmp_path_factory.mktemp("artefacts")


@pytest.fixture(autouse=True)
def no_shipped_oracle(tmp_path, monkeypatch):
    """These tests train their tiny oracle (or reuse it): a shipped oracle in pretrained/
    would be the teacher otherwise."""
    monkeypatch.setattr("legoh.policies.pretrained.PRETRAINED_DIR", tmp_path / "no-pretrained")


def tiny(algo, artefacts, *more):
    return compose_config(f"algo={algo}", f"artefacts={artefacts}", *TINY, *more)


def test_oracle_is_trained_once_then_reused(artefacts):
    cfg = tiny("unified", artefacts)
    first = ensure_oracle(cfg)
    stamp = first.stat().st_mtime_ns
    again = ensure_oracle(tiny("ep_h", artefacts))  # another student, same stage-1 config
    assert again == first and first.stat().st_mtime_ns == stamp
    other = oracle_artefact_dir(tiny("unified", artefacts, "seed=1"))
    assert other != first.parent  # another seed needs another oracle


def test_the_shipped_oracle_is_the_default_teacher(artefacts, tmp_path, monkeypatch):
    """With no algo.oracle_checkpoint the robot's pretrained/<robot>_oracle.pt teaches, and
    nothing is trained; algo.oracle_checkpoint=pretrained names it too."""
    trained = ensure_oracle(tiny("unified", artefacts))  # a real checkpoint to ship
    shipped = tmp_path / "pretrained"
    shipped.mkdir()
    shutil.copy(trained, shipped / "h1_oracle.pt")
    monkeypatch.setattr("legoh.policies.pretrained.PRETRAINED_DIR", shipped)
    fresh = tmp_path / "fresh-artefacts"
    assert ensure_oracle(tiny("unified", fresh)) == shipped / "h1_oracle.pt"
    assert not fresh.exists()  # no oracle trained
    pinned = tiny("unified", fresh, "algo.oracle_checkpoint=pretrained")
    assert ensure_oracle(pinned) == shipped / "h1_oracle.pt"


def test_a_job_waits_for_the_job_training_its_oracle(artefacts, tmp_path):
    """Two jobs of a sweep that need the same oracle: the second waits for the first and
    reads its result. Failed before with RunFolderBusy."""
    import threading
    import time

    from legoh.runs import run_lock

    trained = ensure_oracle(tiny("unified", artefacts))
    cfg = tiny("unified", tmp_path / "artefacts")
    out = oracle_artefact_dir(cfg)
    holding = threading.Event()

    def first_job():  # holds the folder as train_oracle does, then leaves a finished oracle
        with run_lock(out):
            holding.set()
            time.sleep(1.0)
            shutil.copy(trained, out / "oracle.pt")
            (out / "DONE").write_text("the first job's\n")

    thread = threading.Thread(target=first_job)
    thread.start()
    holding.wait()
    try:
        assert ensure_oracle(cfg) == out / "oracle.pt"
    finally:
        thread.join()
    assert (out / "DONE").read_text() == "the first job's\n"  # read, not trained again


def test_a_teacher_of_another_robot_or_layout_is_refused(artefacts, tmp_path):
    """The teacher's checkpoint names its robot and observation layout; a mismatch is
    refused naming the field, before anything trains."""
    from legoh.checkpoint import save_checkpoint
    from legoh.policies.oracle import load_teacher
    from legoh.policies.student import make_student_env

    cfg = tiny("rma_b", artefacts)
    state = load_checkpoint(ensure_oracle(cfg))
    env = make_student_env(cfg, 1, ((1,), 1))
    try:
        save_checkpoint(tmp_path / "g1.pt", {**state, "robot": "g1"})
        with pytest.raises(CheckpointError, match="robot 'g1'"):
            load_teacher(cfg, tmp_path / "g1.pt", env)
        layout = {**state["layout"], "obs/proprio": (7,)}
        save_checkpoint(tmp_path / "layout.pt", {**state, "layout": layout})
        with pytest.raises(CheckpointError, match="obs/proprio"):
            load_teacher(cfg, tmp_path / "layout.pt", env)
    finally:
        env.close()


@pytest.mark.parametrize("algo", ["unified", "ep_h_hlm", "rma_b"])
def test_one_dagger_iteration_then_resume(artefacts, tmp_path, algo):
    cfg = tiny(algo, artefacts)
    run = train_student(cfg, tmp_path)
    assert run.iterations == 2 and run.checkpoint.is_file()
    rows = run.csv.read_text().splitlines()
    assert "distill/loss_action" in rows[0] and len(rows) == 3
    if algo == "unified":
        assert "loss_objective" in rows[0] and "distill/loss_hlm_triplet" in rows[0]
    more = OmegaConf.merge(cfg, {"algo": {"total_frames": 96}})
    resumed = train_student(more, tmp_path, resume=str(run.checkpoint))
    assert resumed.iterations == 3
    state = load_checkpoint(run.checkpoint)
    assert state["extra"]["student"] == cfg.algo.student
    # mode=export and mode=eval rebuild the student from its checkpoint
    ckpt = OmegaConf.merge(cfg, {"checkpoint": str(resumed.checkpoint)})
    module, meta = load_exported(export(ckpt, tmp_path))
    assert meta["algo"] == algo and meta["held_dim"] > 0
    policy, env_fn = build_actor(ckpt, ckpt.checkpoint)
    for a, b in zip(policy.locomotion.state_dict().values(),
                    resumed.algorithm.student.locomotion.state_dict().values(), strict=True):
        assert torch.equal(a, b)
    assert env_fn(0).observation_spec["obs"]["proprio"].shape[-1] == meta["proprio"]


def test_stage_two_builds_the_critic_its_oracle_trained(artefacts, tmp_path):
    """algo.critic_hidden travels in the oracle's checkpoint. Failed before with: a size
    mismatch loading the oracle's critic (stage 2 built the default 512-256-128)."""
    from legoh.train.oracle import train_oracle

    stage1 = compose_config("trail=flat", "algo.num_envs=4", "algo.steps_per_env=8",
                            "algo.total_frames=32", "algo.critic_hidden=[32,16]")
    oracle = train_oracle(stage1, tmp_path / "oracle").checkpoint
    run = train_student(tiny("rma_b", artefacts, f"algo.oracle_checkpoint={oracle}"),
                        tmp_path / "student")
    critic = load_checkpoint(run.checkpoint)["models"]["critic"]
    widths = {w.shape[0] for name, w in critic.items() if name.endswith("weight")}
    assert {32, 16} <= widths and 512 not in widths


def test_dagger_mixture_runs_and_logs_its_share(artefacts, tmp_path):
    """algo.dagger_mix_iterations=2: the teacher acts on every step of the first batch (no
    PPO step: the student acted on none), on half of the second."""
    import csv

    run = train_student(tiny("unified", artefacts, "algo.dagger_mix_iterations=2"), tmp_path)
    with run.csv.open() as f:
        rows = list(csv.DictReader(f))
    assert [float(r["dagger/beta"]) for r in rows] == [1.0, 0.5]
    assert float(rows[0]["dagger/teacher_acted"]) == 1.0


def test_imitation_learning_rate_warms_up_and_resumes_on_its_ramp(artefacts, tmp_path):
    """algo.distill_warmup_iterations=4: the imitation optimiser steps at lr/4, then lr/2;
    a resumed run goes on along the ramp (3/4 of lr), not from its start. Failed before:
    every update at lr (a warm start's fresh Adam moved each weight by ~lr at once)."""
    import csv

    cfg = tiny("unified", artefacts, "algo.distill_warmup_iterations=4", "algo.lr=4e-4")
    run = train_student(cfg, tmp_path / "a")
    with run.csv.open() as f:
        assert [float(r["distill/lr"]) for r in csv.DictReader(f)] == pytest.approx([1e-4, 2e-4])
    longer = tiny("unified", artefacts, "algo.distill_warmup_iterations=4", "algo.lr=4e-4",
                  f"algo.total_frames={2 * cfg.algo.total_frames}")
    resumed = train_student(longer, tmp_path / "b", resume=str(run.checkpoint))
    with resumed.csv.open() as f:
        rates = [float(r["distill/lr"]) for r in csv.DictReader(f)]
    assert rates[-2:] == pytest.approx([3e-4, 4e-4])


def test_on_iteration_sees_the_student_and_can_stop_training(artefacts, tmp_path):
    """train_student's hook gets the student's own policy (not DAgger's mixture with the
    teacher) after each iteration; True stops the run with a checkpoint."""
    from legoh.train.dagger import TeacherMix

    seen = []

    def hook(it, stats, policy):
        seen.append((it, policy))
        return True

    run = train_student(tiny("unified", artefacts, "algo.dagger_mix_iterations=2"), tmp_path,
                        on_iteration=hook)
    assert [it for it, _ in seen] == [1] and run.iterations == 1
    assert load_checkpoint(run.checkpoint)["iteration"] == 1
    policy = seen[0][1]
    assert not isinstance(policy, TeacherMix)
    assert list(policy.module) == list(run.algorithm.student.policy.module)


def test_a_new_student_starts_from_a_students_weights(artefacts, tmp_path, capsys):
    """init=PATH (or pretrained: the shipped <robot>_<algo>.pt) starts a new run from a
    stage-2 checkpoint's student weights, its critic the teacher's; another student type
    is refused. Failed before: stage 2 ignored init= (every student from scratch)."""
    first = train_student(tiny("unified", artefacts), tmp_path / "a")
    state = torch.load(first.checkpoint, map_location="cpu", weights_only=False)
    for name in ("navigation", "locomotion"):  # weights no seeded init could give
        state["models"][name] = {k: v + 0.5 if v.is_floating_point() else v
                                 for k, v in state["models"][name].items()}
    torch.save(state, tmp_path / "moved.pt")
    first.algorithm.student.navigation.load_state_dict(state["models"]["navigation"])
    first.algorithm.student.locomotion.load_state_dict(state["models"]["locomotion"])
    hook_weights = {}

    def hook(it, stats, policy):  # the first update moved the weights a little, not away
        hook_weights.update(policy.state_dict())
        return True

    warm = train_student(tiny("unified", artefacts, f"init={tmp_path / 'moved.pt'}",
                              "algo.lr=1e-9"), tmp_path / "b", on_iteration=hook)
    assert "student weights from" in capsys.readouterr().out
    trained = first.algorithm.student.policy.state_dict()
    # (the adaptive schedule's floor, 1e-5, moves a weight ~1e-5 a step)
    assert all(torch.allclose(hook_weights[k], trained[k], atol=1e-4) for k in trained)
    cold = train_student(tiny("unified", artefacts, "init=none", "algo.lr=1e-9"),
                         tmp_path / "c")
    assert not any(torch.allclose(v, trained[k], atol=0.1)
                   for k, v in cold.algorithm.student.policy.state_dict().items())
    assert warm.iterations == 1
    with pytest.raises(CheckpointError, match="student 'lego_h'"):
        train_student(tiny("rma_b", artefacts, f"init={first.checkpoint}"), tmp_path / "d")


def test_a_history_latent_student_starts_from_one_without(artefacts, tmp_path, capsys):
    """algo.history_latent=true warm-started from a student without the latent: every
    weight loaded, the latent's input columns zero (it acts as the loaded student), its
    encoder the teacher's adaptation module; the latent's regression is logged; resuming
    it without the flag is refused, and using it restores the flag."""
    from legoh.eval.cli import for_checkpoint
    from legoh.modules.students import PRIV_LATENT_DIM
    from legoh.policies.student import (
        build_student,
        load_student_adding_history,
        make_student_env,
        state_shapes,
        student_from_checkpoint,
    )

    plain_run = train_student(tiny("unified", artefacts), tmp_path / "a")
    teacher = plain_run.algorithm.teacher_path
    cfg = tiny("unified", artefacts, "algo.history_latent=true")
    plain = student_from_checkpoint(tiny("unified", artefacts), plain_run.checkpoint)
    grown = build_student(cfg)
    load_student_adding_history(cfg, plain_run.checkpoint, grown, teacher)
    adaptation = load_checkpoint(teacher)["models"]["adaptation"]
    for key, value in grown.navigation.navigator.history.state_dict().items():
        torch.testing.assert_close(value, adaptation[f"module.{key}"])
    env = make_student_env(cfg, 3, state_shapes(grown))
    try:
        td = env.reset()
    finally:
        env.close()
    td.set(keys.PROPRIO_HISTORY, torch.randn_like(td[keys.PROPRIO_HISTORY]))
    with torch.no_grad():
        out = grown.policy(td.clone())
        assert out[keys.HISTORY_LATENT].abs().sum() > 0
        torch.testing.assert_close(out[LOC], plain.policy(td.clone())[LOC])

    stats = {}
    run = train_student(tiny("unified", artefacts, f"init={plain_run.checkpoint}",
                             "algo.history_latent=true"), tmp_path / "b",
                        on_iteration=lambda it, s, policy: stats.update(s) or True)
    assert "has no history latent" in capsys.readouterr().out
    assert stats["distill/loss_priv_latent"] > 0
    assert grown.navigation.navigator.history_dim == PRIV_LATENT_DIM
    with pytest.raises(CheckpointError, match="algo.history_latent=True, but this run has "
                                              "algo.history_latent=False"):
        train_student(tiny("unified", artefacts), tmp_path / "c", resume=str(run.checkpoint))
    own, _ = for_checkpoint(tiny("unified", artefacts), str(run.checkpoint))
    assert own.algo.history_latent is True


def test_checkpoint_of_another_student_is_refused(artefacts, tmp_path):
    run = train_student(tiny("rma_b", artefacts), tmp_path / "a")
    with pytest.raises(CheckpointError, match="student 'rma_b'"):
        train_student(tiny("rma_h", artefacts), tmp_path / "b", resume=str(run.checkpoint))


def test_a_student_is_refused_through_another_camera(artefacts, tmp_path):
    """The layout checks the frames' shape, not what they show: a student trained through
    a 30-degree camera loaded into a run with a 55-degree one would have seen other ground
    in the same pixels, silently. Failed before: it loaded."""
    from legoh.policies.student import student_from_checkpoint

    at30 = "robot.camera.pitch_deg=30"
    run = train_student(tiny("unified", artefacts, at30), tmp_path / "a")
    student_from_checkpoint(tiny("unified", artefacts, at30), run.checkpoint)  # same: loads
    with pytest.raises(CheckpointError, match=r"robot.camera.pitch_deg=30.0, but this run has "
                                              r"robot.camera.pitch_deg=55.0"):
        student_from_checkpoint(tiny("unified", artefacts, "robot.camera.pitch_deg=55"),
                                run.checkpoint)


def test_evaluation_sees_through_the_camera_the_student_learned_with(artefacts, tmp_path,
                                                                     capsys):
    """Using a trained student (mode=eval, play, export) takes its camera and depth settings
    from its checkpoint: a 30-degree student stays usable under a 55-degree default, its
    env built at 30 degrees. Failed before: refused (no for_checkpoint)."""
    from legoh.eval.cli import build_actor, for_checkpoint

    run = train_student(tiny("unified", artefacts, "robot.camera.pitch_deg=30"), tmp_path / "a")
    cfg = tiny("unified", artefacts, "robot.camera.pitch_deg=55", "env.depth.far=4.0")
    own, path = for_checkpoint(cfg, str(run.checkpoint))
    assert own.robot.camera.pitch_deg == 30.0 and own.env.depth.far == 3.0
    assert path == str(run.checkpoint) and cfg.robot.camera.pitch_deg == 55.0  # a copy
    assert "robot.camera.pitch_deg=30.0, env.depth.far=3.0" in capsys.readouterr().out
    student, env_fn = build_actor(cfg, str(run.checkpoint))
    env = env_fn(0)
    try:
        assert env.base_env.cfg.depth.far == 3.0
        assert env.base_env.depth_cam is not None
    finally:
        env.close()


def test_an_overlapped_student_trains_with_decoupled_ppo(artefacts, tmp_path):
    """With collector.overlap a student acts with the weights of the update before last.
    Without decoupled PPO's behaviour weight its PPO ran away (grad norm 9e7, NaN actions,
    docs/unified.md, "Speed"), and stage 2 refused the overlap; now it trains, and the log
    says how much of the batch PPO could use (ESS). Failed before: refused."""
    from legoh.eval.curves import read_columns

    run = train_student(tiny("unified", artefacts, "collector.overlap=true"), tmp_path / "a")
    cols = read_columns(run.csv)
    assert len(cols["grad_norm"]) >= 2 and all(torch.isfinite(torch.tensor(cols["grad_norm"])))
    assert all(0.0 < ess <= 1.0 for ess in cols["ESS"])


def test_student_benchmark_and_study_table(artefacts, tmp_path):
    """Two jobs of a sweep folder, benchmarked through the student's env, gathered."""
    sweep = tmp_path / "multirun"
    oracle = ensure_oracle(tiny("ep_h", artefacts))  # both seeds share it: keeps the test short
    for seed in (0, 1):
        cfg = tiny("ep_h", artefacts, f"seed={seed}", f"algo.oracle_checkpoint={oracle}")
        job = sweep / f"ep_h-seed{seed}"
        run = train_student(cfg, job)
        torch.manual_seed(seed)
        result = evaluate(cfg, run.algorithm.student.policy, job, label="ep_h", progress=False,
                          env_fn=student_eval_env_fn(cfg, run.algorithm.student))
        assert set(result["rows"]["overall"]) == set(METRICS)
        (job / ".hydra").mkdir()
        (job / ".hydra" / "config.yaml").write_text(OmegaConf.to_yaml(cfg))
    paths = study_table(sweep, tmp_path / "table", "plugin_hlm")
    text = paths["markdown"].read_text()
    assert "| ep_h |" in text and "seeds [0, 1]" in text
    shutil.rmtree(sweep)


@pytest.mark.parametrize("study", sorted(STUDIES))
def test_every_sweep_composes_all_its_jobs(study):
    """Expand the sweep's parameters as Hydra's basic sweeper does; compose every job."""
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        hydra_cfg = compose("config", overrides=[f"+experiment={study}"],
                            return_hydra_config=True)
        params = hydra_cfg.hydra.sweeper.params
        axes = [[f"{k}={v}" for v in str(vals).split(",")] for k, vals in params.items()]
        jobs = list(itertools.product(*axes))
        assert len(jobs) >= 2
        for job in jobs:
            cfg = compose("config", overrides=[f"+experiment={study}", *job])
            validate(cfg)
            for override in job:
                key, value = override.split("=")
                node = OmegaConf.select(cfg, key)
                have = node.name if key in ("algo", "robot") else node
                assert str(have) == value, f"{study}: {override} composed as {have}"
    assert Path(CONF_DIR, "experiment", f"{study}.yaml").is_file()


def test_same_seed_same_training(artefacts, tmp_path, request):
    """Stage 2 is reproducible on the CPU: two runs of one config log the same losses; and
    the collector yielding its own buffer in place (no copy of the batch, collect.py) trains
    exactly as torchrl's copying default does, over three batches."""
    import csv

    logs = []
    for k in range(3):
        if k == 2:
            request.getfixturevalue("copying_collector")
        run = train_student(tiny("unified", artefacts, "algo.total_frames=96"),
                            tmp_path / str(k))
        with run.csv.open() as f:
            logs.append([{key: row[key] for key in row if not key.startswith(("time/",
                                                                             "frames_per_s"))}
                         for row in csv.DictReader(f)])
    assert len(logs[0]) == 3
    assert logs[0] == logs[1] == logs[2]


def test_a_shipped_student_is_slim_and_checkpoint_pretrained_picks_it(artefacts, tmp_path,
                                                                    monkeypatch):
    """ship_pretrained writes pretrained/<robot>_unified.pt without optimiser and RNG states,
    and ``checkpoint=pretrained`` under algo=unified loads that file (its weights), while the
    oracle stage still means <robot>_oracle.pt."""
    import sys
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
    import ship_pretrained

    run = train_student(tiny("unified", artefacts), tmp_path / "run")
    shipped = tmp_path / "pretrained"
    monkeypatch.setattr("legoh.policies.pretrained.PRETRAINED_DIR", shipped)
    monkeypatch.setattr(ship_pretrained, "PRETRAINED_DIR", shipped)
    dst = ship_pretrained.ship_file(run.checkpoint, "h1", "unified")
    assert dst == shipped / "h1_unified.pt"
    assert dst.stat().st_size < 0.75 * run.checkpoint.stat().st_size
    state = load_checkpoint(dst)
    assert "optimizers" not in state and "rng" not in state
    policy, _ = build_actor(tiny("unified", artefacts), "pretrained")
    for a, b in zip(policy.navigation.state_dict().values(),
                    run.algorithm.student.navigation.state_dict().values(), strict=True):
        assert torch.equal(a, b)
    with pytest.raises(FileNotFoundError, match="no pretrained oracle"):
        build_actor(compose_config("trail=flat", "eval.robots=1"), "pretrained")
    with pytest.raises(SystemExit, match="robot 'h1', not 'g1'"):
        ship_pretrained.ship_file(run.checkpoint, "g1", "unified")


@pytest.mark.parametrize("precision,dtype", [("bfloat16", torch.bfloat16),
                                             ("float32", torch.float32)])
def test_update_precision_reaches_the_imitation_update(artefacts, tmp_path, monkeypatch,
                                                       precision, dtype):
    """algo.update_precision=bfloat16 runs the imitation forward passes (TC-ViTs, GRU, heads,
    HLM's frozen VAE) under bfloat16 autocast, with finite float32 losses, and the student
    acts with its encoder in the same precision. Failed before with: the TC-ViTs re-run in
    float32 (only PPO followed the setting); then with: the acting encoder in float32; then
    with: HLM's VAE in float32."""
    import csv
    import math

    import legoh.objectives.hlm as hlm
    from legoh.modules.tcvit import FactorisedViViT

    def current_dtype():
        return (torch.get_autocast_dtype("cpu") if torch.is_autocast_enabled("cpu")
                else torch.float32)

    seen = {True: [], False: []}  # grad enabled: the imitation update; else the acting
    prior_seen = []
    encode, frozen_encode = FactorisedViViT.forward, hlm.frozen_encode

    def spy(self, depth, terminus):
        seen[torch.is_grad_enabled()].append(current_dtype())
        return encode(self, depth, terminus)

    def prior_spy(vae, actions01, mask=None):
        prior_seen.append(current_dtype())
        return frozen_encode(vae, actions01, mask)

    monkeypatch.setattr(FactorisedViViT, "forward", spy)
    monkeypatch.setattr(hlm, "frozen_encode", prior_spy)
    run = train_student(tiny("unified", artefacts, f"algo.update_precision={precision}"),
                        tmp_path)
    assert seen[True] and set(seen[True]) == {dtype}
    assert seen[False] and set(seen[False]) == {dtype}
    assert prior_seen and set(prior_seen) == {dtype}
    with run.csv.open() as f:
        rows = list(csv.DictReader(f))
    assert all(math.isfinite(float(r["distill/loss_action"])) for r in rows)


def test_the_student_main_job_films_its_student(artefacts, tmp_path, capsys):
    """``python run.py algo=unified`` ends with a video of the student, its depth view beside
    the robot, as the oracle's main job does. Failed before with: no play.mp4 (only the
    oracle stage was filmed)."""
    from legoh.app import train_and_evaluate

    train_and_evaluate(tiny("unified", artefacts), tmp_path)
    assert "[legoh] video:" in capsys.readouterr().out
    assert list(tmp_path.glob("play.*")) and (tmp_path / "play_filmstrip.png").is_file()
