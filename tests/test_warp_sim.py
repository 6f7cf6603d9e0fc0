"""MuJoCo Warp backend (``WarpSim``) against the CPU physics, on Warp's CPU device.

Same scene, same start, same controls: ``mujoco.rollout`` (the CPU backend's engine) and
``WarpSim`` must agree within float32 (MuJoCo Warp computes in float32, MuJoCo in float64).
Four H1 worlds spawn 2 cm above the height-field ground of a RandomMix tile at different
places, drop and stand for 0.5 s. The device is Warp's CPU unless ``--warp-device`` (or
``LEGOH_WARP_DEVICE``) names another: ``experiments/gpu_check.sh`` runs these on CUDA.

The first run compiles MuJoCo Warp's kernels (2-3 min on 2 cores); they are cached
(``WARP_CACHE_PATH``, set in conftest.py), so later runs take seconds.
"""

from __future__ import annotations

import warnings

import mujoco
import numpy as np
import pytest
import torch
from mujoco import rollout
from omegaconf import OmegaConf

from legoh import keys
from legoh.envs.randomization import PhysicsDraw, build_model_pool
from legoh.envs.scene import Scene, build_scene
from legoh.envs.sensors import DepthRaycaster, camera_poses
from legoh.envs.terrain import build_terrain_map
from tests.conftest import compose_config

pytest.importorskip("mujoco_warp", reason="MuJoCo Warp not installed: pip install -e .[gpu]")
from legoh.envs.warp_sim import WarpSim  # noqa: E402

N, SUBSTEPS = 4, 4
STEPS = 25  # policy steps: 0.5 s at 50 Hz
STATE = mujoco.mjtState.mjSTATE_FULLPHYSICS
SENSOR_TOL = 1e-5  # sensors of one state: float32 against float64
FORCE_RTOL = 1e-5  # contact forces and torques: relative (they are hundreds of newtons)
HEIGHT_TOL = 1e-3  # m, base height after 0.5 s of contact dynamics
DEPTH_TOL = 1e-5  # m


@pytest.fixture(scope="module")
def device(request: pytest.FixtureRequest) -> str:
    return request.config.getoption("--warp-device")


def scene_of(robot: str) -> Scene:
    cfg = compose_config(f"robot={robot}", "trail=randommix", "trail.levels=1",
                         "trail.variants=1")
    terrain = build_terrain_map(OmegaConf.to_object(cfg.trail), cfg.seed)
    return build_scene(OmegaConf.to_object(cfg.robot), terrain, cfg.sim.dt)


@pytest.fixture(scope="module")
def scene() -> Scene:
    return scene_of("h1")


def nominal() -> PhysicsDraw:
    return PhysicsDraw(np.ones(1), np.zeros(1), np.zeros((1, 3)), np.ones(1))


def spawn(scene: Scene, n: int = N, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(qpos (n, nq), ctrl (n, nu)): default pose 2 cm above the ground near the tile start,
    each world at its own place and heading."""
    rng = np.random.default_rng(seed)
    tile = scene.terrain.tiles[0]
    qpos = np.tile(scene.model.qpos0, (n, 1))
    xy = tile.start[:2] + rng.uniform(-0.3, 0.3, (n, 2))  # on the start pad
    qpos[:, :2] = xy
    qpos[:, 2] = scene.terrain.height_at(xy) + scene.stand_height + 0.02
    yaw = rng.uniform(-0.5, 0.5, n)
    qpos[:, 3:7] = np.column_stack([np.cos(yaw / 2), 0 * yaw, 0 * yaw, np.sin(yaw / 2)])
    pose = np.tile(scene.robot.default_pose, (n, 1))
    qpos[:, scene.qpos_adr] = pose
    return qpos, pose


def cpu_forward(model: mujoco.MjModel, qpos: np.ndarray, ctrl: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """(full physics state (n, nstate), sensordata (n, ns)) of each row after mj_forward."""
    data = mujoco.MjData(model)
    states, sens = [], []
    for q, c in zip(qpos, ctrl, strict=True):
        mujoco.mj_resetData(model, data)
        data.qpos[:], data.ctrl[:] = q, c
        mujoco.mj_forward(model, data)
        state = np.empty(mujoco.mj_stateSize(model, STATE))
        mujoco.mj_getState(model, data, state, STATE)
        states.append(state)
        sens.append(data.sensordata.copy())
    return np.array(states), np.array(sens)


def cpu_rollout(models: list[mujoco.MjModel], qpos: np.ndarray, ctrl: np.ndarray,
                nstep: int) -> tuple[np.ndarray, np.ndarray]:
    """(state (n, nstep, nstate), sensordata (n, nstep, ns)) holding ``ctrl``."""
    state0 = np.array([cpu_forward(m, q[None], c[None])[0][0]
                       for m, q, c in zip(models, qpos, ctrl, strict=True)])
    control = np.repeat(ctrl[:, None], nstep, axis=1)
    datas = [mujoco.MjData(models[0])]
    return rollout.rollout(models, datas, state0, control, nstep=nstep)


def warp_run(sim: WarpSim, steps: int, ctrl: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(qpos (n, steps, nq), sensordata (n, steps * substeps, ns)) of ``steps`` policy steps."""
    qpos, sens = [], []
    for _ in range(steps):
        sim.step(torch.as_tensor(ctrl, dtype=torch.float32))
        qpos.append(sim.qpos.cpu().numpy().copy())
        sens.append(sim.sensordata.cpu().numpy().copy())
    return np.stack(qpos, 1), np.concatenate(sens, 1)


def contact_flags(scene: Scene, sens: np.ndarray) -> np.ndarray:
    """Feet 'found' counts (every 4th entry of their block) and unsafe-contact counts > 0."""
    sl = scene.sensors
    feet = sens[..., sl.feet_contact][..., ::4]
    return np.concatenate([feet, sens[..., sl.unsafe_found]], -1) > 0


def assert_sensors_close(scene: Scene, got: np.ndarray, want: np.ndarray) -> None:
    """The sensors of one state: positions and orientations within SENSOR_TOL, actuator
    torques within FORCE_RTOL of their scale, contact flags identical.

    Contact forces are not compared here: MuJoCo Warp's height-field collider makes fewer
    contact points per foot than MuJoCo's (4 vs up to 12, measured), so one forward pass
    shares the load differently; ``test_half_second_matches_rollout`` compares the settled
    load instead.
    """
    sl = scene.sensors
    kinematic = np.r_[sl.camera_pos, sl.camera_quat, sl.feet_pos]
    np.testing.assert_allclose(got[..., kinematic], want[..., kinematic], rtol=0,
                               atol=SENSOR_TOL)
    np.testing.assert_array_equal(contact_flags(scene, got), contact_flags(scene, want))
    torque = np.r_[sl.torques]
    scale = np.abs(want[..., torque]).max() + 1.0
    np.testing.assert_allclose(got[..., torque], want[..., torque], rtol=0,
                               atol=FORCE_RTOL * scale)


def feet_normal_force(scene: Scene, sens: np.ndarray) -> np.ndarray:
    """(...,) N: the feet's summed vertical contact force (per foot: found, net force xyz)."""
    feet = sens[..., scene.sensors.feet_contact]
    return feet[..., 3::4].sum(-1)


@pytest.fixture(scope="module")
def sim(scene: Scene, device: str):
    s = WarpSim(scene.model, scene.robot.base_body, nominal(), N, SUBSTEPS, device=device)
    yield s
    s.close()


def reset_all(sim: WarpSim, scene: Scene, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    qpos, ctrl = spawn(scene, seed=seed)
    ids = torch.arange(N)
    sim.reset_envs(ids, torch.as_tensor(qpos), torch.zeros(N, scene.model.nv),
                   torch.as_tensor(ctrl))
    return qpos, ctrl


# --------------------------------------------------------------------------- interface
def test_views_share_the_physics_state(sim: WarpSim, scene: Scene) -> None:
    assert sim.qpos.shape == (N, scene.model.nq) and sim.qvel.shape == (N, scene.model.nv)
    assert sim.sensordata.shape == (N, SUBSTEPS, scene.model.nsensordata)
    assert sim.time.shape == (N,) and sim.model_of_env.dtype == torch.int64
    assert sim.qpos.device == sim.device and sim.qpos.dtype == torch.float32
    reset_all(sim, scene)
    sim.qvel[1, 0:2] += torch.tensor([1.0, 0.0], device=sim.device)  # a push
    sim.step(torch.as_tensor(spawn(scene)[1], dtype=torch.float32))
    vx = sim.qvel[:, 0].cpu()
    assert vx[1] > 0.5 and vx[[0, 2, 3]].abs().max() < 0.2
    assert torch.allclose(sim.time.cpu(), torch.full((N,), SUBSTEPS * scene.model.opt.timestep))


# --------------------------------------------------------------------------- parity
def test_reset_sensors_match_mj_forward(sim: WarpSim, scene: Scene) -> None:
    qpos, ctrl = reset_all(sim, scene)
    _, want = cpu_forward(scene.model, qpos, ctrl)
    got = sim.sensordata.cpu().numpy()
    for s in range(SUBSTEPS):  # every substep slot holds the state's sensors
        assert_sensors_close(scene, got[:, s], want)
    np.testing.assert_allclose(sim.qpos.cpu().numpy(), qpos, atol=1e-6)
    assert (sim.time.cpu() == 0).all()


def test_g1_loads_and_matches_before_touchdown(device: str) -> None:
    """G1 on the same ground: the sensors of its reset state, then 0.06 s of falling, before
    its feet touch down (a 2 cm drop takes 0.064 s; after it the two engines' contacts are
    equivalent but not bitwise, see above, and the compliant kp 200 legs spread that)."""
    g1 = scene_of("g1")
    sim = WarpSim(g1.model, g1.robot.base_body, nominal(), N, SUBSTEPS, device=device)
    qpos, ctrl = reset_all(sim, g1)
    assert_sensors_close(g1, sim.sensordata[:, 0].cpu().numpy(),
                         cpu_forward(g1.model, qpos, ctrl)[1])
    state, _ = cpu_rollout([g1.model] * N, qpos, ctrl, 3 * SUBSTEPS)
    got_qpos, _ = warp_run(sim, 3, ctrl)
    np.testing.assert_allclose(got_qpos[:, -1, :3], state[:, -1, 1:4], atol=1e-4)
    sim.close()


def test_half_second_matches_rollout(sim: WarpSim, scene: Scene) -> None:
    """Sensors, base height and contact flags over 0.5 s of dropping and standing."""
    qpos, ctrl = reset_all(sim, scene)
    state, sens = cpu_rollout([scene.model] * N, qpos, ctrl, STEPS * SUBSTEPS)
    got_qpos, got_sens = warp_run(sim, STEPS, ctrl)
    want_qpos = state[:, SUBSTEPS - 1::SUBSTEPS, 1:1 + scene.model.nq]
    height_err = np.abs(got_qpos[..., 2] - want_qpos[..., 2]).max()
    assert height_err < HEIGHT_TOL, f"base height differs by {height_err * 1e3:.2f} mm"
    np.testing.assert_array_equal(contact_flags(scene, got_sens), contact_flags(scene, sens))
    # the first substep starts from the same state: the tight tolerance holds there
    assert_sensors_close(scene, got_sens[:, 0], sens[:, 0])
    assert contact_flags(scene, sens[:, -1])[:, :2].all(), "the feet should be standing"
    # the settled load: the same weight on the feet (within the solver's tolerance)
    np.testing.assert_allclose(feet_normal_force(scene, got_sens[:, -SUBSTEPS:]),
                               feet_normal_force(scene, sens[:, -SUBSTEPS:]), rtol=0.02)


def test_depth_matches_ray_caster(sim: WarpSim, scene: Scene) -> None:
    qpos, ctrl = spawn(scene)
    poses, mats = camera_poses(scene.model, qpos)
    # look down at the ground and ahead at the horizon too (misses clip to far)
    tilt = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], dtype=float)
    poses, mats = np.concatenate([poses, poses]), np.concatenate([mats, mats @ tilt])
    args = (87.0, 32, 24, 5.0)
    cpu = DepthRaycaster(scene.model, *args, threads=1)
    data = mujoco.MjData(scene.model)  # the world as the last robot's kinematics left it
    data.qpos[:] = qpos[-1]
    mujoco.mj_kinematics(scene.model, data)
    want = cpu.render(data, poses, mats)
    got = sim.make_depth_camera(*args).render(torch.as_tensor(poses), torch.as_tensor(mats))
    assert got.shape == (2 * N, 24, 32)
    assert (want < 5.0).mean() > 0.2, "the test should see the ground"
    np.testing.assert_allclose(got.cpu().numpy(), want, rtol=0, atol=DEPTH_TOL)


def test_raymarch_camera_on_the_backend_device(sim: WarpSim, scene: Scene) -> None:
    """env.depth.backend=raymarch on this backend: torch on the sim's device, the CPU ray
    caster's depths (tests/test_depth_raymarch.py holds the thresholds' measurements)."""
    qpos, _ = spawn(scene)
    poses, mats = camera_poses(scene.model, qpos)
    args = (87.0, 32, 24, 5.0)
    data = mujoco.MjData(scene.model)
    mujoco.mj_forward(scene.model, data)
    want = DepthRaycaster(scene.model, *args, threads=1).render(data, poses, mats)
    cam = sim.make_depth_camera(*args, backend="raymarch")
    got = cam.render(torch.as_tensor(poses, device=sim.device),
                     torch.as_tensor(mats, device=sim.device))
    assert got.device == sim.device and got.shape == (N, 24, 32)
    err = np.abs(got.cpu().numpy() - want)
    assert np.median(err) < 1e-4 and np.mean(err < 0.05) > 0.98


# --------------------------------------------------------------------------- resets
def test_masked_reset_leaves_other_worlds_alone(sim: WarpSim, scene: Scene) -> None:
    qpos, ctrl = reset_all(sim, scene)
    step = torch.as_tensor(ctrl, dtype=torch.float32)
    for _ in range(5):
        sim.step(step)
    before = (sim.qpos.clone(), sim.qvel.clone(), sim.time.clone(), sim.sensordata.clone())
    ids = torch.tensor([1, 3])
    new_qpos, new_ctrl = spawn(scene, seed=5)
    sim.reset_envs(ids, torch.as_tensor(new_qpos[ids]), torch.zeros(2, scene.model.nv),
                   torch.as_tensor(new_ctrl[ids]))
    keep = torch.tensor([0, 2])
    for old, new in zip(before, (sim.qpos, sim.qvel, sim.time, sim.sensordata), strict=True):
        assert torch.equal(old[keep], new[keep])
    assert (sim.time[ids] == 0).all()
    _, want = cpu_forward(scene.model, new_qpos[ids], new_ctrl[ids])
    for s in range(SUBSTEPS):
        assert_sensors_close(scene, sim.sensordata[ids, s].cpu().numpy(), want)
    # the kept worlds go on as if nothing happened: compare with a sim never reset
    ref = WarpSim(scene.model, scene.robot.base_body, nominal(), N, SUBSTEPS,
                  device=str(sim.wp_device))
    reset_all(ref, scene)
    for _ in range(6):
        ref.step(step)
    sim.step(step)
    np.testing.assert_allclose(sim.qpos[keep].cpu().numpy(), ref.qpos[keep].cpu().numpy(),
                               atol=1e-5)
    ref.close()


def test_nonfinite_state_is_reported(sim: WarpSim, scene: Scene) -> None:
    _, ctrl = reset_all(sim, scene)
    sim.qvel[2, 6] = float("nan")
    sim.step(torch.as_tensor(ctrl, dtype=torch.float32))
    bad = sim.nonfinite().cpu()
    assert bad.tolist() == [False, False, True, False]
    assert not torch.isfinite(sim.qpos[2]).all()  # the env's own check sees it too
    reset_all(sim, scene)
    assert not sim.nonfinite().any()


def test_contact_overflow_is_reported(scene: Scene, device: str) -> None:
    small = WarpSim(scene.model, scene.robot.base_body, nominal(), N, SUBSTEPS,
                    device=device, nconmax=1, njmax=8, overflow_check_every=1)
    _, ctrl = reset_all(small, scene)
    with pytest.warns(RuntimeWarning, match=r"overflow in 4/4 worlds .*nconmax 1 per world"):
        for _ in range(10):  # the feet land after about 5 steps
            small.step(torch.as_tensor(ctrl, dtype=torch.float32))
    assert small.overflow_events >= N
    # a reset clears MuJoCo Warp's flags; the next check still reports what came before it
    small.overflow_check_every = 0
    for _ in range(3):
        small.step(torch.as_tensor(ctrl, dtype=torch.float32))
    reset_all(small, scene)
    with pytest.warns(RuntimeWarning, match="overflow in 4/4 worlds"):
        assert small.check_overflow() == N
    assert small.check_overflow() == 0  # and counted once
    small.close()


# --------------------------------------------------------------------------- randomisation
def test_world_given_draw_k_matches_model_copy_k(scene: Scene, device: str) -> None:
    rng = np.random.default_rng(3)
    k = 4
    draws = PhysicsDraw(
        friction=np.r_[1.0, rng.uniform(0.3, 1.5, k - 1)],
        mass_offset=np.r_[0.0, rng.uniform(-1.0, 3.0, k - 1)],
        com_offset=np.r_[np.zeros((1, 3)), rng.uniform(-0.05, 0.05, (k - 1, 3))],
        motor_strength=np.r_[1.0, rng.uniform(0.8, 1.2, k - 1)])
    pool = build_model_pool(scene.model, scene.robot.base_body, draws)
    sim = WarpSim(scene.model, scene.robot.base_body, draws, N, SUBSTEPS, device=device)
    assert sim.num_draws == k
    given = torch.tensor([3, 1, 0, 2])
    sim.set_models(torch.arange(N), given)
    assert sim.model_of_env.cpu().tolist() == given.tolist()
    for name in ("geom_friction", "body_mass", "body_ipos", "body_subtreemass",
                 "actuator_gainprm", "actuator_biasprm", "body_invweight0", "dof_invweight0"):
        per_world = getattr(sim.m, name).numpy()
        want = np.array([getattr(pool[g], name) for g in given.tolist()])
        np.testing.assert_allclose(per_world, want.reshape(per_world.shape), rtol=1e-6,
                                   err_msg=name)
    qpos, ctrl = reset_all(sim, scene)
    steps = 10
    state, sens = cpu_rollout([pool[g] for g in given], qpos, ctrl, steps * SUBSTEPS)
    got_qpos, got_sens = warp_run(sim, steps, ctrl)
    want_qpos = state[:, SUBSTEPS - 1::SUBSTEPS, 1:1 + scene.model.nq]
    # touchdown on other frictions and masses diverges a little more than the nominal (1.2 mm)
    assert np.abs(got_qpos[..., 2] - want_qpos[..., 2]).max() < 2 * HEIGHT_TOL
    assert_sensors_close(scene, got_sens[:, 0], sens[:, 0])
    # and the draws matter: the nominal model would have given another state (any
    # coordinate: on sphere feet a draw's base height alone can differ by ~1e-6 m)
    nominal_state, _ = cpu_rollout([pool[0]] * N, qpos, ctrl, steps * SUBSTEPS)
    nq = scene.model.nq
    moved = np.abs(nominal_state[[0, 1, 3], -1, 1:1 + nq] - state[[0, 1, 3], -1, 1:1 + nq])
    assert moved.max(axis=1).min() > 1e-5
    sim.close()


# --------------------------------------------------------------------------- the env
def test_hiking_env_episode_on_both_backends(device: str) -> None:
    """One HikingEnv episode from the same seed on each backend: observations agree."""
    from legoh.envs.hiking_env import make_env

    overrides = ("robot=h1", "trail=randommix", "trail.levels=1", "trail.variants=1",
                 "env.randomization.enabled=false", "env.depth.enabled=false")
    runs = {}
    for backend in ("mujoco", "warp"):
        cfg = compose_config(*overrides, f"sim={backend}", f"sim.warp_device={device}")
        env = make_env(cfg, num_envs=N)
        hold = torch.zeros(env.action_spec.shape, device=env.device)  # the default pose
        steps, td = [], env.reset()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            for _ in range(25):
                td.set(keys.ACTION, hold)
                out, td = env.step_and_maybe_reset(td)
                steps.append(out.to("cpu"))
        runs[backend] = torch.stack(steps, dim=1)
        env.close()
    a, b = runs["mujoco"], runs["warp"]
    # measured over 25 steps (0.5 s), N H1s holding the default pose from the same spawn:
    # proprio within 0.017 (ang vel x 0.25; joints 0.004 rad), scandots 0.0014 m, the goal
    # inputs (metres to the terminus, yaw frame) 0.06 m
    for key, tol in [(("next", "obs", "proprio"), 0.03), (("next", "obs", "scandots"), 5e-3),
                     (("next", "obs", "goal"), 0.1)]:
        torch.testing.assert_close(b[key].float(), a[key].float(), atol=tol, rtol=0)
    assert torch.equal(a["next", "done"], b["next", "done"])
