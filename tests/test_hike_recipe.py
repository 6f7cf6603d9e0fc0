"""The hiking recipe (issue "The oracle hikes"): the curriculum's expected distance, the
randomisation gate, the env's curriculum state, the warm start and the legacy checkpoint
conversion. Each fault test states how the old code failed it."""

from pathlib import Path

import pytest
import torch
from torchrl.envs.utils import ExplorationType, set_exploration_type

from legoh import keys
from legoh.checkpoint import CheckpointError, load_checkpoint
from legoh.envs.hiking_env import make_env
from legoh.envs.mdp import events
from legoh.policies.oracle import build_oracle, load_oracle_checkpoint
from legoh.train.oracle import warm_start
from tests.conftest import compose_config

ROOT = Path(__file__).resolve().parents[1]
WALKER = ROOT / "experiments/results/learn_walk/h1-walk-s0-fast-c256-e3/oracle.pt"
LEAN = "algo.critic_hidden=[256,128,64]"
SMALL = ("trail.variants=1", "trail.levels=2")


def _place_on_waypoint(env, ids: torch.Tensor, k: int) -> None:
    """Put envs ``ids`` at waypoint ``k`` of their tile with the goal index there, so
    their progress is the path length to that waypoint."""
    tile = env.goals.tile[ids]
    qpos = env.sim.qpos[ids].clone()
    qpos[:, 0:2] = env.trails_t.waypoints[tile, k]
    env.sim.reset_envs(ids, qpos, torch.zeros(len(ids), env.sim.nv, dtype=env.dtype),
                       env.ctrl[ids])
    env.goals.index[ids] = k


def test_curriculum_expects_the_commanded_speed_times_the_episode() -> None:
    # Fault: the expected distance was the goal speed (0.8 m/s) x 20 s = 16 m whatever the
    # command, so a robot told to walk at 0.5 m/s that covered its 10 m stayed put (the
    # main job's 245 iterations never promoted a robot).
    env = make_env(compose_config("trail=randommix", *SMALL), num_envs=2)
    env.reset()
    ids = torch.arange(2)
    env.command.speed[:] = 0.5  # expected 10 m in the 20 s episode: up above 8 m
    env.level[:] = 0
    k = int((env.trails_t.cum_length[env.goals.tile[0]] > 9.0).nonzero()[0])
    _place_on_waypoint(env, ids, k)
    env.spawned_at[:] = 0.0  # both started at the trail start
    env.steps[:] = 100
    events.curriculum(env, ids)
    assert env.level.tolist() == [1, 1]
    env.close()


def test_curriculum_counts_from_the_spawn_point() -> None:
    """A robot spawned along the trail (env.spawn_along) is judged on the path it covered
    from its spawn point: the same place past 9 m of path promotes a robot that started at
    the trail start and demotes one that started 1 m before it."""
    env = make_env(compose_config("trail=randommix", *SMALL), num_envs=2)
    env.reset()
    ids = torch.arange(2)
    env.command.speed[:] = 0.5  # expected: 10 m, or the path left from the spawn
    env.level[:] = torch.tensor([0, 1])  # up from 0, down from 1 (SMALL has two levels)
    tile = env.goals.tile[0]
    k = int((env.trails_t.cum_length[tile] > 9.0).nonzero()[0])
    _place_on_waypoint(env, ids, k)
    here = env.trails_t.cum_length[env.goals.tile, k]  # m of path to waypoint k, per env
    env.spawned_at[:] = torch.stack([torch.zeros_like(here[0]), here[1] - 1.0])
    env.steps[:] = 100
    events.curriculum(env, ids)
    assert env.level.tolist() == [1, 0]
    env.close()


def test_curriculum_keeps_the_level_of_a_standing_episode() -> None:
    env = make_env(compose_config("trail=randommix", *SMALL), num_envs=2)
    env.reset()
    env.command.speed[:] = 0.0  # told to stand: covered nothing, expected nothing
    env.level[:] = 1
    env.steps[:] = 100
    events.curriculum(env, torch.arange(2))
    assert env.level.tolist() == [1, 1]
    env.close()


def _gate(*overrides: str):
    return events.RandomizationSchedule(compose_config(*overrides).env.randomization, 9)


def test_gate_stays_closed_while_robots_fall() -> None:
    gate = _gate()
    for _ in range(50):
        gate.episodes_ended(torch.ones(16, dtype=torch.bool))
        gate.step()
    assert gate.survival == 0.0 and gate.strength(10**9) == 0.0


def test_gate_opens_and_ramps_once_robots_stay_up() -> None:
    gate = _gate("env.randomization.ramp_steps=100", "env.randomization.gate=0.8",
                 "env.randomization.gate_window=10")
    gate.episodes_ended(torch.tensor([True] * 5 + [False] * 15))  # 75 % up: closed
    gate.step()
    assert gate.survival == pytest.approx(0.75) and gate.ramp == 0.0
    gate.episodes_ended(torch.zeros(20, dtype=torch.bool))  # 0.9 x 15 + 20 of 0.9 x 20 + 20
    gate.step()
    assert gate.survival == pytest.approx(0.9 * (13.5 + 20) / (18 + 20) / 0.9)
    for _ in range(9):
        gate.step()
    assert gate.strength(0) == pytest.approx(0.1)
    for _ in range(200):
        gate.step()
    assert gate.strength(0) == 1.0


def test_gate_weighs_a_burst_of_timeouts_by_its_share() -> None:
    # Fault: an EMA over episodes in order let the 60 time-outs of the first synchronised
    # episodes open the gate (survival 0.7 -> 0.8) amid 93 % falls.
    gate = _gate("env.randomization.gate_window=1000")
    for _ in range(999):
        gate.episodes_ended(torch.ones(1, dtype=torch.bool))
        gate.step()
    gate.episodes_ended(torch.zeros(100, dtype=torch.bool))
    gate.step()
    assert gate.survival < 0.3 and gate.ramp == 0.0


def test_steps_schedule_is_the_paper_switch() -> None:
    gate = _gate("env.randomization.schedule=steps", "env.randomization.start_after_steps=5",
                 "env.randomization.delay_after_steps=10")
    assert [gate.strength(s) for s in (4, 5)] == [0.0, 1.0]
    assert [gate.delay_on(s) for s in (9, 10)] == [0.0, 1.0]


def test_env_gate_counts_training_falls_and_scales_pushes() -> None:
    cfg = compose_config("trail=flat", *SMALL, "env.randomization.ramp_steps=1",
                         "env.randomization.gate=0.75")
    env = make_env(cfg, num_envs=4)
    td = env.reset()
    env.fell_last[:] = torch.tensor([True, False, False, False])
    env.steps[:] = 10
    env._reset_envs(torch.arange(4))  # three of four ended episodes were not falls
    assert env.randomization.survival == 0.75
    td = env.step(td.set(keys.ACTION, torch.zeros(4, env.num_actions)))
    assert env.randomization.strength(env.global_steps) == 1.0
    assert td["next", keys.RANDOMIZATION][0, 0] == 1.0
    env.close()


def test_curriculum_state_round_trips_with_the_gate() -> None:
    env = make_env(compose_config("trail=flat", *SMALL), num_envs=3)
    env.reset()
    env.level[:] = torch.tensor([0, 1, 1])
    env.category[:] = torch.tensor([0, 0, 0])  # moved by the lagging mix: kept too
    env.global_steps = 77
    env.randomization.load_state({"ramp": 0.25, "alive": 9.0, "ended": 10.0})
    state = env.curriculum_state()
    other = make_env(compose_config("trail=flat", *SMALL), num_envs=3)
    other.load_curriculum_state(state)
    assert other.curriculum_state() == state
    assert other.category.tolist() == [0, 0, 0]
    env.close()
    other.close()


def test_a_resume_with_another_number_of_robots_is_refused_naming_the_key() -> None:
    """Failed before with torch's "expanded size ... must match" (a resumed campaign run
    with --envs changed), which names neither the key nor the value to use."""
    env = make_env(compose_config("trail=flat", *SMALL), num_envs=3)
    state = env.curriculum_state()
    other = make_env(compose_config("trail=flat", *SMALL), num_envs=4)
    with pytest.raises(ValueError, match="algo.num_envs=3"):
        other.load_curriculum_state(state)
    env.close()
    other.close()


def _actor_on(cfg, path):
    env = make_env(cfg, num_envs=6)
    dims, actor, critic, adaptation = build_oracle(env, cfg)
    return env, dims, {"actor": actor, "critic": critic, "adaptation": adaptation}


def test_legacy_checkpoint_converts_exactly() -> None:
    # The committed walker's privileged vector ends in a one-hot of its single category
    # (flat): folding that constant input into the biases must not change any output.
    cfg = compose_config("trail=flat", *SMALL, LEAN)
    env, dims, models = _actor_on(cfg, WALKER)
    models["actor"].load_state_dict(load_oracle_checkpoint(WALKER, cfg, dims)["models"]["actor"])
    legacy = load_checkpoint(WALKER)
    assert legacy["layout"]["obs/privileged"] == (10,)
    td = env.reset()
    w_old = legacy["models"]["actor"]["module.0.module.1.module.0.weight"]
    b_old = legacy["models"]["actor"]["module.0.module.1.module.0.bias"]
    priv = torch.cat([td[keys.PRIVILEGED], torch.ones(6, 1)], 1)
    latent_old = torch.nn.functional.elu(priv @ w_old.T + b_old)
    encoder = models["actor"].module[0].module[1].module[0]
    latent_new = torch.nn.functional.elu(encoder(td[keys.PRIVILEGED]))
    torch.testing.assert_close(latent_new, latent_old)
    env.close()


def test_warm_start_loads_the_walker_and_refuses_another_critic(tmp_path) -> None:
    cfg = compose_config("trail=hike", *SMALL, LEAN)
    env, dims, models = _actor_on(cfg, WALKER)
    warm_start(cfg, WALKER, dims, models)
    ref_env, ref_dims, ref = _actor_on(compose_config("trail=flat", *SMALL, LEAN), WALKER)
    ref["actor"].load_state_dict(load_oracle_checkpoint(WALKER, cfg, ref_dims)["models"]["actor"])
    td = env.reset()
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        torch.testing.assert_close(models["actor"](td.clone())[keys.ACTION],
                                   ref["actor"](td.clone())[keys.ACTION])
    other = compose_config("trail=hike", *SMALL, "algo.critic_hidden=[512,256,128]")
    with pytest.raises(CheckpointError, match="algo.critic_hidden"):
        warm_start(other, WALKER, dims, _actor_on(other, WALKER)[2])
    env.close()
    ref_env.close()


def test_an_oracle_is_rebuilt_from_its_own_head(tmp_path) -> None:
    # Fault (stage 2, eval, play): the actor was built from this run's algo.tanh_bound, so a
    # tanh-bounded oracle loaded into a linear head without a word.
    from omegaconf import OmegaConf

    from legoh.checkpoint import make_payload, save_checkpoint
    from legoh.policies.oracle import load_oracle_actor

    bounded = compose_config("trail=flat", *SMALL, "algo.tanh_bound=4.8")
    env, dims, models = _actor_on(bounded, None)
    path = save_checkpoint(tmp_path / "oracle.pt", make_payload(
        models=models, iteration=1, robot="h1", layout=dims.as_layout(),
        config=OmegaConf.to_container(bounded, resolve=True, enum_to_str=True)))
    actor = load_oracle_actor(compose_config("trail=flat", *SMALL), path, env)
    assert actor.module[0].module[2].module.bound == 4.8
    with pytest.raises(CheckpointError, match="robot"):
        load_oracle_actor(compose_config("trail=flat", *SMALL, "robot=g1"), path, env)
    env.close()
