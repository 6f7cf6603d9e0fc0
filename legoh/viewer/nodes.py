"""A rollout's viser scene nodes: the trail tiles, the robots and the trail's markers, and
the body poses they are moved to (``legoh.viewer.server`` plays them).

Node names (the tests read them back from viser's scene graph)::

    /terrain/tile_<k>/ground, box_<j>, trunk_<j>    the k-th distinct tile robots are on
    /robots/<body>                                  one batched mesh, one instance per robot
    /trail/tile_<k>/waypoints                       one instance per waypoint but the last
    /trail/tile_<k>/terminus/pole, flag
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
import viser
from omegaconf import DictConfig, OmegaConf

from legoh.play import Rollout
from legoh.video import (
    CAMERA_DISTANCE,
    CAMERA_ELEVATION,
    CAMERA_SIDE,
    FLAG,
    OBSTACLE,
    POLE_HEIGHT,
    ROBOT,
    TRUNK,
    WAYPOINT,
    WAYPOINT_LIFT,
    WAYPOINT_RADIUS,
)
from legoh.viewer.scene import body_meshes, body_poses, robot_model, tile_meshes

ROOTS = ("/terrain", "/robots", "/trail")  # removed and built anew for each rollout


def rgb255(rgb: tuple[float, float, float]) -> tuple[int, int, int]:
    """An rgb colour 0-1 as viser's 0-255 ints."""
    return tuple(int(round(255 * c)) for c in rgb)


@dataclass
class Replay:
    """One rollout ready to replay: the world poses of every drawn body, every step."""

    cfg: DictConfig
    rollout: Rollout
    names: list[str]  # robot bodies drawn (those with a mesh)
    meshes: list[trimesh.Trimesh]  # each one's mesh, body frame
    pos: np.ndarray  # (T+1, N, B, 3) world positions, m
    quat: np.ndarray  # (T+1, N, B, 4) world orientations, wxyz
    tiles: list[int]  # distinct tiles the robots hike, indices into the terrain map
    tile_of: np.ndarray  # (N,) each robot's position in ``tiles``

    def step_of(self, frame: int) -> np.ndarray:
        """(N,) the step each robot shows at ``frame``: frozen where its episode ended."""
        return np.minimum(frame, self.rollout.end)

    def default_view(self, robot: int, step: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """(look-at, camera position) of the video's view of ``robot`` at ``step``: from
        behind and beside it along the trail (+x), looking down ``CAMERA_ELEVATION``."""
        base = self.pos[step, robot, 0]
        distance = CAMERA_DISTANCE * self.rollout.base_height
        az, el = np.radians(CAMERA_SIDE), np.radians(-CAMERA_ELEVATION)
        offset = distance * np.array([-np.cos(el) * np.cos(az), -np.cos(el) * np.sin(az),
                                      np.sin(el)])
        return base, base + offset


def prepare(cfg: DictConfig, rollout: Rollout) -> Replay:
    """Body meshes' poses for every step of ``rollout`` (``mj_kinematics`` of its qpos)."""
    model = robot_model(OmegaConf.to_object(cfg.robot))
    meshes = body_meshes(model)
    pos, quat = body_poses(model, rollout.qpos, list(meshes))
    index = [next(k for k, t in enumerate(rollout.terrain.tiles) if t is tile)
             for tile in rollout.tiles]
    tiles = list(dict.fromkeys(index))
    return Replay(cfg, rollout, [model.body(b).name for b in meshes], list(meshes.values()),
                  pos, quat, tiles, np.array([tiles.index(t) for t in index]))


def add_nodes(scene: viser.SceneApi, replay: Replay) -> dict[str, viser.SceneNodeHandle]:
    """Every node of ``replay`` (as at its first step), by name."""
    return {**_terrain(scene, replay), **_robots(scene, replay), **_trail(scene, replay)}


def _terrain(scene: viser.SceneApi, replay: Replay) -> dict[str, viser.SceneNodeHandle]:
    nodes, terrain = {}, replay.rollout.terrain
    for k, t in enumerate(replay.tiles):
        meshes, root = tile_meshes(terrain, terrain.tiles[t]), f"/terrain/tile_{k}"
        nodes[f"{root}/ground"] = scene.add_mesh_trimesh(f"{root}/ground", meshes.ground)
        for j, box in enumerate(meshes.boxes):
            nodes[f"{root}/box_{j}"] = scene.add_mesh_simple(
                f"{root}/box_{j}", box.vertices, box.faces, color=rgb255(OBSTACLE),
                flat_shading=True)
        for j, trunk in enumerate(meshes.trunks):
            nodes[f"{root}/trunk_{j}"] = scene.add_mesh_simple(
                f"{root}/trunk_{j}", trunk.vertices, trunk.faces, color=rgb255(TRUNK))
    return nodes


def _robots(scene: viser.SceneApi, replay: Replay) -> dict[str, viser.SceneNodeHandle]:
    n, nodes = replay.pos.shape[1], {}
    for b, (body, mesh) in enumerate(zip(replay.names, replay.meshes, strict=True)):
        name = f"/robots/{body}"
        nodes[name] = scene.add_batched_meshes_simple(
            name, mesh.vertices, mesh.faces, batched_wxyzs=replay.quat[0, :, b],
            batched_positions=replay.pos[0, :, b],
            batched_colors=np.tile(rgb255(ROBOT), (n, 1)), lod="off")
    return nodes


def _trail(scene: viser.SceneApi, replay: Replay) -> dict[str, viser.SceneNodeHandle]:
    nodes, terrain = {}, replay.rollout.terrain
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=WAYPOINT_RADIUS)
    for k, t in enumerate(replay.tiles):
        tile, root = terrain.tiles[t], f"/trail/tile_{k}"
        points = tile.waypoints[:-1] + [0.0, 0.0, WAYPOINT_LIFT]  # the last: the terminus
        nodes[f"{root}/waypoints"] = scene.add_batched_meshes_simple(
            f"{root}/waypoints", sphere.vertices, sphere.faces,
            batched_wxyzs=np.tile([1.0, 0.0, 0.0, 0.0], (len(points), 1)),
            batched_positions=points,
            batched_colors=np.tile(rgb255(WAYPOINT), (len(points), 1)), lod="off")
        end = tile.terminus
        nodes[f"{root}/terminus/pole"] = scene.add_cylinder(
            f"{root}/terminus/pole", radius=0.03, height=POLE_HEIGHT,
            position=end + [0.0, 0.0, POLE_HEIGHT / 2.0], color=(240, 240, 240))
        nodes[f"{root}/terminus/flag"] = scene.add_box(  # faces the trail, as the video's
            f"{root}/terminus/flag", dimensions=(0.024, 0.6, 0.4),
            position=end + [0.0, 0.3, POLE_HEIGHT - 0.2], color=rgb255(FLAG))
    return nodes
