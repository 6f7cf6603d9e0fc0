"""HikingEnv: specs, determinism, partial resets, terminations, depth, divergence, curriculum.

Scenes are built once per module on a one-tile map (``trail.levels=1 trail.variants=1``) and
shared by the envs of a test; each env is small (2-4 robots) and closed after its test.
"""

from collections.abc import Callable, Iterator

import mujoco
import numpy as np
import pytest
import torch
from omegaconf import DictConfig, OmegaConf
from tensordict import TensorDictBase
from torchrl.envs.utils import check_env_specs

from legoh import keys
from legoh.envs.curriculum import update_levels
from legoh.envs.hiking_env import HikingEnv
from legoh.envs.math3d import wrap_angle
from legoh.envs.mdp.events import SPAWN_YAW_NOISE
from legoh.envs.mdp.terminations import TERMINATIONS, Outcome, Termination
from legoh.envs.robots import CAMERA_NAME
from legoh.envs.scene import Scene, build_scene
from legoh.envs.terrain import build_terrain_map
from tests.conftest import compose_config

ROBOTS = ["h1", "g1"]
TRAILS = ["flat", "randommix", "ditch", "hurdle", "gap", "forest", "hill"]
ONE_TILE = ("trail.levels=1", "trail.variants=1")


def config(robot: str = "h1", trail: str = "flat", *overrides: str) -> DictConfig:
    """A composed run config on a one-tile map."""
    return compose_config(f"robot={robot}", f"trail={trail}", *ONE_TILE, *overrides)


def scene_of(cfg: DictConfig, boxes: np.ndarray | None = None) -> Scene:
    """The scene of ``cfg``'s map, with extra ``boxes`` (M, 7) rows added when given."""
    terrain = build_terrain_map(OmegaConf.to_object(cfg.trail), cfg.seed)
    if boxes is not None:
        terrain.boxes = np.vstack([terrain.boxes, boxes]).astype(np.float32)
    return build_scene(OmegaConf.to_object(cfg.robot), terrain, cfg.sim.dt)


@pytest.fixture(scope="module")
def flat() -> tuple[DictConfig, Scene]:
    cfg = config()
    return cfg, scene_of(cfg)


EnvFactory = Callable[..., HikingEnv]


@pytest.fixture
def make(flat: tuple[DictConfig, Scene]) -> Iterator[EnvFactory]:
    """``make(num_envs, seed=0, cfg=None, scene=None, evaluation=False, **env_fields)``: a
    HikingEnv on the shared flat scene unless told otherwise; every env made is closed
    after the test."""
    made: list[HikingEnv] = []

    def factory(num_envs: int = 4, seed: int = 0, cfg: DictConfig | None = None,
                scene: Scene | None = None, evaluation: bool = False,
                **env_fields: object) -> HikingEnv:
        if cfg is None:
            cfg, scene = flat
        env_cfg = OmegaConf.to_object(cfg.env)
        # at the trail start unless a test asks otherwise: these tests place robots there
        env_cfg.spawn_along = 0.0
        for name, value in env_fields.items():
            setattr(env_cfg, name, value)
        env = HikingEnv(OmegaConf.to_object(cfg.robot), OmegaConf.to_object(cfg.trail),
                        env_cfg, OmegaConf.to_object(cfg.sim), num_envs, seed=seed, scene=scene,
                        evaluation=evaluation)
        made.append(env)
        return env

    yield factory
    for env in made:
        env.close()


def zero_step(env: HikingEnv, td: TensorDictBase) -> TensorDictBase:
    """One step holding the default pose; returns the ``next`` tensordict."""
    return env.step(td.set(keys.ACTION, torch.zeros(env.action_spec.shape)))["next"]


def random_policy(env: HikingEnv, seed: int) -> Callable[[TensorDictBase], TensorDictBase]:
    """Uniform actions in [-1, 1] from a seeded torch generator."""
    gen = torch.Generator().manual_seed(seed)

    def act(td: TensorDictBase) -> TensorDictBase:
        return td.set(keys.ACTION, torch.rand(env.action_spec.shape, generator=gen) * 2 - 1)

    return act


def flags(td: TensorDictBase, key: str | tuple[str, str]) -> list[bool]:
    """A per-env bool entry as a list."""
    return td[key].reshape(-1).tolist()


# --------------------------------------------------------------------------- specs
@pytest.mark.parametrize("trail", TRAILS)
@pytest.mark.parametrize("robot", ROBOTS)
def test_check_env_specs(make: EnvFactory, robot: str, trail: str) -> None:
    cfg = config(robot, trail)
    check_env_specs(make(2, cfg=cfg, scene=scene_of(cfg)))


def test_check_env_specs_with_depth(make: EnvFactory) -> None:
    cfg = config("h1", "flat", "env.depth.enabled=true")
    check_env_specs(make(2, cfg=cfg, scene=scene_of(cfg)))


# --------------------------------------------------------------------------- determinism
def rollout(env: HikingEnv, steps: int = 100) -> TensorDictBase:
    return env.rollout(steps, random_policy(env, seed=7), break_when_any_done=False)


def test_same_seed_same_observations(make: EnvFactory) -> None:
    a, b = rollout(make(2, seed=3)), rollout(make(2, seed=3))
    obs_keys = [k for k in a.keys(True, True) if "obs" in k or "expert" in k]
    assert len(obs_keys) >= 10  # root and ("next", ...) observations
    for key in obs_keys:
        assert torch.equal(a[key], b[key]), key


def test_compiled_step_equals_the_eager_one(make: EnvFactory, monkeypatch) -> None:
    """``env.compile`` traces a step's and a reset's derivations into one graph each
    (fullgraph: a term that breaks the graph fails here) with the same state, bookkeeping,
    rewards and observations as the eager env, resets included. The aot_eager backend
    runs the traced graph with torch's own kernels (the inductor's C++ build is what
    experiments/bench.py env times)."""
    import functools

    monkeypatch.setattr(torch, "compile", functools.partial(torch.compile, backend="aot_eager"))
    torch._dynamo.reset()
    eager, compiled = make(3, seed=5), make(3, seed=5, compile=True)
    assert compiled._after_step is not compiled._derive_step
    a, b = rollout(eager, 120), rollout(compiled, 120)
    assert a["next", keys.DONE].any()  # the reset graph ran too
    for key in a.keys(True, True):
        torch.testing.assert_close(a[key], b[key], rtol=1e-6, atol=1e-6, msg=str(key))
    torch.testing.assert_close(eager.episode_metres, compiled.episode_metres)
    torch.testing.assert_close(eager.goals.index, compiled.goals.index)


def test_compile_without_a_cpp_compiler_is_refused_naming_the_key(make: EnvFactory,
                                                                  monkeypatch) -> None:
    import torch._inductor.config as inductor

    monkeypatch.setattr(inductor.cpp, "cxx", (None, "/nonexistent/g++"))
    with pytest.raises(RuntimeError, match="env.compile=false"):
        make(2, compile=True)


def test_different_seed_different_observations(make: EnvFactory) -> None:
    a, b = rollout(make(2, seed=3), 20), rollout(make(2, seed=4), 20)
    assert not torch.equal(a["next", "obs", "proprio"], b["next", "obs", "proprio"])


# --------------------------------------------------------------------------- resets
def test_partial_reset_touches_only_masked_envs(make: EnvFactory) -> None:
    env = make(4)
    td = env.reset()
    for _ in range(15):
        td = zero_step(env, td)
    held = td.clone()
    qpos = env.sim.qpos.clone()
    mask = torch.tensor([True, False, True, False])
    keep = ~mask
    out = env.reset(td.clone().set("_reset", mask[:, None]))

    assert torch.equal(td["obs", "proprio_history"], held["obs", "proprio_history"]), (
        "a reset changed tensors returned earlier")
    assert torch.equal(env.sim.qpos[keep], qpos[keep])
    assert not torch.allclose(env.sim.qpos[~keep, :2], qpos[~keep, :2])
    np.testing.assert_array_equal(env.steps, [0, 15, 0, 15])
    for key in out["obs"].keys():
        assert torch.equal(out["obs", key][keep], held["obs", key][keep]), key

    after = zero_step(env, out)
    history, before = after["obs", "proprio_history"], held["obs", "proprio_history"]
    # The kept envs' history moved on by exactly one step (no entry from the reset)...
    assert torch.equal(history[keep, :-1], before[keep, 1:])
    # ...and the reset envs' history holds only the reset and this step.
    assert not history[~keep, :-2].any()
    assert history[~keep, -2:].abs().sum(-1).gt(0).all()


# --------------------------------------------------------------------------- spawn
def spawn_of(td: TensorDictBase) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(tile, goal index, base xy, yaw) of each robot in a reset TensorDict."""
    quat = td[keys.BASE_QUAT].numpy()  # (w, x, y, z), upright: a rotation about z
    return (td[keys.TILE].numpy(), td[keys.WAYPOINT].numpy(), td[keys.BASE_POS][:, :2].numpy(),
            2.0 * np.arctan2(quat[:, 3], quat[:, 0]))


def test_spawn_along_the_trail_stands_robots_on_waypoints(make: EnvFactory) -> None:
    """env.spawn_remaining=[2, 10] on the flat tile (waypoints 20, 18, ..., 2, 0 m from
    the terminus): each robot stands on a waypoint 2-10 m from the terminus, faces the next
    one, its goal index is that next one, and progress counts from the trail start.

    Failed before with: every robot at the trail start, goal index 0."""
    lo, hi = 2.0, 10.0
    env = make(16, spawn_remaining=[lo, hi], spawn_noise=0.0)
    tile, goal, xy, yaw = spawn_of(env.reset())
    t = env.trails
    on = goal - 1  # the waypoint stood on
    assert (on >= 0).all() and (goal <= t.count[tile] - 1).all()
    np.testing.assert_allclose(xy, t.waypoints[tile, on], atol=1e-6)
    left = t.length[tile] - t.cum_length[tile, on]
    assert ((left >= lo - 1e-9) & (left <= hi + 1e-9)).all()
    assert len(set(on.tolist())) >= 3  # uniform over the five waypoints in range
    np.testing.assert_array_equal(env.goals.index.numpy(), goal)
    to_next = t.waypoints[tile, goal] - xy
    heading = np.arctan2(to_next[:, 1], to_next[:, 0])
    assert (np.abs(wrap_angle(torch.as_tensor(yaw - heading)).numpy())
            <= SPAWN_YAW_NOISE + 1e-6).all()
    progress = env.goals.progress(env.state.base_xy).numpy()
    np.testing.assert_allclose(progress, 1.0 - left / t.length[tile], atol=1e-6)


def test_spawn_along_the_trail_keeps_the_jitter(make: EnvFactory) -> None:
    env = make(8, spawn_remaining=[2.0, 10.0])  # the default spawn_noise, 0.3 m
    tile, goal, xy, _ = spawn_of(env.reset())
    offset = np.abs(xy - env.trails.waypoints[tile, goal - 1])
    assert (offset <= env.cfg.spawn_noise + 1e-6).all() and offset.max() > 0.01


@pytest.mark.parametrize(("remaining", "left"), [([10.6, 11.0], 10.0), ([0.0, 0.5], 2.0),
                                                 ([30.0, 40.0], 20.0)])
def test_spawn_range_without_a_waypoint_takes_the_closest_never_the_terminus(
        make: EnvFactory, remaining: list[float], left: float) -> None:
    env = make(4, spawn_remaining=remaining, spawn_noise=0.0)
    tile, goal, _, _ = spawn_of(env.reset())
    t = env.trails
    np.testing.assert_allclose(t.length[tile] - t.cum_length[tile, goal - 1], left, atol=1e-6)


def test_spawn_at_the_trail_start_without_spawn_along(make: EnvFactory) -> None:
    """Training (env.spawn_remaining unset) with env.spawn_along=0 (the fixture's) starts at
    the trail start, goal index 0 (the share along the trail: tests/test_spawns.py)."""
    env = make(4)
    assert env.cfg.spawn_remaining is None
    tile, goal, xy, _ = spawn_of(env.reset())
    assert (goal == 0).all()
    assert (np.abs(xy - env.trails.start[tile, :2]) <= env.cfg.spawn_noise + 1e-6).all()


# --------------------------------------------------------------------------- terminations
@pytest.mark.parametrize("axis", [1, 2], ids=["roll", "pitch"])
def test_tipped_robot_falls(make: EnvFactory, axis: int) -> None:
    env = make(2)
    td = env.reset()
    tilt = np.zeros(4)
    tilt[0], tilt[axis] = np.cos(np.pi / 4), np.sin(np.pi / 4)  # 90 degrees
    env.sim.qpos[0, 3:7] = torch.as_tensor(tilt)
    out = zero_step(env, td)
    assert flags(out, keys.FELL) == [True, False]
    assert flags(out, keys.TERMINATED) == [True, False]
    assert flags(out, keys.TRUNCATED) == [False, False]
    assert flags(out, keys.DONE) == [True, False]


def test_reward_clipped_at_zero_and_a_fall_costs_the_termination_term(
        make: EnvFactory) -> None:
    env = make(2, reward_preset="table6")  # the preset that clips
    td = env.reset()
    tilt = np.array([np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0])
    env.sim.qpos[0, 3:7] = torch.as_tensor(tilt)
    out = zero_step(env, td)
    reward, terms = out[keys.REWARD][:, 0], out[keys.REWARD_TERMS]
    penalty = -200.0 * env.dt  # Table 6's preset: legged_gym's termination weight, x dt
    assert env.reward_terms["termination"].weight == -200.0
    # the fall penalty is a term of the table, logged as reward/termination
    assert terms["termination"].tolist() == pytest.approx([penalty, 0.0])
    assert float(reward[0]) == pytest.approx(penalty, abs=1e-6)  # clipped total 0 + penalty
    assert float(reward[1]) >= 0.0  # standing: the clipped total, never negative


def test_a_new_termination_term_ends_episodes(make: EnvFactory, monkeypatch) -> None:
    def off_trail(env: HikingEnv, s) -> torch.Tensor:  # a stand-in: env 1 at its third step
        return (env.steps >= 3) & (torch.arange(env.num_envs) == 1)

    monkeypatch.setitem(TERMINATIONS, "off_trail", Termination(off_trail, Outcome.failure))
    env = make(2)
    td = env.reset()
    for step in range(1, 4):
        td = zero_step(env, td)
        assert flags(td, (keys.INFO, "off_trail")) == [False, step == 3], step
    assert flags(td, keys.TERMINATED) == [False, True]
    assert flags(td, keys.TRUNCATED) == [False, False]
    assert flags(td, keys.DONE) == [False, True]
    assert env.fell_last.tolist() == [False, True]  # a failure: the gate counts it


@pytest.mark.parametrize("truncates", [True, False], ids=["truncates", "terminates"])
def test_robot_at_terminus_reaches(make: EnvFactory, truncates: bool) -> None:
    """A reach is reported either way; by default (``env.reach_truncates``) it truncates the
    episode, so GAE bootstraps past it and reaching costs no future reward (a terminating
    reach taught the H1 v2 oracle to stop 1-1.4 m short of the terminus)."""
    env = make(2, reach_truncates=truncates)
    td = env.reset()
    env.sim.qpos[1, 0:2] = torch.as_tensor(env.trails.terminus[int(env.goals.tile[1])])
    out = zero_step(env, td)
    assert flags(out, keys.REACHED) == [False, True]
    assert flags(out, keys.FELL) == [False, False]
    assert flags(out, keys.DONE) == [False, True]
    assert flags(out, keys.TERMINATED) == [False, not truncates]
    assert flags(out, keys.TRUNCATED) == [False, truncates]
    assert env.fell_last.tolist() == [False, False]  # a reach is never a fall


def test_reach_truncates_by_default_and_terminates_under_recipe_v1() -> None:
    assert config("h1", "flat").env.reach_truncates is True
    assert config("h1", "flat", "+experiment=recipe_v1").env.reach_truncates is False


def test_episode_metres_count_the_path_walked_and_restart_with_the_episode(make: EnvFactory
                                                                           ) -> None:
    """A robot moved 1 m toward its waypoint reports ~1 m walked, one left standing ~0;
    a reset episode starts again from 0 (the progress bar's ``walked``)."""
    env = make(2)
    td = env.reset()
    tile, index = int(env.goals.tile[0]), int(env.goals.index[0])
    toward = torch.as_tensor(env.trails.waypoints[tile][index], dtype=env.sim.qpos.dtype)
    toward = toward - env.sim.qpos[0, 0:2]
    env.sim.qpos[0, 0:2] += toward / torch.linalg.vector_norm(toward)
    out = zero_step(env, td)
    metres = out[keys.EPISODE_METRES]
    assert abs(float(metres[0]) - 1.0) < 0.1, metres
    assert abs(float(metres[1])) < 0.05, metres
    td = env.reset(out.select().set("_reset", torch.tensor([[True], [False]])))
    assert float(env.episode_metres[0]) == 0.0
    assert float(env.episode_metres[1]) == float(metres[1])


def test_reach_radius_of_training_and_of_evaluation() -> None:
    """One key each: ``env.reach_radius`` in training, ``eval.reach_radius`` in evaluation."""
    from legoh.envs.hiking_env import make_env

    cfg = config("h1", "flat", "env.reach_radius=0.4", "eval.reach_radius=0.7")
    for evaluation, radius in ((False, 0.4), (True, 0.7)):
        env = make_env(cfg, num_envs=1, evaluation=evaluation)
        assert env.reach_radius == radius
        env.close()


def test_timeout_truncates(make: EnvFactory) -> None:
    env = make(2, episode_length_s=0.1, stagger_timeouts=False)  # 5 policy steps at 50 Hz
    assert env.max_steps == 5
    td = env.reset()
    for step in range(1, 6):
        td = zero_step(env, td)
        assert flags(td, keys.TRUNCATED) == [step == 5] * 2, step
        assert flags(td, keys.TERMINATED) == [False, False]
    assert flags(td, keys.DONE) == [True, True]


def test_first_time_outs_are_staggered_in_training_only(make: EnvFactory) -> None:
    """env.stagger_timeouts: a training robot's first episode times out after a random
    share of the episode, later ones after all of it, so resets spread out; an evaluation
    env never staggers. Failed before: every first episode ran max_steps (all robots timed
    out together, and after each start only falls could end an episode for 20 s)."""
    for evaluation in (False, True):
        env = make(64, episode_length_s=0.2, evaluation=evaluation)  # 10 policy steps
        td = env.reset()
        ends: list[list[tuple[int, bool]]] = [[] for _ in range(64)]
        for step in range(1, 31):
            out, td = env.step_and_maybe_reset(
                td.set(keys.ACTION, torch.zeros(env.action_spec.shape)))
            nxt = out["next"]
            timed_out = (nxt[keys.TRUNCATED] & ~nxt[keys.TERMINATED]).squeeze(-1)
            for i in nxt[keys.DONE].squeeze(-1).nonzero().squeeze(1).tolist():
                ends[i].append((step, bool(timed_out[i])))
        firsts = [e[0][0] for e in ends if e and e[0][1]]
        seconds = [e[1][0] - e[0][0] for e in ends if len(e) > 1 and e[0][1] and e[1][1]]
        assert len(firsts) > 40 and seconds and set(seconds) == {10}
        if evaluation:
            assert set(firsts) == {10}  # every robot its whole episode
        else:
            assert len(set(firsts)) >= 5 and min(firsts) < 10  # spread over the episode


# --------------------------------------------------------------------------- failures
def test_nan_action_names_env_indices(make: EnvFactory) -> None:
    env = make(4)
    td = env.reset()
    action = torch.zeros(env.action_spec.shape)
    action[1, 0], action[3, 2] = float("nan"), float("inf")
    with pytest.raises(ValueError, match=r"\[1, 3\]"):
        env.step(td.set(keys.ACTION, action))


@pytest.mark.parametrize("bad_qvel", [np.nan, 1e6], ids=["nan", "huge"])
def test_diverged_env_is_reset_and_truncated(make: EnvFactory, bad_qvel: float,
                                             tmp_path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)  # MuJoCo writes its instability warning to MUJOCO_LOG.TXT
    env = make(3)
    td = env.reset()
    for _ in range(3):
        td = zero_step(env, td)
    env.sim.qvel[1] = bad_qvel
    out = zero_step(env, td)
    assert env.diverged_count == 1
    assert flags(out, keys.TRUNCATED) == [False, True, False]
    assert flags(out, keys.TERMINATED) == [False, False, False]
    np.testing.assert_array_equal(env.steps, [4, 0, 4])
    start = env.trails.start[int(env.goals.tile[1]), :2]
    assert np.abs(env.sim.qpos[1, :2].numpy() - start).max() <= env.cfg.spawn_noise + 1e-9
    for _ in range(3):
        out = zero_step(env, out)
        for key in out["obs"].keys():
            assert torch.isfinite(out["obs", key]).all(), key
    assert env.diverged_count == 1
    np.testing.assert_array_equal(env.steps, [7, 3, 7])


def test_a_diverged_env_is_reset_once_and_flagged(make: EnvFactory, tmp_path,
                                                 monkeypatch) -> None:
    """torchrl's reset of the truncated env keeps the in-place reset: the ``next`` state the
    batch records is the state the env goes on from; ``info/diverged`` marks the step.

    Failed before with: AttributeError (no keys.DIVERGED); without the flag, env 1's root
    base position moved from (4.81, 8.22) to (4.72, 7.77): a second spawn, drawn by torchrl's
    reset after the in-place one."""
    monkeypatch.chdir(tmp_path)  # MuJoCo writes its instability warning to MUJOCO_LOG.TXT
    env = make(3)
    td = env.reset()
    td = zero_step(env, td)
    env.sim.qvel[1] = 1e6
    td, root = env.step_and_maybe_reset(td.set(keys.ACTION, torch.zeros(env.action_spec.shape)))
    assert flags(td["next"], keys.DIVERGED) == [False, True, False]
    assert flags(root, keys.DIVERGED) == [False, False, False]
    torch.testing.assert_close(root[keys.BASE_POS], td["next", keys.BASE_POS])
    assert env.diverged_count == 1


# --------------------------------------------------------------------------- depth
BOX_AHEAD = 1.2  # m from the spawn point to the box face, along the trail (+x)


def test_depth_sees_box_ahead(make: EnvFactory) -> None:
    # Odd image sizes put a pixel centre on the optical axis: its depth is the ray length.
    cfg = config("h1", "flat", "env.depth.enabled=true", "env.depth.width=33",
                 "env.depth.height=25")
    tile = build_terrain_map(OmegaConf.to_object(cfg.trail), cfg.seed).tiles[0]
    face_x = tile.start[0] + BOX_AHEAD
    half = np.array([0.1, 2.0, 1.5])  # m: thin, wide and tall wall
    box = np.array([[face_x + half[0], tile.start[1], tile.start[2] + half[2], *half, 0.0]])
    scene = scene_of(cfg, box)
    env = make(2, cfg=cfg, scene=scene, spawn_noise=0.0)
    depth = env.reset()["obs", "depth"]  # (N, T, H, W), normalised
    centre = (depth[:, -1, 12, 16].numpy() + 0.5) * env.cfg.depth.far

    # Expected: the optical axis of the camera (posed by a forward pass of the same state)
    # meets the plane x = face_x.
    data = mujoco.MjData(scene.model)
    cam = scene.model.camera(CAMERA_NAME).id
    for i in range(env.num_envs):
        data.qpos[:] = env.sim.qpos[i]
        mujoco.mj_forward(scene.model, data)
        pos, axis = data.cam_xpos[cam], -data.cam_xmat[cam].reshape(3, 3)[:, 2]
        expected = (face_x - pos[0]) / axis[0]
        hit_z = pos[2] + expected * axis[2]
        assert 0.3 < expected < env.cfg.depth.far and hit_z > tile.start[2]  # on the wall
        assert centre[i] == pytest.approx(expected, abs=0.03)


def test_depth_backend_is_picked_by_key(make: EnvFactory,
                                        flat: tuple[DictConfig, Scene]) -> None:
    """env.depth.backend picks the camera; both see the same flat trail from the same poses.
    A bad value set from Python (no composition check) fails naming key, value, choices."""
    from legoh.envs.batched_sim import RaycastCamera
    from legoh.envs.heightmap_depth import HeightmapDepthCamera

    frames = {}
    for backend, kind in [("raymarch", HeightmapDepthCamera), ("multiray", RaycastCamera)]:
        cfg = config("h1", "flat", "env.depth.enabled=true", f"env.depth.backend={backend}")
        env = make(2, cfg=cfg, scene=flat[1])
        assert isinstance(env.depth_cam, kind)
        frames[backend] = env.reset()["obs", "depth"]
    torch.testing.assert_close(frames["raymarch"], frames["multiray"], atol=1e-4, rtol=0)
    env_cfg = OmegaConf.to_object(config("h1", "flat", "env.depth.enabled=true").env)
    env_cfg.depth.backend = "lidar"
    with pytest.raises(ValueError, match=r"env\.depth\.backend='lidar'.*'raymarch', 'multiray'"):
        make(2, cfg=config("h1", "flat"), scene=flat[1], depth=env_cfg.depth)


# --------------------------------------------------------------------------- curriculum
def levels_after(levels: list[int], covered: list[float], reached: list[bool],
                 num_levels: int = 5, seed: int = 0) -> np.ndarray:
    n = len(levels)
    return update_levels(torch.tensor(levels), torch.tensor(covered, dtype=torch.float64),
                         torch.full((n,), 100.0), torch.tensor(reached), num_levels,
                         torch.Generator().manual_seed(seed)).numpy()


def test_curriculum_up_down_stay() -> None:
    new = levels_after([2, 2, 2, 2, 2], [90.0, 60.0, 30.0, 80.0, 40.0], [False] * 5)
    np.testing.assert_array_equal(new, [3, 2, 1, 2, 2])  # > 80% up, < 40% down, else stay


def test_curriculum_reached_counts_as_up() -> None:
    np.testing.assert_array_equal(levels_after([1, 1], [5.0, 5.0], [True, False]), [2, 0])


def test_curriculum_bottom_level_stays() -> None:
    np.testing.assert_array_equal(levels_after([0], [0.0], [False]), [0])


def test_curriculum_past_top_goes_to_random_level() -> None:
    new = levels_after([4] * 200, [95.0] * 200, [False] * 200)
    assert new.min() >= 0 and new.max() <= 4
    assert len(np.unique(new)) > 1


def test_curriculum_zero_expected_distance() -> None:
    new = update_levels(torch.tensor([1]), torch.tensor([0.0]), torch.tensor([0.0]),
                        torch.tensor([False]), 5, torch.Generator().manual_seed(0))
    np.testing.assert_array_equal(new, [0])


def test_lagging_mix_sends_robots_to_the_category_that_lags() -> None:
    """Category 3's robots sit at level 0, the others at the top: with mix 1 an ended
    episode moves there with weight 5 against 1 each (5 / 9), and takes a level of its
    new category's robots; with mix 0 every robot keeps its category and level."""
    from legoh.envs.curriculum import lagging_categories

    n = 900
    category = torch.arange(n) % 5
    levels = torch.where(category == 3, 0, 4)
    ended = torch.arange(n)
    cat, lev = lagging_categories(category, levels, ended, 5, 5, 1.0,
                                  torch.Generator().manual_seed(0))
    share = float((cat == 3).float().mean())
    assert abs(share - 5 / 9) < 0.05, share
    np.testing.assert_array_equal(lev[cat == 3], 0)
    np.testing.assert_array_equal(lev[cat != 3], 4)
    same_cat, same_lev = lagging_categories(category, levels, ended, 5, 5, 0.0,
                                            torch.Generator().manual_seed(0))
    assert torch.equal(same_cat, category) and torch.equal(same_lev, levels)


def test_lagging_mix_moves_ended_episodes_only(make: EnvFactory) -> None:
    """The curriculum event: robots whose episode ran move between categories, robots
    reset before their first step (steps 0) keep theirs."""
    from legoh.config.env import CurriculumConfig
    from legoh.envs.mdp import events

    cfg = compose_config("trail=hike", "trail.levels=2", "trail.variants=1")
    env = make(60, cfg=cfg, scene=scene_of(cfg), curriculum=CurriculumConfig(lagging_mix=1.0))
    env.reset()
    before = env.category.clone()
    env.steps[:30] = 10
    env.steps[30:] = 0
    events.curriculum(env, torch.arange(60))
    assert torch.equal(env.category[30:], before[30:])
    assert (env.category[:30] != before[:30]).any()


def test_uniform_rule_draws_every_level_whatever_the_episode_did(make: EnvFactory) -> None:
    """``env.curriculum.rule=uniform`` (a student's): robots standing still at their spawn
    (covered 0: the distance rule keeps level 0) draw their next level over all levels."""
    from legoh.config.env import CurriculumConfig, LevelRule
    from legoh.envs.mdp import events

    cfg = compose_config("trail=randommix", "trail.levels=3", "trail.variants=1")
    scene = scene_of(cfg)
    seen = {}
    for rule in LevelRule:
        env = make(64, cfg=cfg, scene=scene, curriculum=CurriculumConfig(rule=rule))
        env.reset()
        env.level.zero_()
        env.steps.fill_(10)
        events.curriculum(env, torch.arange(64))
        seen[rule] = set(env.level.tolist())
    assert seen[LevelRule.distance] == {0}
    assert seen[LevelRule.uniform] == {0, 1, 2}


def test_depth_frames_are_reproducible() -> None:
    """Two envs, same seed, same actions: the same depth frames. Before each ray-casting
    thread got its own MjData (mj_multiRay allocates on it), frames of identical runs
    differed by up to 0.49 (normalised) on a shared one."""
    from legoh.envs.hiking_env import make_env

    cfg = compose_config("trail=flat", "env.depth.enabled=true")  # the full map: many chunks
    actions = torch.randn(30, 8, 10, generator=torch.Generator().manual_seed(0)) * 0.3
    frames = []
    for _ in range(2):
        env = make_env(cfg, num_envs=8, depth=OmegaConf.to_object(cfg.env.depth))
        try:
            td, out = env.reset(), []
            for t in range(len(actions)):
                td.set("action", actions[t])
                stepped, td = env.step_and_maybe_reset(td)
                out.append(stepped["next", "obs", "depth"].clone())
            frames.append(torch.stack(out))
        finally:
            env.close()
    assert torch.equal(frames[0], frames[1])


def test_make_env_refuses_unknown_settings() -> None:
    """A misspelled override to make_env is refused, naming it.

    Failed before with: DID NOT RAISE (setattr made a dead attribute; the env ran with 20 s)."""
    from legoh.envs.hiking_env import make_env

    with pytest.raises(TypeError, match=r"unknown env setting\(s\) \['epsiode_length_s'\]"):
        make_env(compose_config("trail=flat"), num_envs=1, epsiode_length_s=5.0)
