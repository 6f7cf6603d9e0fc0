"""What the web viewer draws, as plain meshes and arrays (no viser here): the robot's body
meshes and their world poses at every recorded step, and the trail tiles' ground and
obstacles.

The robot is the env's own MJCF edit (``build_robot_spec`` with its visual meshes,
coarsened as the video does), compiled alone: its ``qpos`` layout is the scene's, so the
env's recorded poses replay on it through ``mj_kinematics``. The ground is the terrain
map's height field cut to each tile (``legoh.envs.terrain.export``), at the video's
reduced resolution.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
import trimesh

from legoh.config import RobotConfig
from legoh.envs.robots import ROBOT_GEOM_GROUP, build_robot_spec
from legoh.envs.terrain import TerrainMap
from legoh.envs.terrain.export import (
    heightfield_mesh,
    obstacle_meshes,
    tile_obstacles,
    tile_window,
)
from legoh.envs.terrain.terrain_map import Tile
from legoh.video import GRID_CELL, GROUND, GROUND_ALT, MESH_CELL, TERRAIN_STRIDE, coarsen_mesh

TILE_MARGIN = 2.0  # m of the border around each tile drawn (the tiles' borders are 4 m)


def robot_model(robot: RobotConfig) -> mujoco.MjModel:
    """The robot alone, visual meshes kept and coarsened (``MESH_CELL``: H1 286k -> 23k
    faces, light enough for a browser's software WebGL)."""
    spec, _ = build_robot_spec(robot, render=True)
    for mesh in spec.meshes:
        coarsen_mesh(spec, mesh, MESH_CELL)
    return spec.compile()


def _geom_mesh(model: mujoco.MjModel, g: int) -> trimesh.Trimesh | None:
    """Geom ``g`` as a mesh in its own frame (meshes and primitives; None for others)."""
    size, kind = model.geom_size[g], model.geom_type[g]
    if kind == mujoco.mjtGeom.mjGEOM_MESH:
        m = model.geom_dataid[g]
        v0, nv = model.mesh_vertadr[m], model.mesh_vertnum[m]
        f0, nf = model.mesh_faceadr[m], model.mesh_facenum[m]
        return trimesh.Trimesh(model.mesh_vert[v0:v0 + nv], model.mesh_face[f0:f0 + nf],
                               process=False)
    if kind == mujoco.mjtGeom.mjGEOM_SPHERE:
        return trimesh.creation.icosphere(subdivisions=2, radius=size[0])
    if kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
        return trimesh.creation.capsule(height=2 * size[1], radius=size[0], count=[8, 8])
    if kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
        return trimesh.creation.cylinder(radius=size[0], height=2 * size[1], sections=12)
    if kind == mujoco.mjtGeom.mjGEOM_BOX:
        return trimesh.creation.box(extents=2 * size)
    return None


def body_meshes(model: mujoco.MjModel) -> dict[int, trimesh.Trimesh]:
    """Body id -> its visual geoms merged into one mesh in the body's frame (its colliders
    where it has no visual geom at all, as the video does)."""
    robot = model.geom_bodyid != 0
    visual = robot & (model.geom_group != ROBOT_GEOM_GROUP)
    shown = np.flatnonzero(visual if visual.any() else robot)
    parts: dict[int, list[trimesh.Trimesh]] = {}
    for g in shown:
        mesh = _geom_mesh(model, g)
        if mesh is None:
            continue
        pose = trimesh.transformations.quaternion_matrix(model.geom_quat[g])  # wxyz
        pose[:3, 3] = model.geom_pos[g]
        mesh.apply_transform(pose)
        parts.setdefault(int(model.geom_bodyid[g]), []).append(mesh)
    return {b: trimesh.util.concatenate(p) for b, p in sorted(parts.items())}


def body_poses(model: mujoco.MjModel, qpos: np.ndarray, bodies: list[int]
               ) -> tuple[np.ndarray, np.ndarray]:
    """World positions (T, N, B, 3) and orientations (T, N, B, 4, wxyz) of ``bodies`` for
    the generalised positions ``qpos`` (T, N, nq) of N robots over T steps."""
    if qpos.shape[-1] != model.nq:
        raise ValueError(f"qpos has {qpos.shape[-1]} entries per robot but the robot model "
                         f"has nq={model.nq}: the rollout was recorded with another robot")
    data = mujoco.MjData(model)
    flat = qpos.reshape(-1, model.nq)
    pos = np.empty((len(flat), len(bodies), 3))
    quat = np.empty((len(flat), len(bodies), 4))
    for k, q in enumerate(flat):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)  # positions only: no contacts needed
        pos[k], quat[k] = data.xpos[bodies], data.xquat[bodies]
    return (pos.reshape(*qpos.shape[:2], len(bodies), 3),
            quat.reshape(*qpos.shape[:2], len(bodies), 4))


@dataclass
class TileMeshes:
    """One trail tile's world-frame meshes: the ground (vertex-coloured checker of
    ``GRID_CELL`` squares, as the video's), boxes (hurdles, steps) and tree trunks."""

    ground: trimesh.Trimesh
    boxes: list[trimesh.Trimesh]
    trunks: list[trimesh.Trimesh]


def tile_meshes(terrain: TerrainMap, tile: Tile, margin: float = TILE_MARGIN,
                stride: int = TERRAIN_STRIDE) -> TileMeshes:
    """``tile`` and ``margin`` m around it, its height field keeping every ``stride``-th
    sample (0.05 -> 0.1 m by default: a quarter of the triangles)."""
    si, sj = tile_window(terrain, tile, margin)
    origin = terrain.origin + np.array([si.start, sj.start]) * terrain.resolution
    ground = heightfield_mesh(terrain.heights[si, sj][::stride, ::stride],
                              terrain.resolution * stride, origin)
    cell = np.floor(ground.vertices[:, :2] / GRID_CELL).astype(int).sum(axis=1) % 2
    rgb = np.where(cell[:, None] == 0, GROUND, GROUND_ALT)
    ground.visual.vertex_colors = np.c_[(rgb * 255).astype(np.uint8),
                                        np.full(len(rgb), 255, np.uint8)]
    boxes, cylinders = tile_obstacles(terrain, tile, margin)
    return TileMeshes(ground, obstacle_meshes(boxes, cylinders[:0]),
                      obstacle_meshes(boxes[:0], cylinders))
