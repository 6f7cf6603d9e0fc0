"""Robots built from config by MjSpec edits: structure, mass, standing, camera, options."""

import mujoco
import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from legoh.config import RobotConfig, SimConfig
from legoh.envs.robots import CAMERA_NAME, IMU_SENSORS, build_robot_spec, mjcf_path
from legoh.envs.sensors import DepthRaycaster
from legoh.stand import build_standing_scene, hold_default_pose
from tests.conftest import compose_config

ROBOTS = ["h1", "g1"]
EXPECTED_ACTIONS = {"h1": 10, "g1": 12}


def robot_cfg(name: str, *overrides: str) -> RobotConfig:
    return OmegaConf.to_object(compose_config(f"robot={name}", *overrides).robot)


@pytest.mark.parametrize("name", ROBOTS)
def test_compiles_with_legs_controlled(name: str) -> None:
    spec, info = build_robot_spec(robot_cfg(name))
    model = spec.compile()
    assert info.num_actions == EXPECTED_ACTIONS[name]
    assert model.nu == len(info.actuated_joints)
    assert all("hip" in j or "knee" in j or "ankle" in j for j in info.action_joints)
    for sensor in IMU_SENSORS:
        assert model.sensor(sensor).id >= 0
    assert model.camera(CAMERA_NAME).id >= 0
    for foot in info.feet_bodies:
        assert model.body(foot).id >= 0


@pytest.mark.parametrize("name", ROBOTS)
def test_joints_match_the_source_mjcf(name: str) -> None:
    cfg = robot_cfg(name)
    spec, info = build_robot_spec(cfg)
    model = spec.compile()
    source = mujoco.MjModel.from_xml_path(str(mjcf_path(cfg)))
    assert list(info.action_joints) == list(cfg.leg_joints)
    for i, joint in enumerate(info.actuated_joints):
        np.testing.assert_allclose(model.joint(joint).range, source.joint(joint).range)
        np.testing.assert_allclose(info.joint_range[i], source.joint(joint).range)
        assert model.actuator(i).trnid[0] == model.joint(joint).id  # actuator order = joints


@pytest.mark.parametrize("name", ROBOTS)
def test_total_mass_within_one_percent(name: str) -> None:
    cfg = robot_cfg(name)
    model = build_robot_spec(cfg)[0].compile()
    source = mujoco.MjModel.from_xml_path(str(mjcf_path(cfg)))
    assert model.body_subtreemass[0] == pytest.approx(source.body_subtreemass[0], rel=0.01)


@pytest.mark.parametrize("name", ROBOTS)
def test_visual_meshes_stripped_for_training_kept_for_rendering(name: str) -> None:
    train = build_robot_spec(robot_cfg(name))[0].compile()
    render = build_robot_spec(robot_cfg(name), render=True)[0].compile()
    assert render.ngeom > train.ngeom
    # Every training geom collides, and none is a mesh (colliders are fitted primitives).
    assert np.all(train.geom_contype | train.geom_conaffinity)
    assert not np.any(train.geom_type == mujoco.mjtGeom.mjGEOM_MESH)


@pytest.mark.parametrize("name", ROBOTS)
def test_shins_and_feet_have_colliders(name: str) -> None:
    cfg = robot_cfg(name)
    model = build_robot_spec(cfg)[0].compile()
    for body in [*cfg.feet_bodies, *cfg.knee_bodies]:
        assert np.sum(model.geom_bodyid == model.body(body).id) >= 1, body


@pytest.mark.parametrize("name", ROBOTS)
def test_upper_body_active_joins_the_action(name: str) -> None:
    cfg = robot_cfg(name, "robot.upper_body=active")
    _, info = build_robot_spec(cfg)
    assert info.num_actions == len(cfg.leg_joints) + len(cfg.upper_joints)


@pytest.mark.parametrize("name", ROBOTS)
def test_stands_five_seconds_under_pd(name: str) -> None:
    cfg = robot_cfg(name)
    model, data, info = build_standing_scene(cfg, SimConfig())
    heights = hold_default_pose(model, data, seconds=5.0)
    assert np.all(np.abs(heights - info.nominal_base_height) < 0.05), (heights.min(), heights.max())
    up = data.xmat[model.body(info.base_body).id].reshape(3, 3)[:, 2]
    assert up[2] > 0.95  # still upright, not merely high


@pytest.mark.parametrize("name", ROBOTS)
def test_camera_at_head_sees_floor_ahead(name: str) -> None:
    cfg = robot_cfg(name)
    model, data, info = build_standing_scene(cfg, SimConfig())
    cam_pos = data.cam_xpos[model.camera(CAMERA_NAME).id]
    assert cam_pos[2] > 0.75 * (info.nominal_base_height + 0.6 if name == "h1" else 1.2)
    forward = -data.cam_xmat[model.camera(CAMERA_NAME).id].reshape(3, 3)[:, 2]
    pitch = np.deg2rad(cfg.camera.pitch_deg)  # looks forward and down, by its pitch
    assert forward[0] == pytest.approx(np.cos(pitch), abs=0.05) and forward[2] < 0
    depth = DepthRaycaster(model, cfg.camera.fovy_deg, 32, 24, far=10.0).render_camera(
        data, CAMERA_NAME)
    assert np.all(np.isfinite(depth))
    rows = depth.mean(axis=1)
    assert rows[-1] < rows[len(rows) // 2] < 10.0  # floor: ranges shrink toward the bottom
    assert np.all(np.diff(rows) <= 1e-6)
    # A planar floor seen from height h: the bottom row's ray hits at the predicted depth.
    assert rows[-1] < 3.0 * cam_pos[2]


def test_custom_mjcf_path_is_used_and_a_missing_one_is_named(tmp_path) -> None:
    cfg = robot_cfg("h1")
    explicit = robot_cfg("h1", f"robot.mjcf={mjcf_path(cfg)}")
    assert build_robot_spec(explicit)[0].compile().nu == 19
    with pytest.raises(FileNotFoundError, match="nowhere.xml"):
        build_robot_spec(robot_cfg("h1", f"robot.mjcf={tmp_path / 'nowhere.xml'}"))


def test_mjcf_without_the_joints_is_refused(tmp_path) -> None:
    other = tmp_path / "other.xml"
    other.write_text("<mujoco><worldbody><body name='pelvis'><freejoint/>"
                     "<geom size='0.1'/></body></worldbody></mujoco>")
    with pytest.raises(ValueError, match="left_hip_yaw"):
        build_robot_spec(robot_cfg("h1", f"robot.mjcf={other}"))


def _feet_colliders(model: mujoco.MjModel, cfg: RobotConfig) -> list[np.ndarray]:
    """Per foot, the geom ids of its colliders."""
    return [np.flatnonzero((model.geom_bodyid == model.body(f).id) & (model.geom_contype > 0))
            for f in cfg.feet_bodies]


def _sole_bottom(model: mujoco.MjModel, geoms: np.ndarray) -> float:
    """Lowest point (m, foot frame) of a foot's colliders, as built (axis-aligned here)."""
    out = np.inf
    for g in geoms:
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, model.geom_quat[g])
        rot, size = rot.reshape(3, 3), model.geom_size[g]
        kind = model.geom_type[g]
        if kind == mujoco.mjtGeom.mjGEOM_SPHERE:
            reach = size[0]
        elif kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
            reach = size[0] + abs(rot[2, 2]) * size[1]
        else:
            reach = float(np.abs(rot[2]) @ size)
        out = min(out, model.geom_pos[g][2] - reach)
    return float(out)


@pytest.mark.parametrize("name", ROBOTS)
def test_sphere_feet_sit_at_the_soles_corners(name: str) -> None:
    """robot.feet_collider=spheres: four spheres per foot spanning the source colliders'
    sole (heel to toe, side to side), their bottoms on its lowest point; box: one box."""
    source_cfg = robot_cfg(name, "robot.feet_collider=source")
    source = build_robot_spec(source_cfg)[0].compile()
    spheres = build_robot_spec(robot_cfg(name, "robot.feet_collider=spheres"))[0].compile()
    box = build_robot_spec(robot_cfg(name, "robot.feet_collider=box"))[0].compile()
    for old, new, one in zip(_feet_colliders(source, source_cfg),
                             _feet_colliders(spheres, source_cfg),
                             _feet_colliders(box, source_cfg), strict=True):
        assert len(new) == 4 and np.all(spheres.geom_type[new] == mujoco.mjtGeom.mjGEOM_SPHERE)
        assert len(one) == 1 and box.geom_type[one[0]] == mujoco.mjtGeom.mjGEOM_BOX
        xy = spheres.geom_pos[new][:, :2]
        r = spheres.geom_size[new[0], 0]
        span = source.geom_pos[old][:, 0]
        assert xy[:, 0].min() - r <= span.min() and xy[:, 0].max() + r >= span.max()
        assert xy[:, 1].min() < 0 < xy[:, 1].max()  # both sides of the sole
        assert _sole_bottom(spheres, new) == pytest.approx(_sole_bottom(source, old), abs=1e-6)
        assert _sole_bottom(box, one) == pytest.approx(_sole_bottom(source, old), abs=1e-6)
        # friction and contact dimension are the source's (per-env friction lives there)
        np.testing.assert_allclose(spheres.geom_friction[new], source.geom_friction[old[:1]]
                                   .repeat(4, axis=0))
    # the rest of the body is untouched
    assert spheres.ngeom - 8 == source.ngeom - sum(map(len, _feet_colliders(source, source_cfg)))


@pytest.mark.parametrize(("name", "feet"), [("h1", "spheres"), ("h1", "box"), ("g1", "spheres")])
def test_new_feet_stand_and_carry_the_weight(name: str, feet: str) -> None:
    """On each feet collider the robot stands under PD and the feet's contact sensors (what
    feet_contact and the force terms read) carry its weight."""
    from legoh.config.compose import compose_config as compose
    from legoh.envs.hiking_env import make_env

    cfg = compose(f"robot={name}", "trail=flat", "trail.variants=1", "trail.levels=1",
                  f"robot.feet_collider={feet}")  # randomisation: its gate starts closed
    env = make_env(cfg, num_envs=1)
    td = env.reset()
    for _ in range(100):  # 2 s holding the default pose
        td["action"] = torch.zeros(1, env.num_actions)
        td = env.step(td)["next"]
    s = env.state
    weight = env.scene.model.body_subtreemass[1] * 9.81
    assert bool(s.feet_contact.all())
    assert float(s.feet_force[0, :, 2].abs().sum()) == pytest.approx(weight, rel=0.15)
    assert abs(float(s.base_height[0]) - env.robot.nominal_base_height) < 0.05
    env.close()
