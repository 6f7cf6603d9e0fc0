"""The simulated world: one robot on the whole terrain map, as one MjModel.

Every env steps its own MjData against the same model (robots never meet: each MjData holds
one robot), so a step costs the same whatever the size of the map. The terrain is a grid of
height-field chunks (see ``_add_terrain`` for why); hurdles, platforms and tree trunks are
static geoms of the world body.

Sensors are added so that everything the env reads after a batched step is in ``sensordata``
(camera pose, feet positions and contact forces, unsafe contacts, joint torques) and the step
never needs a per-env call into MuJoCo.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np

from legoh.config import RobotConfig
from legoh.envs.robots import (
    CAMERA_NAME,
    WORLD_CONAFFINITY,
    WORLD_CONTYPE,
    RobotInfo,
    build_robot_spec,
    set_options,
    standing_base_height,
)
from legoh.envs.terrain import TerrainMap

# Contact sensor data layout: "found" count, then the net force (3) in the contact frame.
_CONTACT_FOUND, _CONTACT_FORCE = 1, 2
_REDUCE_NETFORCE = 3


@dataclass(frozen=True)
class SensorSlices:
    """Where each quantity sits in ``sensordata`` (start, stop) per sensor group."""

    camera_pos: slice
    camera_quat: slice
    feet_pos: slice  # 3 per foot
    feet_contact: slice  # per foot: found, then net force xyz
    unsafe_found: slice  # per non-foot body: contacts found with the world
    torques: slice  # 1 per actuator, N m


@dataclass
class Scene:
    """A compiled world and what the env needs to know about it."""

    model: mujoco.MjModel
    robot: RobotInfo
    terrain: TerrainMap
    sensors: SensorSlices
    stand_height: float  # m: base height above the ground in the default pose
    qpos_adr: np.ndarray  # (nu,) qpos addresses of actuated joints
    dof_adr: np.ndarray  # (nu,) qvel addresses of actuated joints
    scan_heights: np.ndarray  # (nx, ny) ground with obstacle tops, for scandots


def _add_terrain(spec: mujoco.MjSpec, tm: TerrainMap, chunk: float) -> None:
    """The ground as square height-field chunks (MuJoCo rows run along y), plus obstacles.

    Why chunks: MuJoCo's ray-height-field test walks every cell of the rectangle the ray
    spans inside the field's bounding box, so one field over a whole trail map costs seconds
    per depth frame (measured: 4.4 s for 64 x 48 rays on RandomMix). Chunks of ``chunk``
    metres with their own height range keep each ray's rectangle small, and the ray cutoff
    skips distant chunks: about 5 ms per frame, whatever the size of the map. Neighbouring
    chunks share their border row, so the ground is continuous for contacts.
    """
    h = tm.heights.astype(np.float64)
    nx, ny = h.shape
    step = max(2, int(round(chunk / tm.resolution)))
    world = dict(contype=WORLD_CONTYPE, conaffinity=WORLD_CONAFFINITY, group=0)
    for i0 in range(0, nx - 1, step):
        for j0 in range(0, ny - 1, step):
            block = h[i0:i0 + step + 1, j0:j0 + step + 1]
            bx, by = block.shape
            low = float(block.min())
            elevation = max(float(block.max()) - low, 1e-3)
            name = f"terrain_{i0}_{j0}"
            rx, ry = (bx - 1) * tm.resolution / 2.0, (by - 1) * tm.resolution / 2.0
            field = spec.add_hfield(name=name, nrow=by, ncol=bx, size=[rx, ry, elevation, 0.5])
            field.userdata = ((block.T - low) / elevation).ravel().tolist()
            spec.worldbody.add_geom(
                name=name, type=mujoco.mjtGeom.mjGEOM_HFIELD, hfieldname=name,
                pos=[tm.origin[0] + i0 * tm.resolution + rx,
                     tm.origin[1] + j0 * tm.resolution + ry, low],
                rgba=[0.55, 0.5, 0.42, 1.0], **world,
            )
    for k, (x, y, z, hx, hy, hz, yaw) in enumerate(tm.boxes.astype(np.float64)):
        spec.worldbody.add_geom(
            name=f"box{k}", type=mujoco.mjtGeom.mjGEOM_BOX, pos=[x, y, z], size=[hx, hy, hz],
            quat=[np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)], rgba=[0.45, 0.35, 0.25, 1.0],
            **world,
        )
    for k, (x, y, z, r, hz) in enumerate(tm.cylinders.astype(np.float64)):
        spec.worldbody.add_geom(
            name=f"trunk{k}", type=mujoco.mjtGeom.mjGEOM_CYLINDER, pos=[x, y, z], size=[r, hz, 0],
            rgba=[0.35, 0.25, 0.15, 1.0], **world,
        )


def scan_height_grid(tm: TerrainMap, trees: bool = True) -> np.ndarray:
    """Ground heights raised to the top of every obstacle (``trees``: tree trunks too):
    what scandots measure."""
    grid = tm.heights.astype(np.float32).copy()
    nx, ny = grid.shape
    xs = tm.origin[0] + np.arange(nx) * tm.resolution
    ys = tm.origin[1] + np.arange(ny) * tm.resolution
    for x, y, z, hx, hy, hz, yaw in tm.boxes:
        reach = np.hypot(hx, hy)
        i0, i1 = np.searchsorted(xs, [x - reach, x + reach])
        j0, j1 = np.searchsorted(ys, [y - reach, y + reach])
        gx, gy = np.meshgrid(xs[i0:i1] - x, ys[j0:j1] - y, indexing="ij")
        c, s = np.cos(yaw), np.sin(yaw)
        inside = (np.abs(c * gx + s * gy) <= hx) & (np.abs(-s * gx + c * gy) <= hy)
        block = grid[i0:i1, j0:j1]
        block[inside] = np.maximum(block[inside], z + hz)
    for x, y, z, r, hz in (tm.cylinders if trees else []):
        i0, i1 = np.searchsorted(xs, [x - r, x + r])
        j0, j1 = np.searchsorted(ys, [y - r, y + r])
        gx, gy = np.meshgrid(xs[i0:i1] - x, ys[j0:j1] - y, indexing="ij")
        block = grid[i0:i1, j0:j1]
        inside = gx**2 + gy**2 <= r**2
        block[inside] = np.maximum(block[inside], z + hz)
    return grid


def _add_sensors(spec: mujoco.MjSpec, info: RobotInfo) -> list[str]:
    """Sensors in a fixed order; returns the non-foot bodies watched for unsafe contacts."""
    S, Obj = mujoco.mjtSensor, mujoco.mjtObj
    spec.add_sensor(name="camera_pos", type=S.mjSENS_FRAMEPOS, objtype=Obj.mjOBJ_CAMERA,
                    objname=CAMERA_NAME)
    spec.add_sensor(name="camera_quat", type=S.mjSENS_FRAMEQUAT, objtype=Obj.mjOBJ_CAMERA,
                    objname=CAMERA_NAME)
    for foot in info.feet_bodies:
        spec.add_sensor(name=f"{foot}_pos", type=S.mjSENS_FRAMEPOS, objtype=Obj.mjOBJ_XBODY,
                        objname=foot)
    for foot in info.feet_bodies:
        s = spec.add_sensor(name=f"{foot}_contact", type=S.mjSENS_CONTACT, objtype=Obj.mjOBJ_BODY,
                            objname=foot, reftype=Obj.mjOBJ_BODY, refname="world")
        s.intprm = [_CONTACT_FOUND | _CONTACT_FORCE, _REDUCE_NETFORCE, 1]
    unsafe = [b.name for b in spec.bodies
              if b.name and b.name not in info.feet_bodies and b.name != "world"]
    for body in unsafe:
        s = spec.add_sensor(name=f"{body}_touch", type=S.mjSENS_CONTACT, objtype=Obj.mjOBJ_BODY,
                            objname=body, reftype=Obj.mjOBJ_BODY, refname="world")
        s.intprm = [_CONTACT_FOUND, 0, 1]
    for joint in info.actuated_joints:
        spec.add_sensor(name=f"{joint}_torque", type=S.mjSENS_ACTUATORFRC,
                        objtype=Obj.mjOBJ_ACTUATOR, objname=joint)
    return unsafe


def _sensor_slices(model: mujoco.MjModel, info: RobotInfo, unsafe: list[str]) -> SensorSlices:
    """Read each group's place in sensordata off the compiled model (groups are contiguous)."""

    def span(names: list[str]) -> slice:
        first, last = model.sensor(names[0]), model.sensor(names[-1])
        return slice(int(first.adr[0]), int(last.adr[0] + last.dim[0]))

    return SensorSlices(
        camera_pos=span(["camera_pos"]),
        camera_quat=span(["camera_quat"]),
        feet_pos=span([f"{f}_pos" for f in info.feet_bodies]),
        feet_contact=span([f"{f}_contact" for f in info.feet_bodies]),
        unsafe_found=span([f"{b}_touch" for b in unsafe]),
        torques=span([f"{j}_torque" for j in info.actuated_joints]),
    )


def build_scene(robot_cfg: RobotConfig, terrain: TerrainMap, dt: float,
                render: bool = False, hfield_chunk: float = 4.0,
                decorate: Callable[[mujoco.MjSpec], None] | None = None) -> Scene:
    """Robot + terrain map + sensors, compiled once. ``render`` keeps the robot's visual
    meshes; ``decorate`` edits the spec last, before it is compiled (videos dress a
    scene of their own with it: ``legoh/video.py``)."""
    spec, info = build_robot_spec(robot_cfg, render=render)
    for geom in spec.geoms:
        if geom.contype:  # robot friction wins contact pairs: per-env friction lives there
            geom.priority = 1
    _add_terrain(spec, terrain, hfield_chunk)
    unsafe = _add_sensors(spec, info)
    set_options(spec, dt)
    spec.worldbody.add_light(pos=[0.0, 0.0, 30.0], dir=[0.0, 0.0, -1.0],
                             type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL)
    spec.visual.global_.offwidth, spec.visual.global_.offheight = 1280, 960
    if decorate is not None:
        decorate(spec)
    model = spec.compile()
    slices = _sensor_slices(model, info, unsafe)
    qpos_adr = np.array([model.jnt_qposadr[model.joint(j).id] for j in info.actuated_joints])
    dof_adr = np.array([model.jnt_dofadr[model.joint(j).id] for j in info.actuated_joints])
    return Scene(model=model, robot=info, terrain=terrain, sensors=slices,
                 stand_height=standing_base_height(model, info), qpos_adr=qpos_adr,
                 dof_adr=dof_adr, scan_heights=scan_height_grid(terrain))


def standing_pose(scene: Scene) -> mujoco.MjData:
    """An MjData of the robot standing in its default pose at the origin on flat ground
    (yaw 0), its kinematics computed: where the feet and their colliders are at rest."""
    model, d = scene.model, mujoco.MjData(scene.model)
    d.qpos[:] = model.qpos0
    d.qpos[0:3] = [0.0, 0.0, scene.stand_height]
    d.qpos[3:7] = [1.0, 0.0, 0.0, 0.0]
    d.qpos[scene.qpos_adr] = scene.robot.default_pose
    mujoco.mj_kinematics(model, d)
    return d


def feet_rest_height(scene: Scene) -> np.ndarray:
    """(F,) height of each foot body's origin above flat ground in the default pose: the
    zero of the swing-height terms' foot lift."""
    d = standing_pose(scene)
    return d.xpos[[scene.model.body(b).id for b in scene.robot.feet_bodies], 2].copy()
