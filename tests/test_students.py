"""Students (LEGO-H and the baselines): keys and shapes on a real env, latent tiling,
recurrent state, gradients, and the re-run through time used by the imitation losses."""

import pytest
import torch
from torchrl.envs.utils import ExplorationType, set_exploration_type

from legoh import keys
from legoh.modules.actor_critic import LOC
from legoh.modules.students import STUDENTS, StudentDims, make_student, unroll
from legoh.objectives.distill import distillation_loss, goal_correction_target
from legoh.policies.student import make_student_env, state_shapes
from tests.conftest import compose_config

NUM_ENVS, STEPS = 3, 12


@pytest.fixture(scope="module")
def cfg():
    return compose_config("trail=flat", "algo=unified", "env.depth.every=5")


# each student, and LEGO-H whose locomotion reads a history latent too (algo.history_latent)
VARIANTS = [*sorted(STUDENTS), "lego_h+history"]


def build(cfg, variant):
    name, _, extra = variant.partition("+")
    algo = {"lego_h": "unified", "ep_h": "ep_h", "rma_b": "rma_b", "rma_h": "rma_h"}[name]
    run_cfg = compose_config("trail=flat", f"algo={algo}")
    probe = make_student_env(run_cfg, 1, ((1,), 1))
    far = run_cfg.algo.depth_far or run_cfg.env.depth.far
    dims = StudentDims.from_spec(probe.observation_spec, depth_far=far)
    probe.close()
    student = make_student(name, dims, 10, 4.8, history_latent=extra == "history")
    env = make_student_env(run_cfg, NUM_ENVS, state_shapes(student))
    return run_cfg, student, env


def deterministic_rollout(student, env):
    """STEPS steps of the student's mean action from seed 0; closes ``env``."""
    try:
        torch.manual_seed(0)
        with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
            return env.rollout(STEPS, student.policy, break_when_any_done=False)
    finally:
        env.close()


@pytest.mark.parametrize("name", VARIANTS)
def test_student_rollout_keys_shapes_and_tiling(cfg, name):
    run_cfg, student, env = build(cfg, name)
    try:
        torch.manual_seed(0)
        with torch.no_grad():
            td = env.rollout(STEPS, student.policy, break_when_any_done=False)
    finally:
        env.close()
    assert td.shape == (NUM_ENVS, STEPS)
    assert td["action"].shape == (NUM_ENVS, STEPS, 10)
    assert td[keys.STUDENT_LATENT].shape == (NUM_ENVS, STEPS, 32)
    nav = student.navigation.navigator
    assert td[keys.NAV_GOAL].shape == (NUM_ENVS, STEPS, nav.nav_dim)
    assert td[keys.NEAR_GOALS].shape == (NUM_ENVS, STEPS, nav.num_goals, 2)
    assert torch.isfinite(td["action"]).all()
    assert (keys.HISTORY_LATENT in td.keys(True)) == name.endswith("+history")
    if nav.history_dim:
        assert td[keys.HISTORY_LATENT].shape == (NUM_ENVS, STEPS, 20)
    if nav.uses_depth:
        fresh = td[keys.DEPTH_FRESH].reshape(NUM_ENVS, STEPS)[0]
        assert fresh[0] and fresh.sum() < STEPS  # a frame at reset, then every 5 steps
        held = td["next", *keys.NAV_HELD][0]
        for t in range(1, STEPS):  # latent tiling: the held outputs change only on new frames
            same = torch.equal(held[t], held[t - 1])
            assert same == (not bool(fresh[t]) and not bool(td[keys.IS_INIT][0, t]))


@pytest.mark.parametrize("name", VARIANTS)
def test_unroll_reproduces_collection_and_gradients_reach_every_parameter(cfg, name):
    run_cfg, student, env = build(cfg, name)
    td = deterministic_rollout(student, env)
    out = unroll(student.navigation, td)
    torch.testing.assert_close(out[keys.STUDENT_LATENT], td[keys.STUDENT_LATENT])
    torch.testing.assert_close(out[keys.NAV_GOAL], td[keys.NAV_GOAL])
    history = student.navigation.navigator.history_dim
    if history:
        torch.testing.assert_close(out[keys.HISTORY_LATENT], td[keys.HISTORY_LATENT])

    # labels of the right shapes stand in for the oracle's
    td.set(keys.TEACHER_ACTION, torch.randn_like(td["action"]))
    td.set(keys.TEACHER_LATENT, torch.rand_like(td[keys.STUDENT_LATENT]) - 0.5)
    td.set(keys.TEACHER_PRIV_LATENT, torch.rand(NUM_ENVS, STEPS, 20))
    head_in = out.clone(recurse=False)
    head_in.set(keys.PROPRIO, td[keys.PROPRIO])
    loc = student.locomotion.module[0](head_in).get(LOC)
    w = run_cfg.algo.weights
    loss = distillation_loss(out, loc, td, w)
    assert ("loss_priv_latent" in loss.keys()) == bool(history)
    total = sum(v for k, v in loss.items() if k.startswith("loss_"))
    # PPO trains the std: the log-likelihood of the collected actions reaches it
    dist = student.locomotion.get_dist(td.select(*student.locomotion.in_keys).clone())
    total = total - dist.log_prob(td["action"]).mean()
    total.backward()
    for mod_name, module in student.modules().items():
        for pname, p in module.named_parameters():
            assert p.grad is not None, f"{name}: no gradient reaches {mod_name}.{pname}"
            assert torch.isfinite(p.grad).all(), f"{name}: {mod_name}.{pname}"


def test_zero_state_is_a_new_episode(cfg):
    """is_init resets the recurrent state whatever was stored."""
    _, student, env = build(cfg, "ep_h")
    try:
        td = env.reset()
    finally:
        env.close()
    nav = student.navigation
    with torch.no_grad():
        a = nav(td.clone())[keys.STUDENT_LATENT]
        dirty = td.clone()
        dirty.set(keys.NAV_STATE, torch.randn_like(td[keys.NAV_STATE]))
        b = nav(dirty)[keys.STUDENT_LATENT]
    assert td[keys.IS_INIT].all()
    torch.testing.assert_close(a, b)


def test_goal_correction_target_turns_the_terminus_toward_the_waypoint():
    goal = torch.tensor([[10.0, 0.0, 5.0, 0.0]])
    expert = torch.tensor([[[1.0, 1.0], [2.0, 2.0], [3.0, 3.0]]])
    target = goal_correction_target(goal, expert)
    torch.testing.assert_close(target, torch.tensor([[2 ** -0.5 - 1.0, 2 ** -0.5]]))


def test_unknown_student_is_refused(cfg):
    dims = StudentDims(proprio=39, history=10, depth=(4, 24, 32))
    with pytest.raises(ValueError, match="unknown student 'ep-h'"):
        make_student("ep-h", dims, 10, 4.8)
    with pytest.raises(ValueError, match="needs depth frames"):
        make_student("ep_h", StudentDims(proprio=39, history=10, depth=None), 10, 4.8)
    with pytest.raises(ValueError, match="algo.history_latent=true applies to student "
                                         "'lego_h' only, got algo.student='rma_b'"):
        make_student("rma_b", dims, 10, 4.8, history_latent=True)


def test_unroll_encodes_fresh_frames_ahead_with_the_same_result(cfg, monkeypatch):
    """unroll encodes every fresh frame of the batch in one call (LEGO-H's TC-ViTs
    encoder); outputs and gradients equal those of encoding step by step."""
    import legoh.modules.students as students

    _, student, env = build(cfg, "lego_h")
    td = deterministic_rollout(student, env)
    nav = student.navigation
    ahead = students.encode_fresh(nav.navigator, td)
    fresh = (td[keys.IS_INIT] | td[keys.DEPTH_FRESH]).reshape(NUM_ENVS, STEPS)
    assert ahead.shape[:2] == (NUM_ENVS, STEPS) and (ahead[~fresh] == 0).all()

    def run():
        nav.zero_grad()
        out = unroll(nav, td)
        (out[keys.STUDENT_LATENT].square().sum() + out[keys.NAV_GOAL].square().sum()).backward()
        return out, {n: p.grad.clone() for n, p in nav.named_parameters()}

    out, grads = run()
    monkeypatch.setattr(students, "encode_fresh", lambda nav, batch: None)  # step by step
    out_ref, grads_ref = run()
    torch.testing.assert_close(out[keys.STUDENT_LATENT], out_ref[keys.STUDENT_LATENT])
    for name, g in grads.items():
        torch.testing.assert_close(g, grads_ref[name], rtol=1e-4, atol=1e-6, msg=name)
