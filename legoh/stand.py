"""The first main job: build the robot, hold the default pose, and take its picture.

Until the training stage lands, ``python run.py`` runs this: it proves the config composes,
the robot builds and stands under its own PD, and the depth camera sees the ground.
"""

from __future__ import annotations

import os
import sys

if sys.platform.startswith("linux"):  # headless; must precede mujoco's first import
    os.environ.setdefault("MUJOCO_GL", "egl")

from pathlib import Path  # noqa: E402

import mujoco  # noqa: E402
import numpy as np  # noqa: E402
from omegaconf import DictConfig, OmegaConf  # noqa: E402

from legoh.config import RobotConfig, SimConfig  # noqa: E402
from legoh.config.env import DepthConfig  # noqa: E402
from legoh.envs.robots import (  # noqa: E402
    CAMERA_NAME,
    RobotInfo,
    add_flat_ground,
    build_robot_spec,
    reset_to_default,
    set_options,
    standing_base_height,
)
from legoh.envs.sensors import DepthRaycaster  # noqa: E402

PREVIEW_SCALE = 4  # the picture's depth image in multiples of env.depth's size (128 x 96)


def build_standing_scene(robot_cfg: RobotConfig, sim: SimConfig, render: bool = False
                         ) -> tuple[mujoco.MjModel, mujoco.MjData, RobotInfo]:
    """The robot on a flat floor, in its default pose with its feet on the ground."""
    spec, info = build_robot_spec(robot_cfg, render=render)
    add_flat_ground(spec)
    set_options(spec, sim.dt)
    if render:
        spec.worldbody.add_light(pos=[0.0, 0.0, 4.0], dir=[0.0, 0.0, -1.0],
                                  type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL)
    model = spec.compile()
    data = mujoco.MjData(model)
    reset_to_default(model, data, info, np.array([0.0, 0.0, standing_base_height(model, info)]))
    return model, data, info


def hold_default_pose(model: mujoco.MjModel, data: mujoco.MjData, seconds: float) -> np.ndarray:
    """Step the physics with the PD targets at the default pose; returns base heights (m)."""
    steps = int(round(seconds / model.opt.timestep))
    heights = np.empty(steps)
    for i in range(steps):
        mujoco.mj_step(model, data)
        heights[i] = data.qpos[2]
    return heights


def render_picture(model: mujoco.MjModel, data: mujoco.MjData, info: RobotInfo,
                   robot_cfg: RobotConfig, depth_cfg: DepthConfig, path: Path) -> Path:
    """A PNG: the robot seen from the side-front, beside its egocentric depth image."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_TRACKING
    cam.trackbodyid = model.body(info.base_body).id
    cam.distance, cam.azimuth, cam.elevation = 3.0 * info.nominal_base_height, 135.0, -15.0
    with mujoco.Renderer(model, height=480, width=480) as renderer:
        renderer.update_scene(data, camera=cam)
        rgb = renderer.render()
    c, d = robot_cfg.camera, depth_cfg
    depth = DepthRaycaster(model, c.fovy_deg, d.width * PREVIEW_SCALE, d.height * PREVIEW_SCALE,
                           d.far).render_camera(data, CAMERA_NAME)

    fig, axes = plt.subplots(1, 2, figsize=(10, 4.6), gridspec_kw={"width_ratios": [1, 1.2]})
    axes[0].imshow(rgb)
    axes[0].set_title(f"{robot_cfg.name}: default pose after standing")
    axes[0].axis("off")
    im = axes[1].imshow(depth, cmap="viridis_r", vmin=0.0, vmax=d.far)
    axes[1].set_title(f"head camera depth (m), pitch {c.pitch_deg:.0f} deg")
    axes[1].axis("off")
    fig.colorbar(im, ax=axes[1], fraction=0.04)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def main(cfg: DictConfig, out_dir: Path) -> Path:
    """Validate the config, stand the robot for ``cfg.stand_seconds``, write its picture."""
    robot_cfg: RobotConfig = OmegaConf.to_object(cfg.robot)
    sim: SimConfig = OmegaConf.to_object(cfg.sim)
    model, data, info = build_standing_scene(robot_cfg, sim, render=True)
    heights = hold_default_pose(model, data, cfg.stand_seconds)
    print(f"[legoh] {info.name}: {info.num_actions} actions over {len(info.actuated_joints)} "
          f"actuated joints; base height {heights[-1]:.3f} m after {cfg.stand_seconds:.1f} s "
          f"(lowest {heights.min():.3f} m; nominal {info.nominal_base_height:.3f} m)")
    path = render_picture(model, data, info, robot_cfg, OmegaConf.to_object(cfg.env.depth),
                          out_dir / f"{info.name}_standing.png")
    print(f"[legoh] picture of the robot: {path}")
    return path
