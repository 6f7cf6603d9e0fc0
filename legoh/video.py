"""Videos of a hike: a camera that follows the robot through a dressed scene of its own, the
expert trail drawn into it, the student's depth view beside it, a caption burnt into each
frame, and the MP4 / filmstrip writers (``mode=play`` and the experiments' videos use it
through ``legoh.play.render_policy_video``).

The env's model is never touched: :func:`render_model` compiles a sibling of it from the
same robot config and terrain map (same ``qpos`` layout, so the env's poses replay on it)
with the robot's visual meshes, a sky, a gridded ground, coloured obstacles and a sun that
follows the robot and casts shadows.

Software EGL (llvmpipe) draws every triangle it is given, twice with shadows (once into the
shadow map): the camera hides world geoms farther than ``VIEW_RADIUS`` from the robot and
fog fades the ground into the horizon before that edge; the shadow map is small and covers
only ``SHADOW_BOX`` around the robot. docs/oracle.md ("Watching a policy") gives the
measured cost of a frame.
"""

from __future__ import annotations

import os
import sys

if sys.platform.startswith("linux"):  # headless; must precede mujoco's first import
    os.environ.setdefault("MUJOCO_GL", "egl")

import dataclasses  # noqa: E402
import importlib.util  # noqa: E402
from functools import partial  # noqa: E402
from pathlib import Path  # noqa: E402

import imageio.v2 as imageio  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402
import trimesh  # noqa: E402
from PIL import Image, ImageDraw, ImageFont  # noqa: E402

from legoh.config import RobotConfig  # noqa: E402
from legoh.envs.robots import ROBOT_GEOM_GROUP  # noqa: E402
from legoh.envs.scene import build_scene  # noqa: E402
from legoh.envs.terrain import TerrainMap  # noqa: E402
from legoh.envs.terrain.terrain_map import Tile  # noqa: E402

WIDTH, HEIGHT = 640, 480  # px, the main view
PANEL_WIDTH = 320  # px, the depth view's column beside the main view (students)
FILMSTRIP_FRAMES = 8
# x264's constant rate factor: imageio's quality=7 meant crf 15, which wrote the 192 s hill
# film at 26 MB; at 30 it was 3.9 MB with the robot and the terrain as legible
VIDEO_CRF = 30

# Camera: a 3/4 view from behind the robot and to its side, looking along the trail
CAMERA_DISTANCE = 4.0  # x the robot's nominal base height, m
CAMERA_ELEVATION = -26.0  # deg, from above
CAMERA_SIDE = 25.0  # deg the camera swings off the trail's heading
LOOK_AHEAD = 1.2  # m along the trail ahead of the robot the camera looks at
TRAIL_AHEAD = 2.5  # m along the trail that set its heading at the robot
SMOOTHING = 0.15  # share of the gap to its target the camera closes each frame

# What is drawn and how much it costs (software EGL: per triangle, twice with shadows)
VIEW_RADIUS = 12.0  # m: world geoms farther from the robot are not drawn
BEHIND = 5.0  # m: nor those whose centre is farther than this behind it (out of view)
TERRAIN_STRIDE = 2  # the video's ground keeps every 2nd height sample (0.05 -> 0.1 m)
MESH_CELL = 0.012  # m: the robot's meshes merged to one vertex per cell (H1: 286k -> 23k faces)
HIDDEN_GROUP = 5  # geom group the far world geoms are moved to (not drawn)
SEE_THROUGH = 0.25  # alpha of a tree trunk standing between the camera and the robot
FOG_START = 5.0  # m from the camera: the ground fades into the horizon from here
SHADOW_SIZE = 1024  # px, the shadow map's side (MuJoCo's default 4096 costs ~3x a frame)
SHADOW_BOX = 9.0  # m: half the side of the square around the robot where shadows fall
SUN = (0.1, -0.7, 1.0)  # direction the sunlight comes from (x, y, z), normalised below

# Colours (rgb, 0-1)
SKY_TOP, SKY_HORIZON = (0.35, 0.55, 0.85), (0.86, 0.91, 0.96)
GROUND, GROUND_ALT, GRID = (0.70, 0.64, 0.52), (0.62, 0.56, 0.45), (0.42, 0.38, 0.31)
GRID_CELL = 1.0  # m: the ground's checker squares
OBSTACLE = (0.92, 0.48, 0.16)  # hurdles, steps and platforms (boxes)
TRUNK = (0.38, 0.24, 0.12)  # tree trunks (cylinders)
ROBOT = (0.36, 0.38, 0.43)  # the robot's meshes: dark enough to stand out, light enough to shade
WAYPOINT, NEXT_WAYPOINT, PASSED = (0.10, 0.75, 0.95), (1.0, 0.85, 0.1), (0.55, 0.55, 0.55)
FLAG = (0.9, 0.1, 0.1)
WAYPOINT_RADIUS = 0.09  # m
WAYPOINT_LIFT = 0.25  # m above the ground, so hurdles and steps do not hide them
POLE_HEIGHT = 1.6  # m, the terminus's flagpole
DEPTH_COLORMAP = "viridis_r"  # near bright, far dark: as the mode=stand picture
CAPTION_SIZE = 17  # px, the caption's font


def dress(spec: mujoco.MjSpec, base_body: str) -> None:
    """Give a scene spec its video look (``build_scene``'s ``decorate``): sky, gridded
    ground, coloured obstacles, the robot's visual meshes shown and its colliders hidden,
    a sun on the robot's base (it tracks its centre of mass, so its shadow box follows)."""
    for mesh in spec.meshes:
        coarsen_mesh(spec, mesh, MESH_CELL)
    spec.add_texture(name="sky", type=mujoco.mjtTexture.mjTEXTURE_SKYBOX,
                     builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT, rgb1=SKY_TOP,
                     rgb2=SKY_HORIZON, width=256, height=1536)
    spec.add_texture(name="ground", type=mujoco.mjtTexture.mjTEXTURE_2D,
                     builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER, mark=mujoco.mjtMark.mjMARK_EDGE,
                     rgb1=GROUND, rgb2=GROUND_ALT, markrgb=GRID, width=128, height=128)
    ground = spec.add_material(name="ground", texuniform=True, specular=0.1,
                               texrepeat=[0.5 / GRID_CELL, 0.5 / GRID_CELL])
    ground.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "ground"
    for geom in spec.geoms:
        if geom.parent.name != "world":
            if geom.group != ROBOT_GEOM_GROUP:  # its colliders are hidden by the camera
                geom.material, geom.rgba = "", [*ROBOT, 1.0]
            continue
        if geom.type == mujoco.mjtGeom.mjGEOM_HFIELD:
            geom.material, geom.rgba = "ground", [1.0, 1.0, 1.0, 1.0]
        elif geom.type == mujoco.mjtGeom.mjGEOM_BOX:
            geom.material, geom.rgba = "ground", [*OBSTACLE, 1.0]
        elif geom.type == mujoco.mjtGeom.mjGEOM_CYLINDER:
            geom.rgba = [*TRUNK, 1.0]
    for light in spec.lights:  # build_scene's light from straight above: a soft fill
        light.castshadow, light.diffuse = False, [0.25, 0.25, 0.25]
    sun = np.asarray(SUN) / np.linalg.norm(SUN)
    spec.body(base_body).add_light(
        name="sun", type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL, castshadow=True,
        mode=mujoco.mjtCamLight.mjCAMLIGHT_TRACKCOM, pos=(20.0 * sun).tolist(),
        dir=(-sun).tolist(), diffuse=[0.75, 0.72, 0.66], specular=[0.1, 0.1, 0.1])
    spec.visual.headlight.ambient = [0.35, 0.35, 0.38]
    spec.visual.headlight.diffuse = [0.25, 0.25, 0.25]
    spec.visual.headlight.specular = [0.0, 0.0, 0.0]
    spec.visual.quality.shadowsize = SHADOW_SIZE
    spec.visual.rgba.fog = [*SKY_HORIZON, 1.0]


def render_model(robot: RobotConfig, terrain: TerrainMap, dt: float, hfield_chunk: float
                 ) -> mujoco.MjModel:
    """The env's scene (same robot config, terrain map and chunks) dressed for video and
    compiled anew: a model of the video's own, never the env's. Its ground is the map at
    half the resolution and its robot meshes are coarsened (``TERRAIN_STRIDE``,
    ``MESH_CELL``): a quarter and a twelfth of the triangles, not visible at 640 x 480."""
    h = terrain.heights[::TERRAIN_STRIDE, ::TERRAIN_STRIDE]
    terrain = dataclasses.replace(terrain, heights=h,
                                  resolution=terrain.resolution * TERRAIN_STRIDE)
    model = build_scene(robot, terrain, dt, render=True, hfield_chunk=hfield_chunk,
                        decorate=partial(dress, base_body=robot.base_body)).model
    extent = model.stat.extent  # the map's size: MuJoCo scales these distances by it
    model.vis.map.shadowclip = SHADOW_BOX / extent
    model.vis.map.fogstart, model.vis.map.fogend = FOG_START / extent, VIEW_RADIUS / extent
    return model


def coarsen_mesh(spec: mujoco.MjSpec, mesh: mujoco.MjsMesh, cell: float) -> None:
    """Replace a file mesh of ``spec`` by its vertex clustering: vertices within one
    ``cell`` (m) merged to their mean, the faces that collapse dropped."""
    if not mesh.file:
        return
    source = trimesh.load(os.path.join(spec.modelfiledir, spec.meshdir, mesh.file),
                          force="mesh", process=False)
    vertices, faces = np.asarray(source.vertices), np.asarray(source.faces)
    cells = np.floor(vertices * np.asarray(mesh.scale) / cell).astype(np.int64)
    _, merged = np.unique(cells, axis=0, return_inverse=True)
    merged = merged.ravel()
    count = np.bincount(merged)
    points = np.zeros((len(count), 3))
    np.add.at(points, merged, vertices)
    faces = merged[faces]
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2])
                  & (faces[:, 0] != faces[:, 2])]
    _, first = np.unique(np.sort(faces, axis=1), axis=0, return_index=True)
    mesh.file = ""
    mesh.uservert = (points / count[:, None]).ravel().tolist()
    mesh.userface = faces[np.sort(first)].ravel().tolist()
    mesh.inertia = mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL  # a thin part stays valid


def _trail_heading(points: np.ndarray, xy: np.ndarray, ahead: float) -> float:
    """Heading (rad) of the polyline ``points`` (K, 2) at ``xy``: of the chord from the
    point nearest ``xy`` to the point ``ahead`` m further along (clamped at the end), so
    a bend ahead turns it early and a robot beside the trail does not."""
    seg = np.diff(points, axis=0)
    length = np.maximum(np.linalg.norm(seg, axis=1), 1e-9)
    t = np.clip(np.einsum("ij,ij->i", xy - points[:-1], seg) / length**2, 0.0, 1.0)
    nearest = np.argmin(np.linalg.norm(points[:-1] + t[:, None] * seg - xy, axis=1))
    cum = np.concatenate([[0.0], np.cumsum(length)])
    here = cum[nearest] + t[nearest] * length[nearest]
    s = np.array([here, min(here + ahead, cum[-1])])
    k = np.minimum(np.searchsorted(cum, s, side="right") - 1, len(seg) - 1)
    a, b = points[k] + ((s - cum[k]) / length[k])[:, None] * seg[k]
    d = b - a if np.linalg.norm(b - a) > 1e-6 else seg[-1]  # at the end: the last leg's
    return float(np.arctan2(d[1], d[0]))


def _wrap(angle: float) -> float:
    return float((angle + np.pi) % (2.0 * np.pi) - np.pi)


class FollowCamera:
    """Films one robot hiking one trail tile on a :func:`render_model` (the camera owns it
    and edits it: far world geoms are hidden each frame).

    A free camera from behind the robot and to its side, aimed a little ahead of it along
    the trail; the aim and the heading are smoothed across frames, so call :meth:`frame`
    in time order. Each frame also draws the tile's expert waypoints (passed ones grey, the
    robot's current goal yellow) and a flag on its terminus.
    """

    def __init__(self, model: mujoco.MjModel, base_body: str, tile: Tile,
                 base_height: float, width: int = WIDTH, height: int = HEIGHT) -> None:
        self.model, self.data = model, mujoco.MjData(model)
        self.base = model.body(base_body).id
        self.trail = np.vstack([tile.start[:2], tile.waypoints[:, :2]])
        self.waypoints = tile.waypoints.astype(np.float64)
        self.world = np.flatnonzero((model.geom_bodyid == 0)
                                    & (model.geom_type != mujoco.mjtGeom.mjGEOM_PLANE))
        self.groups = model.geom_group[self.world].copy()
        self.trunks = self.world[model.geom_type[self.world] == mujoco.mjtGeom.mjGEOM_CYLINDER]
        self.renderer = mujoco.Renderer(model, height=height, width=width)
        self.renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = True
        self.renderer.scene.flags[mujoco.mjtRndFlag.mjRND_FOG] = True
        self.option = mujoco.MjvOption()
        self.option.geomgroup[:] = 1
        robot = model.geom_bodyid != 0
        if np.any(robot & (model.geom_group != ROBOT_GEOM_GROUP)):
            self.option.geomgroup[ROBOT_GEOM_GROUP] = 0  # visual meshes shown instead
        self.option.geomgroup[HIDDEN_GROUP] = 0
        self.option.sitegroup[:] = 0
        self.cam = mujoco.MjvCamera()
        self.cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        self.cam.elevation = CAMERA_ELEVATION
        self.cam.distance = CAMERA_DISTANCE * base_height
        self.heading: float | None = None  # rad, smoothed; None until the first frame
        self.aim = np.zeros(3)

    def frame(self, qpos: np.ndarray, goal: int = 0) -> np.ndarray:
        """(height, width, 3) uint8 of the robot in pose ``qpos`` (nq,); ``goal``: index of
        the robot's current expert waypoint (the env's ``info/waypoint``)."""
        self.data.qpos[:] = qpos
        mujoco.mj_kinematics(self.model, self.data)  # positions only: no contacts needed
        mujoco.mj_comPos(self.model, self.data)  # the sun tracks the subtree's CoM
        mujoco.mj_camlight(self.model, self.data)
        base = self.data.xpos[self.base]
        heading = _trail_heading(self.trail, base[:2], TRAIL_AHEAD)
        aim = np.array([*(base[:2] + LOOK_AHEAD * np.array([np.cos(heading),
                                                              np.sin(heading)])), base[2]])
        if self.heading is None:
            self.heading, self.aim = heading, aim
        else:
            self.heading += SMOOTHING * _wrap(heading - self.heading)
            self.aim += SMOOTHING * (aim - self.aim)
        self.cam.azimuth = float(np.degrees(self.heading)) + CAMERA_SIDE
        self.cam.lookat[:] = self.aim
        offset = self.model.geom_pos[self.world, :2] - base[:2]
        behind = -offset @ np.array([np.cos(self.heading), np.sin(self.heading)])
        hide = (np.linalg.norm(offset, axis=1) > VIEW_RADIUS) | (behind > BEHIND)
        self.model.geom_group[self.world] = np.where(hide, HIDDEN_GROUP, self.groups)
        self._see_through(base)
        self.renderer.update_scene(self.data, camera=self.cam, scene_option=self.option)
        self._draw_trail(self.renderer.scene, base, goal)
        return self.renderer.render().copy()

    def _see_through(self, base: np.ndarray) -> None:
        """Fade the tree trunks that stand between the camera and the robot (in xy)."""
        reach = self.cam.distance * np.cos(np.radians(self.cam.elevation))
        az = np.radians(self.cam.azimuth)
        eye = self.aim[:2] - reach * np.array([np.cos(az), np.sin(az)])
        seg = base[:2] - eye
        xy = self.model.geom_pos[self.trunks, :2] - eye
        t = np.clip(xy @ seg / max(float(seg @ seg), 1e-9), 0.0, 1.0)
        gap = np.linalg.norm(xy - t[:, None] * seg, axis=1)
        between = (gap < self.model.geom_size[self.trunks, 0] + 0.3) & (t < 0.9)
        self.model.geom_rgba[self.trunks, 3] = np.where(between, SEE_THROUGH, 1.0)

    def _draw_trail(self, scene: mujoco.MjvScene, base: np.ndarray, goal: int) -> None:
        """The expert waypoints within ``VIEW_RADIUS`` as spheres and a flag on the
        terminus, as user geoms of this frame's scene."""
        last = len(self.waypoints) - 1
        for k, point in enumerate(self.waypoints):
            if np.linalg.norm(point[:2] - base[:2]) > VIEW_RADIUS:
                continue
            if k == last:
                pole = point + [0.0, 0.0, POLE_HEIGHT / 2.0]
                _add_geom(scene, mujoco.mjtGeom.mjGEOM_CYLINDER, [0.03, POLE_HEIGHT / 2.0, 0.0],
                          pole, (0.95, 0.95, 0.95))
                _add_geom(scene, mujoco.mjtGeom.mjGEOM_BOX, [0.012, 0.3, 0.2],  # faces the trail
                          point + [0.0, 0.3, POLE_HEIGHT - 0.2], FLAG)
                continue
            color = PASSED if k < goal else NEXT_WAYPOINT if k == goal else WAYPOINT
            _add_geom(scene, mujoco.mjtGeom.mjGEOM_SPHERE, [WAYPOINT_RADIUS, 0.0, 0.0],
                      point + [0.0, 0.0, WAYPOINT_LIFT], color)

    def close(self) -> None:
        """Free the GL context."""
        self.renderer.close()


def _add_geom(scene: mujoco.MjvScene, kind: mujoco.mjtGeom, size: list[float],
              pos: np.ndarray, rgb: tuple[float, float, float]) -> None:
    """Append one user geom to ``scene`` (skipped when the scene is full)."""
    if scene.ngeom >= scene.maxgeom:
        return
    mujoco.mjv_initGeom(scene.geoms[scene.ngeom], kind, np.asarray(size, dtype=np.float64),
                        np.asarray(pos, dtype=np.float64), np.eye(3).ravel(),
                        np.array([*rgb, 1.0], dtype=np.float32))
    scene.ngeom += 1


def caption_line(robot: str, trail: str, level: int, seconds: float, walked: float,
                 outcome: str = "") -> str:
    """The caption of one frame: robot, trail, level, time (s), distance walked (m)."""
    line = (f"{robot.upper()}  |  trail {trail}, level {level}  |  t = {seconds:4.1f} s  |  "
            f"walked {walked:+.1f} m")
    return f"{line}  |  {outcome}" if outcome else line


def depth_panel(depth: np.ndarray, far: float, height: int = HEIGHT,
                width: int = PANEL_WIDTH, label: str = "robot's depth view") -> np.ndarray:
    """The robot's depth frame beside the main view: (height, width, 3) uint8, the frame
    (h, w) in the env's normalisation (``depth / far - 0.5``) colour-mapped over 0..far m
    and upscaled by whole pixels, on a dark column with its ``label``."""
    from matplotlib import colormaps

    metres = (np.asarray(depth, dtype=np.float64) + 0.5) * far
    rgb = colormaps[DEPTH_COLORMAP](np.clip(metres / far, 0.0, 1.0))[..., :3]
    scale = max(1, min(width // rgb.shape[1], (height - 3 * CAPTION_SIZE) // rgb.shape[0]))
    rgb = np.repeat(np.repeat(rgb, scale, axis=0), scale, axis=1)
    panel = np.full((height, width, 3), 30, dtype=np.uint8)
    top, left = 2 * CAPTION_SIZE, (width - rgb.shape[1]) // 2
    panel[top:top + rgb.shape[0], left:left + rgb.shape[1]] = (rgb * 255).astype(np.uint8)
    image = Image.fromarray(panel)
    draw = ImageDraw.Draw(image)
    font = ImageFont.load_default(size=CAPTION_SIZE - 2)
    draw.text((8, CAPTION_SIZE // 2), label, fill=(235, 235, 235), font=font)
    draw.text((8, top + rgb.shape[0] + 6), f"near 0 m (bright) .. far {far:.1f} m (dark)",
              fill=(200, 200, 200), font=font)
    return np.asarray(image)


def compose(view: np.ndarray, caption: str, depth: np.ndarray | None = None,
            far: float = 1.0) -> np.ndarray:
    """One video frame: ``view`` (H, W, 3), the depth panel to its right when ``depth``
    is given (see :func:`depth_panel`), and ``caption`` on a dark band along the bottom."""
    if depth is not None:
        view = np.concatenate([view, depth_panel(depth, far, view.shape[0])], axis=1)
    image = Image.fromarray(view)
    draw = ImageDraw.Draw(image, "RGBA")
    band = CAPTION_SIZE + 12
    draw.rectangle([0, image.height - band, image.width, image.height], fill=(0, 0, 0, 150))
    draw.text((10, image.height - band + 5), caption, fill=(255, 255, 255),
              font=ImageFont.load_default(size=CAPTION_SIZE))
    return np.asarray(image)


def write_video(frames: list[np.ndarray], path: Path, fps: float) -> Path:
    """An MP4 when imageio-ffmpeg is installed (and ``path`` asks for one), else a GIF
    beside it: pillow ships with matplotlib, so a picture always comes out."""
    if path.suffix == ".mp4" and importlib.util.find_spec("imageio_ffmpeg") is not None:
        imageio.mimwrite(path, frames, fps=fps, macro_block_size=8, quality=None,
                         ffmpeg_params=["-crf", str(VIDEO_CRF)])
        return path
    path = path.with_suffix(".gif")
    imageio.mimwrite(path, frames, duration=1000.0 / fps, loop=0)  # duration: ms per frame
    return path


def write_filmstrip(frames: list[np.ndarray], path: Path, count: int = FILMSTRIP_FRAMES
                    ) -> Path:
    """``count`` frames evenly spread over the episode, side by side, as one PNG."""
    picks = np.unique(np.linspace(0, len(frames) - 1, min(count, len(frames))).round())
    imageio.imwrite(path, np.concatenate([frames[int(i)] for i in picks], axis=1))
    return path
