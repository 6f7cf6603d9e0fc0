"""Issue 11's faults and the walking recipe: policy head, schedule counter, torque memory,
episode-length scalar, command, gait clock, reward presets, per-joint action scale.

Each fault test failed on the code before the fix (stated per test).
"""

import numpy as np
import pytest
import torch
from tensordict import TensorDict
from torchrl.envs.utils import ExplorationType, set_exploration_type

from legoh import keys
from legoh.envs.hiking_env import make_env
from legoh.envs.mdp.events import randomizing
from legoh.envs.mdp.state import compute_state, gait_phase
from legoh.policies.oracle import build_oracle
from legoh.train.runner import batch_scalars
from tests.conftest import compose_config

ONE_TILE = ("trail=flat", "trail.levels=1", "trail.variants=1")


def cfg_of(*overrides: str):
    return compose_config(*ONE_TILE, *overrides)


def test_untrained_oracle_stands_for_five_seconds() -> None:
    # Fault 1: the mean was 4.8 tanh(h); the untrained deterministic policy fell in ~1.3 s.
    cfg = cfg_of("env.randomization.enabled=false")
    env = make_env(cfg, num_envs=4)
    torch.manual_seed(0)
    _, actor, _, _ = build_oracle(env, cfg)
    td = env.reset()
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        for _ in range(int(5.0 / env.dt)):
            td = env.step(actor(td))
            # a fall terminates (a training time-out may come early: env.stagger_timeouts)
            assert not td["next", keys.TERMINATED].any(), "a robot fell under the untrained policy"
            td = td["next"]
    env.close()


def test_paper_head_stays_selectable() -> None:
    cfg = cfg_of("algo.tanh_bound=4.8")
    env = make_env(cfg, num_envs=2)
    _, actor, _, _ = build_oracle(env, cfg)
    with torch.no_grad():
        loc = actor(env.reset())[("hidden", "action_loc")]
    assert loc.abs().max() <= 4.8
    env.close()


def test_schedule_counts_vectorised_steps() -> None:
    # Fault 4: global_steps grew by num_envs per step, so the delay switched on 64x early.
    cfg = cfg_of("env.randomization.schedule=steps", "env.randomization.delay_after_steps=10",
                 "env.randomization.start_after_steps=5")
    env = make_env(cfg, num_envs=8)
    td = env.reset()
    for _ in range(6):
        td = env.step(td.set(keys.ACTION, torch.zeros(8, env.num_actions)))["next"]
    assert env.global_steps == 6
    assert randomizing(env)  # physics draws and pushes from step 5
    env._reset_envs(torch.arange(8))
    assert (env.action_delay.delay == 0).all()  # delays only after 10 vectorised steps
    assert (env.sim.model_of_env > 0).all()  # randomised pool members, not the nominal 0
    env.close()


def test_nominal_model_before_the_schedule_starts() -> None:
    env = make_env(cfg_of(), num_envs=8)
    env.reset()
    assert not randomizing(env)
    assert (env.sim.model_of_env == 0).all()
    np.testing.assert_allclose(env.physics_features[0], [1, 0, 0, 0, 0, 1])
    env.close()


def test_a_robot_blind_to_physics_reads_the_nominal_draw_while_its_draw_acts() -> None:
    # randomization_gap.py --blind: the oracle's privileged input without the draws
    cfg = cfg_of("env.randomization.schedule=steps", "env.randomization.start_after_steps=0",
                 "env.randomization.observe_physics=false")
    env = make_env(cfg, num_envs=8)
    td = env.reset()
    assert (env.sim.model_of_env > 0).all()  # each robot steps a drawn model
    frictions = {float(m.geom_friction[m.geom_priority > 0, 0][0]) for m in env.sim.models}
    assert len(frictions) == len(env.sim.models)  # the draws differ...
    physics = td[keys.PRIVILEGED][:, :6]  # ...but every robot reads the nominal one
    torch.testing.assert_close(physics, torch.tensor([[1.0, 0, 0, 0, 0, 1]]).expand(8, 6))
    env.close()


def test_delta_torques_sees_the_previous_step() -> None:
    # Fault 6: last_torques was a view into sensordata, overwritten by the next step: the
    # term read 0 from the second step of every episode.
    cfg = cfg_of("env.rewards.delta_torques=-1.0", "env.randomization.enabled=false")
    env = make_env(cfg, num_envs=4)
    td = env.reset()
    gen = torch.Generator().manual_seed(0)
    for step in range(3):
        action = torch.randn(4, env.num_actions, generator=gen) * 5
        out = env.step(td.set(keys.ACTION, action))
        term = out["next", keys.REWARD_TERMS, "delta_torques"]
        if step > 0:
            assert (term < 0).all(), f"delta_torques read 0 on step {step + 1}"
        sd = env.sim.sensordata.untyped_storage()
        ptr = env.memory.torques.untyped_storage().data_ptr()
        assert not sd.data_ptr() <= ptr < sd.data_ptr() + sd.nbytes()
        td = out["next"]
    env.close()


def _batch(done: torch.Tensor, steps: torch.Tensor) -> TensorDict:
    n, t = done.shape
    nxt = TensorDict({
        "done": done[..., None], "reward": torch.zeros(n, t, 1),
        keys.EPISODE_STEPS: steps, keys.LEVEL: torch.zeros(n, t, dtype=torch.int64),
        keys.REACHED: torch.zeros(n, t, dtype=torch.bool), keys.FELL: done.clone(),
        keys.DIVERGED: torch.zeros(n, t, dtype=torch.bool),
        keys.PROGRESS: torch.zeros(n, t), keys.REWARD_TERMS: TensorDict({}, [n, t]),
        keys.EPISODE_METRES: steps.float() * 0.01,  # 0.5 m/s at 50 Hz
    }, [n, t])
    return TensorDict({"next": nxt}, [n, t])


def test_episode_length_is_that_of_the_ended_episodes() -> None:
    # Fault 10: frames over dones read as the whole batch when no episode ended (a 30.7 s
    # episode under a 20 s limit).
    none = _batch(torch.zeros(4, 24, dtype=torch.bool), torch.arange(24).expand(4, 24))
    assert np.isnan(batch_scalars(none)["episode_frames"])
    done = torch.zeros(4, 24, dtype=torch.bool)
    done[0, 9], done[1, 19] = True, True
    steps = torch.arange(1, 25).expand(4, 24).clone()
    stats = batch_scalars(_batch(done, steps))
    assert stats["episode_frames"] == pytest.approx(15.0)
    assert stats["episode_metres"] == pytest.approx(0.15)  # of the ended episodes only


def test_command_steers_toward_the_waypoint_and_can_be_zero() -> None:
    cfg = cfg_of("env.command.zero_prob=0.5")
    env = make_env(cfg, num_envs=32)
    td = env.reset()
    cmd = td[keys.COMMAND].numpy()
    standing = cmd[:, 0] == 0
    assert 0 < standing.sum() < 32
    assert (cmd[standing, 1] == 0).all()
    lo, hi = cfg.env.command.speed
    assert ((cmd[~standing, 0] >= lo) & (cmd[~standing, 0] <= hi)).all()
    # turned left of the waypoint by 0.5 rad: a negative (clockwise) yaw rate
    env.sim.qpos[:, 3:7] = 0.0
    pos = env.sim.qpos[:, 0:3]
    d = env.goals.ahead(0) - pos[:, :2]
    heading = torch.atan2(d[:, 1], d[:, 0]) + 0.5
    env.sim.qpos[:, 3], env.sim.qpos[:, 6] = torch.cos(heading / 2), torch.sin(heading / 2)
    command = compute_state(env).command.numpy()
    assert (command[~standing, 1] < 0).all()
    env.close()


def test_evaluation_commands_the_goal_speed() -> None:
    env = make_env(cfg_of("env.command.zero_prob=1.0"), num_envs=4, evaluation=True)
    env.reset()
    assert (env.command.value[:, 0] == env.cfg.goal_speed).all()
    env.close()


def test_gait_clock_is_observed_and_legs_alternate() -> None:
    env = make_env(cfg_of(), num_envs=2)
    td = env.reset()
    proprio = td[keys.PROPRIO]
    np.testing.assert_allclose(proprio[:, -2:].numpy(), [[0.0, 1.0]] * 2, atol=1e-6)
    env.steps[:] = 10
    phase = gait_phase(env.steps, env.dt, env.cfg.gait.period, env.num_feet).numpy()
    np.testing.assert_allclose((phase[:, 1] - phase[:, 0]) % 1.0, 0.5)
    env.close()


def test_reward_presets() -> None:
    hike = make_env(cfg_of(), num_envs=2)  # the default: velocity toward the waypoint
    assert "tracking_waypoint_vel" in hike.reward_terms
    assert "tracking_lin_vel" not in hike.reward_terms and not hike.only_positive
    hike.close()
    walk = make_env(cfg_of("env.reward_preset=walk"), num_envs=2)
    assert "tracking_lin_vel" in walk.reward_terms and "tracking_goal_vel" not in walk.reward_terms
    assert "tracking_waypoint_vel" not in walk.reward_terms and not walk.only_positive
    walk.close()
    table6 = make_env(cfg_of("env.reward_preset=table6"), num_envs=2)
    assert table6.reward_terms["tracking_goal_vel"][1] == 10.0
    assert table6.reward_terms["base_height"][1] == -100.0  # H1's Table 6 column
    assert table6.only_positive
    table6.close()
    with pytest.raises(ValueError, match="reward_preset"):
        make_env(cfg_of("env.reward_preset=nope"), num_envs=2)


def test_per_joint_action_scale_from_effort() -> None:
    env = make_env(cfg_of(), num_envs=2)
    r = env.robot
    a = r.num_actions
    np.testing.assert_allclose(r.action_scale, 0.5 * r.torque_limit[:a] / r.kp[:a])
    env.close()
    fixed = make_env(cfg_of("robot.effort_action_scale=null"), num_envs=2)
    np.testing.assert_allclose(fixed.robot.action_scale, 0.25)
    fixed.close()
