"""The step's term tables (``legoh.envs.mdp``) and the physics backend contract: stateful
terms reset only their rows, the observation spec comes from the observation table, the
proprio layout, torch terrain lookups against the numpy reference, reproducibility."""

import importlib.util

import mujoco
import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from legoh import keys
from legoh.envs.batched_sim import BatchedSim
from legoh.envs.hiking_env import HikingEnv, make_env
from legoh.envs.mdp import observations
from legoh.envs.mdp.events import ActionDelay
from legoh.envs.mdp.observations import ProprioHistory
from legoh.envs.mdp.state import AirTime, Grid, Memory
from legoh.envs.physics import make_physics
from legoh.envs.randomization import draw_physics
from legoh.envs.terrain.terrain_map import bilinear
from tests.conftest import compose_config

ONE_TILE = ("trail=flat", "trail.levels=1", "trail.variants=1")
N = 4
ROWS = torch.tensor([1, 3])  # the envs being reset
KEPT = torch.tensor([0, 2])


@pytest.fixture(scope="module")
def env() -> HikingEnv:
    e = make_env(compose_config(*ONE_TILE), num_envs=N)
    yield e
    e.close()


# --------------------------------------------------------------------------- stateful terms
def _filled(term, attrs: list[str]):
    for a in attrs:
        setattr(term, a, torch.ones_like(getattr(term, a)))
    return term


@pytest.mark.parametrize("make,attrs", [
    (lambda: AirTime(N, 2, 0.02, torch.device("cpu"), torch.float64), ["time"]),
    (lambda: Memory(N, 3, 5, torch.device("cpu"), torch.float64),
     ["action", "dof_vel", "torques"]),
    (lambda: ProprioHistory(N, 10, 7, torch.device("cpu")), ["buf"]),
    (lambda: ActionDelay(N, 2, 3, torch.device("cpu"), torch.float64), ["buf"]),
], ids=["air_time", "memory", "history", "action_delay"])
def test_stateful_term_reset_clears_only_its_rows(make, attrs: list[str]) -> None:
    term = _filled(make(), attrs)
    term.reset(ROWS)
    for a in attrs:
        buf = getattr(term, a)
        assert not buf[ROWS].any(), a
        assert (buf[KEPT] == 1).all(), a


def test_goals_reset_clears_only_its_rows(env: HikingEnv) -> None:
    env.goals.index[:] = 1
    env.goals.reset(ROWS)
    assert env.goals.index.tolist() == [1, 0, 1, 0]
    env.goals.index[:] = 0


def test_action_delay_applies_the_delayed_action() -> None:
    delay = ActionDelay(2, 1, 1, torch.device("cpu"), torch.float64)
    delay.delay[:] = torch.tensor([0, 1])
    delay(torch.tensor([[1.0], [1.0]]))
    applied = delay(torch.tensor([[2.0], [2.0]]))
    assert applied[:, 0].tolist() == [2.0, 1.0]  # env 1 acts one step late


# --------------------------------------------------------------------------- observations
def test_spec_matches_what_the_table_produces(env: HikingEnv) -> None:
    td = env.reset()
    table = set(observations.observation_table(env))
    produced = {k for k in td.keys(True, True) if k[0] in ("obs", "expert", "info")
                and k[:2] != keys.REWARD_TERMS}
    flags = {(keys.INFO, name) for name in ("reached", "fell", "diverged")}
    assert produced == (table - {keys.REWARD_TERMS}) | flags
    assert env.observation_spec.is_in(td.select(*env.observation_spec.keys(True, True)))


def test_a_new_table_term_reaches_the_spec(monkeypatch) -> None:
    extra = ("obs", "base_height")
    original = observations.observation_table

    def with_extra(e):
        return {**original(e), extra: lambda e, obs: e.state.base_height[:, None]}

    monkeypatch.setattr(observations, "observation_table", with_extra)
    e = make_env(compose_config(*ONE_TILE), num_envs=2)
    try:
        assert e.observation_spec[extra].shape == (2, 1)
        assert e.reset()[extra].shape == (2, 1)
    finally:
        e.close()


def test_proprio_layout(env: HikingEnv) -> None:
    """ang_vel x 0.25, gravity, joints - default, joint vel x 0.05, last action, terminus
    direction (2) and distance / 20 (1), sin and cos of the gait clock."""
    td = env.reset()
    action = torch.rand(N, env.num_actions, generator=torch.Generator().manual_seed(1)) - 0.5
    out = env.step(td.set(keys.ACTION, action))["next"]
    p, a = out[keys.PROPRIO].double(), env.num_actions
    qpos, qvel = env.sim.qpos, env.sim.qvel
    parts = [qvel[:, 3:6] * 0.25, None, qpos[:, 7:7 + a] - env.default_pose[:a],
             qvel[:, 6:6 + a] * 0.05, action.double()]
    widths = [3, 3, a, a, a]
    start = 0
    for part, w in zip(parts, widths, strict=True):
        if part is not None:
            torch.testing.assert_close(p[:, start:start + w], part, atol=1e-6, rtol=1e-5)
        start += w
    gravity = p[:, 3:6]
    torch.testing.assert_close(gravity.norm(dim=1), torch.ones(N, dtype=torch.float64))
    direction, dist = p[:, start:start + 2], p[:, start + 2]
    goal = out[keys.GOAL][:, :2].double()
    torch.testing.assert_close(direction, goal / goal.norm(dim=1, keepdim=True), atol=1e-6,
                               rtol=1e-5)
    torch.testing.assert_close(dist, torch.clamp(goal.norm(dim=1) / 20, max=1.0))
    clock = p[:, start + 3:start + 5]
    torch.testing.assert_close(clock.norm(dim=1), torch.ones(N, dtype=torch.float64))
    assert p.shape[1] == start + 5 == env.proprio_dim


def test_proprio_slices_by_name(env: HikingEnv) -> None:
    """The slices readers take by name (the runner's logged joints) are the layout above."""
    a, p = env.num_actions, env.proprio_dim
    assert observations.proprio_slice("joint_pos", a) == slice(6, 6 + a)
    assert observations.proprio_slice("last_action", a) == slice(6 + 2 * a, 6 + 3 * a)
    assert observations.proprio_slice("gait_clock", a) == slice(p - 2, p)
    with pytest.raises(KeyError, match="joint_pos"):
        observations.proprio_slice("joint_position", a)


# --------------------------------------------------------------------------- terrain
def test_grid_lookups_match_the_numpy_reference() -> None:
    rng = np.random.default_rng(0)
    values = rng.random((30, 20)).astype(np.float32)
    origin, res = np.array([-1.0, 2.0]), 0.1
    grid = Grid(values, origin, res, torch.device("cpu"), torch.float64)
    xy = rng.uniform([-1.5, 1.5], [2.5, 4.5], (64, 2))  # inside and beyond the edges
    ref = bilinear(values, origin, res, xy)
    np.testing.assert_allclose(grid.bilinear(torch.as_tensor(xy)).numpy(), ref, atol=1e-12)
    mask = values > 0.5
    edges = Grid(mask, origin, res, torch.device("cpu"), torch.float64, torch.bool)
    ij = np.rint((xy - origin) / res).astype(np.int64)
    i, j = np.clip(ij[:, 0], 0, 29), np.clip(ij[:, 1], 0, 19)
    np.testing.assert_array_equal(edges.nearest(torch.as_tensor(xy)).numpy(), mask[i, j])


# --------------------------------------------------------------------------- reproducibility
def test_same_seed_same_trail_and_rollout() -> None:
    cfg = compose_config("trail=flat", "trail.levels=2", "trail.variants=2")
    runs = []
    for _ in range(2):
        e = make_env(cfg, num_envs=3)
        td, gen = e.reset(), torch.Generator().manual_seed(5)
        for _ in range(20):
            td.set(keys.ACTION, torch.randn(3, e.num_actions, generator=gen) * 0.3)
            _, td = e.step_and_maybe_reset(td)
        runs.append((e.goals.tile.clone(), e.sim.qpos.clone(), td[keys.PROPRIO].clone()))
        e.close()
    for a, b in zip(*runs, strict=True):
        assert torch.equal(a, b)


# --------------------------------------------------------------------------- physics
def _model() -> mujoco.MjModel:
    """A free ball: the smallest model with a base body."""
    return mujoco.MjModel.from_xml_string(
        "<mujoco><worldbody><body name='b'><freejoint/><geom size='0.1' priority='1'/>"
        "</body></worldbody></mujoco>")


def test_mujoco_backend_exposes_torch_views() -> None:
    cfg = OmegaConf.to_object(compose_config(*ONE_TILE).env.randomization)
    cfg.enabled = False
    sim = make_physics("mujoco", _model(), "b", draw_physics(cfg, 0, None), 3, 2, 1, "cpu")
    try:
        assert isinstance(sim, BatchedSim) and sim.dtype == torch.float64
        assert sim.qpos.shape == (3, 7) and sim.qvel.shape == (3, 6)
        assert sim.model_of_env.dtype == torch.int64 and sim.num_draws == 1
        sim.qvel[1, 0] = 2.5  # a write into the view is a write into the physics state
        assert sim.state[1, 1 + sim.nq] == 2.5
        ids = torch.tensor([0])
        qpos = torch.tensor([[0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0]], dtype=torch.float64)
        sim.reset_envs(ids, qpos, torch.zeros(1, 6, dtype=torch.float64),
                       torch.zeros(1, 0, dtype=torch.float64))
        sim.step(torch.zeros(3, 0, dtype=torch.float64))
        assert sim.time.shape == (3,) and (sim.time > 0).all()
        assert sim.qpos[0, 2] < 1.0  # it fell under gravity
    finally:
        sim.close()


def test_unknown_backend_is_refused() -> None:
    with pytest.raises(ValueError, match="known backends"):
        make_physics("bullet", _model(), "b", None, 1, 1, 1, "cpu")


@pytest.mark.skipif(importlib.util.find_spec("mujoco_warp") is not None,
                    reason="MuJoCo Warp is installed here")
def test_warp_backend_without_warp_names_the_gpu_extra() -> None:
    with pytest.raises(ImportError, match=r"gpu"):
        make_physics("warp", _model(), "b", None, 1, 1, 1, "cuda")
