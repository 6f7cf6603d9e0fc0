"""Collectors: envs in the learner's process, in local processes, in Ray actors.

Each kind must yield (envs, time) batches, act with the learner's current weights after
``sync_weights``, and carry a training iteration. The Ray tests start a local Ray cluster of
2 CPUs (loopback only) once for the module.
"""

import copy
import functools
from pathlib import Path

import pytest
import torch

from legoh import keys
from legoh.envs.hiking_env import make_env
from legoh.modules.actor_critic import LOC
from legoh.policies.oracle import build_oracle
from legoh.train.collect import envs_per_worker, make_collector, overlapped, sync_weights
from legoh.train.oracle import train_oracle
from tests.conftest import compose_config
from tests.test_train_oracle import TINY

STEPS = 8  # TINY's algo.steps_per_env
NUM_ENVS = 4  # TINY's algo.num_envs


@pytest.fixture(scope="module")
def ray_cluster():
    """A local Ray cluster limited to 2 CPUs, shut down after the module's tests."""
    ray = pytest.importorskip("ray", reason="ray is not installed (pip install -e '.[dev]')")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield ray
    ray.shutdown()


def collect_twice(*overrides: str) -> None:
    """Two batches: each (envs, time) and acted with the learner's weights of the moment.

    Between them the learner's actor changes; after ``sync_weights`` the workers' action
    means must equal the changed actor's on the observations they saw.
    """
    cfg = compose_config(*TINY, *overrides)
    factory = functools.partial(make_env, cfg)
    probe = factory(1)
    torch.manual_seed(0)
    _, actor, _, _ = build_oracle(probe, cfg)
    probe.close()
    frames = NUM_ENVS * STEPS
    collector = make_collector(cfg, factory, actor, frames, 2 * frames)
    try:
        for i, batch in enumerate(collector):
            assert batch.numel() == frames
            batch = batch.reshape(-1, batch.shape[-1])
            assert batch.shape == (NUM_ENVS, STEPS)
            assert batch[keys.PROPRIO].shape[:2] == (NUM_ENVS, STEPS)
            with torch.no_grad():
                expected = actor(batch.select(*actor.in_keys).clone()).get(LOC)
            torch.testing.assert_close(batch.get(LOC), expected, rtol=1e-4, atol=1e-5)
            if i == 0:  # the learner moves on: perturb every weight, then send them out
                with torch.no_grad():
                    for param in actor.parameters():
                        param.add_(0.05 * torch.randn_like(param))
                sync_weights(collector)
    finally:
        collector.shutdown()


def test_in_process_collector_acts_with_the_learners_actor() -> None:
    collect_twice()  # TINY collects in turns (collector.overlap=false)


def test_the_oracle_overlaps_by_default_and_students_do_not() -> None:
    """collector.overlap=null: the stage decides (the oracle overlaps where it can: sync,
    one worker, CPU); an explicit setting wins."""
    assert overlapped(compose_config())
    assert not overlapped(compose_config("algo=unified"))
    assert not overlapped(compose_config("collector.workers=2"))
    assert not overlapped(compose_config("collector=ray"))
    assert not overlapped(compose_config("collector.overlap=false"))
    assert overlapped(compose_config("algo=unified", "collector.overlap=true"))


def test_two_local_processes_get_the_new_weights() -> None:
    collect_twice("collector.workers=2")


def test_two_ray_workers_get_the_new_weights(ray_cluster) -> None:
    collect_twice("collector=ray", "collector.workers=2")


def test_a_training_iteration_runs_on_two_ray_workers(ray_cluster, tmp_path: Path) -> None:
    cfg = compose_config(*TINY, "collector=ray", "collector.workers=2", "algo.total_frames=64")
    run = train_oracle(cfg, tmp_path)
    assert run.iterations == 2
    rows = run.csv.read_text().strip().splitlines()
    assert len(rows) == 3  # header + 2 iterations


def test_two_collector_processes_feed_one_learner(tmp_path: Path) -> None:
    cfg = compose_config(*TINY, "collector.workers=2", "algo.total_frames=64")
    run = train_oracle(cfg, tmp_path)
    assert run.iterations == 2
    assert len(run.csv.read_text().strip().splitlines()) == 3


def test_workers_must_divide_the_envs(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="divisible"):
        train_oracle(compose_config(*TINY, "collector.workers=3", "algo.total_frames=64"),
                     tmp_path)


def test_envs_per_worker() -> None:
    assert envs_per_worker(compose_config("algo.num_envs=64", "collector.workers=4")) == 16
    assert envs_per_worker(compose_config("algo.num_envs=64")) == 64
    with pytest.raises(ValueError, match="at least one"):
        envs_per_worker(compose_config("collector.workers=0"))


def test_ray_config_composes() -> None:
    cfg = compose_config("collector=ray", "collector.workers=8", "collector.init.address=auto",
                         "collector.cpus_per_worker=4")
    assert (cfg.collector.name, cfg.collector.workers) == ("ray", 8)
    assert cfg.collector.init.address == "auto" and cfg.collector.cpus_per_worker == 4
    assert cfg.collector.policy_device == "cpu"  # workers may have no GPU
    assert compose_config().collector.name == "sync"


def test_worker_curriculum_reaches_the_checkpoint_and_comes_back_on_resume(
        tmp_path: Path) -> None:
    """With 2 worker processes the checkpoint keeps the workers' curriculum (levels, step
    counter), and a resumed run's workers start from it.

    Failed before with: assert 0 == 8 (the checkpoint held the learner's unstepped env's
    step counter); resumed workers also built fresh envs, at level 0 instead of 2."""
    from legoh.checkpoint import load_checkpoint, save_checkpoint

    tiny = [o for o in TINY if not o.startswith("trail.levels")]
    workers = ("collector.workers=2", "trail.levels=3")
    run = train_oracle(compose_config(*tiny, *workers, "algo.total_frames=32"), tmp_path)
    state = load_checkpoint(run.checkpoint)
    assert state["curriculum"]["global_steps"] == STEPS
    state["curriculum"]["level"] = [2] * NUM_ENVS
    save_checkpoint(run.checkpoint, state)
    cfg = compose_config(*tiny, *workers, "algo.total_frames=64", f"resume={run.checkpoint}")
    second = train_oracle(cfg, tmp_path, resume=cfg.resume)
    last = second.csv.read_text().strip().splitlines()
    header, row = last[0].split(","), last[-1].split(",")
    assert float(row[header.index("level_mean")]) == 2.0
    assert load_checkpoint(second.checkpoint)["curriculum"]["global_steps"] == 2 * STEPS


def test_overlapped_collection_trains_and_acts_with_one_update_of_lag(tmp_path: Path) -> None:
    """collector.overlap=true: one worker collects while the learner updates. Its batches
    have the (envs, time) shape; the batch in flight at a sync was acted with the weights
    before it, every later one with the synced weights, never a mix."""
    cfg = compose_config(*TINY, "collector.overlap=true", "algo.total_frames=96")
    run = train_oracle(cfg, tmp_path)
    assert run.iterations == 3 and run.checkpoint.exists()
    env = make_env(cfg, num_envs=NUM_ENVS)
    torch.manual_seed(0)
    _, actor, _, _ = build_oracle(env, cfg)
    before = copy.deepcopy(actor)
    collector = make_collector(cfg, functools.partial(make_env, cfg), actor,
                               NUM_ENVS * STEPS, NUM_ENVS * STEPS * 4, env=env)
    batches = []
    for i, batch in enumerate(collector):
        batches.append(batch.reshape(-1, batch.shape[-1]))
        if i == 0:
            with torch.no_grad():
                for p in actor.parameters():
                    p.add_(0.1)
            sync_weights(collector)
        if i == 3:
            break
    collector.shutdown()
    assert batches[0].shape == (NUM_ENVS, STEPS)
    for k, acting in ((0, before), (1, before), (2, actor), (3, actor)):
        with torch.no_grad():
            fresh = acting(batches[k].select(*acting.in_keys).clone())
        torch.testing.assert_close(batches[k][LOC], fresh[LOC], msg=f"batch {k}")


def test_overlapped_training_repeats_with_its_seed(tmp_path: Path) -> None:
    """Two overlapped runs of one seed log the same losses and rewards (torchrl's
    MultiAsyncCollector applied weights whenever they arrived: two such runs diverged)."""
    cfg = compose_config(*TINY, "collector.overlap=true", "algo.total_frames=192")
    rows = []
    for name in ("a", "b"):
        run = train_oracle(cfg, tmp_path / name)
        lines = run.csv.read_text().strip().splitlines()
        header = lines[0].split(",")
        keep = [i for i, h in enumerate(header) if h.startswith(("loss", "reward"))]
        rows.append([[line.split(",")[i] for i in keep] for line in lines[1:]])
    assert len(rows[0]) == 6 and keep
    assert rows[0] == rows[1]


def test_overlap_takes_one_worker() -> None:
    cfg = compose_config(*TINY, "collector.overlap=true", "collector.workers=2")
    env = make_env(cfg, num_envs=NUM_ENVS)
    with pytest.raises(ValueError, match="collector.overlap"):
        make_collector(cfg, functools.partial(make_env, cfg), None, 16, 32, env=env)


def test_a_sigterm_between_batches_keeps_the_sent_batch_readable() -> None:
    """A job scheduler's SIGTERM reaches the overlap's worker after it sent a batch the
    learner has not read yet (the learner is updating). The worker stays until the learner
    takes it, then leaves by SIGTERM's exit code.

    Failed before with FileNotFoundError in the learner's read: the worker left at once and
    took the batch's file descriptors with it (seen in CI, test_runs' signal test)."""
    import os
    import signal
    import time

    cfg = compose_config(*TINY, "collector.overlap=true")
    env = make_env(cfg, num_envs=NUM_ENVS)
    torch.manual_seed(0)
    _, actor, _, _ = build_oracle(env, cfg)
    frames = NUM_ENVS * STEPS
    collector = make_collector(cfg, functools.partial(make_env, cfg), actor, frames, 2 * frames,
                               env=env)
    try:
        time.sleep(15.0)  # batch 0 is collected and sent; the worker waits for a request
        os.kill(collector._proc.pid, signal.SIGTERM)
        time.sleep(3.0)
        batch = next(iter(collector))
        assert batch.numel() == frames
        collector._proc.join(timeout=10.0)
        assert collector._proc.exitcode == 128 + signal.SIGTERM
    finally:
        collector.shutdown()
        env.close()


def test_the_learner_mirrors_the_workers_categories() -> None:
    """With workers, the learner's env (the one a checkpoint saves) takes each robot's
    category from the batch, as it takes its level. Failed before: the categories the
    workers' lagging mix moved stayed at the learner's initial split, so a resumed run
    paired each robot's level with another category."""
    from tensordict import TensorDict

    from legoh.train.collect import mirror_curriculum

    cfg = compose_config("trail=hike", "trail.levels=2", "trail.variants=1")
    env = make_env(cfg, num_envs=5)
    t = 3
    nxt = TensorDict({"info": {"level": torch.ones(5, t, dtype=torch.long),
                               "category": torch.full((5, t), 3),
                               "randomization": torch.zeros(5, t, 3)}}, batch_size=[5, t])
    mirror_curriculum(object(), env, TensorDict({"next": nxt}, batch_size=[5, t]))
    assert env.category.tolist() == [3] * 5 and env.level.tolist() == [1] * 5
    env.close()
