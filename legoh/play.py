"""``mode=play``: watch a policy hike. Robot 0's first episode as a video and a filmstrip.

The policy runs deterministically on a few robots of the evaluation env (``conf/eval``:
episodes of ``eval.seconds``, on the hardest of ``eval.levels``, the level that the
benchmark's ``trajectories.png`` shows). The picture is the env's own training model
(collision capsules, terrain height fields; no visual meshes), so nothing is rebuilt and
it shows exactly what the policy felt. A side-on camera follows the base; rendering is
headless (EGL on Linux).
"""

from __future__ import annotations

import os
import sys

if sys.platform.startswith("linux"):  # headless; must precede mujoco's first import
    os.environ.setdefault("MUJOCO_GL", "egl")

import copy  # noqa: E402
import importlib.util  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

import imageio.v2 as imageio  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402
from omegaconf import DictConfig, OmegaConf  # noqa: E402
from torchrl.envs.utils import ExplorationType, set_exploration_type, step_mdp  # noqa: E402

from legoh import keys  # noqa: E402
from legoh.envs.robots import ROBOT_GEOM_GROUP  # noqa: E402
from legoh.eval.benchmark import make_eval_env  # noqa: E402
from legoh.eval.metrics import distance_walked  # noqa: E402
from legoh.threads import torch_threads  # noqa: E402

WIDTH, HEIGHT = 320, 240  # px: ~0.06 s a frame with software EGL (FollowCamera)
RENDER_EVERY = 2  # policy steps per frame: 50 Hz policy -> 25 fps, real time
FILMSTRIP_FRAMES = 8
PLAY_ROBOTS = 4  # robots mode=play runs (robot 0 is filmed; the others give the mean DW)
CAMERA_DISTANCE = 3.0  # x the robot's nominal base height, m
CAMERA_ELEVATION = -15.0  # deg, slightly from above
VIEW_RADIUS = 12.0  # m: terrain chunks and obstacles farther from the robot are not drawn
HIDDEN_GROUP = 5  # geom group the far world geoms are moved to (not drawn)


class FollowCamera:
    """Renders one robot of a batched sim from the side of its start heading: a free
    camera whose lookat is set to the base each frame, so the view depends on the pose
    alone (the render data is refilled from the sim's qpos; it keeps no history).

    Software EGL draws every triangle it is given: the whole map's height fields with
    shadows take ~2.6 s a frame (H1, hurdle), the chunks within ``VIEW_RADIUS`` without
    shadows ~0.06 s. The culling edits a copy of the model, never the env's.
    """

    def __init__(self, model: mujoco.MjModel, base_body: str, heading: float,
                 base_height: float) -> None:
        self.model = copy.deepcopy(model)
        self.data = mujoco.MjData(self.model)
        self.base = model.body(base_body).id
        self.world = np.flatnonzero((model.geom_bodyid == 0)
                                    & (model.geom_type != mujoco.mjtGeom.mjGEOM_PLANE))
        self.groups = model.geom_group[self.world].copy()
        self.renderer = mujoco.Renderer(self.model, height=HEIGHT, width=WIDTH)
        self.renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False
        self.option = mujoco.MjvOption()
        self.option.geomgroup[ROBOT_GEOM_GROUP] = 1  # the robot's colliders are its body here
        self.option.geomgroup[HIDDEN_GROUP] = 0
        self.option.sitegroup[:] = 0
        self.cam = mujoco.MjvCamera()
        self.cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        self.cam.azimuth = float(np.degrees(heading)) + 90.0  # side-on to the trail
        self.cam.elevation = CAMERA_ELEVATION
        self.cam.distance = CAMERA_DISTANCE * base_height

    def frame(self, qpos: np.ndarray) -> np.ndarray:
        """(HEIGHT, WIDTH, 3) uint8 of the robot in pose ``qpos`` (nq,)."""
        self.data.qpos[:] = qpos
        mujoco.mj_kinematics(self.model, self.data)  # positions only: no contacts needed
        mujoco.mj_camlight(self.model, self.data)
        self.cam.lookat[:] = base = self.data.xpos[self.base]
        far = np.linalg.norm(self.model.geom_pos[self.world, :2] - base[:2], axis=1)
        self.model.geom_group[self.world] = np.where(far > VIEW_RADIUS, HIDDEN_GROUP,
                                                     self.groups)
        self.renderer.update_scene(self.data, camera=self.cam, scene_option=self.option)
        return self.renderer.render().copy()

    def close(self) -> None:
        """Free the GL context."""
        self.renderer.close()


def write_video(frames: list[np.ndarray], path: Path, fps: float) -> Path:
    """An MP4 when imageio-ffmpeg is installed (and ``path`` asks for one), else a GIF
    beside it: pillow ships with matplotlib, so a picture always comes out."""
    if path.suffix == ".mp4" and importlib.util.find_spec("imageio_ffmpeg") is not None:
        imageio.mimwrite(path, frames, fps=fps, macro_block_size=8)
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


def render_policy_video(cfg: DictConfig, actor, out_path: str | Path,
                        seconds: float | None = None, robots: int = PLAY_ROBOTS,
                        level: int | None = None) -> dict:
    """Run ``actor`` (a TensorDict policy writing ``"action"``; deterministic mode) on
    ``robots`` robots of the evaluation env until each has ended its first episode (reach,
    fall or time-out, as in the benchmark) and film robot 0's.

    Args:
        cfg: composed run config (robot, trail, env, eval). out_path: the video (``.mp4``;
            a ``.gif`` beside it without imageio-ffmpeg); the filmstrip goes next to it as
            ``<stem>_filmstrip.png``. seconds: episode length (default ``eval.seconds``).
        level: trail level (default: the hardest of ``eval.levels``).

    Returns:
        ``{"video": Path, "filmstrip": Path, "distance": m robot 0 walked toward its
        terminus (DW), "fell": bool, "mean_distance": DW over all robots, "frames": int}``.
    """
    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    seconds = float(cfg.eval.seconds if seconds is None else seconds)
    level = int(max(cfg.eval.levels) if level is None else level)
    env = make_eval_env(OmegaConf.merge(cfg, {"eval": {"robots": robots, "seconds": seconds}}))
    camera = None
    was_training = getattr(actor, "training", False)
    if was_training:
        actor.eval()
    try:
        env.level[:] = level
        td = env.reset()
        start, tile = td[keys.BASE_POS].cpu().numpy().copy(), td[keys.TILE].cpu().numpy().copy()
        end, fell = start.copy(), np.zeros(robots, dtype=bool)
        ended = np.zeros(robots, dtype=bool)
        camera = FollowCamera(env.scene.model, env.robot.base_body,
                              float(env.trails.start_yaw[tile[0]]),
                              env.robot.nominal_base_height)
        frames = [camera.frame(env.sim.qpos[0].cpu().numpy())]
        with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC), \
                torch_threads(1):
            for step in range(env.max_steps):
                td = env.step(actor(td))  # no auto-reset: each robot stays where it ended
                nxt = td["next"]
                pos = nxt[keys.BASE_POS].cpu().numpy()
                done = nxt[keys.DONE].reshape(robots).cpu().numpy() & ~ended
                end[done] = pos[done]
                fell[done] = (nxt[keys.FELL].cpu().numpy() & ~nxt[keys.REACHED].cpu().numpy())[done]
                if not ended[0] and ((step + 1) % RENDER_EVERY == 0 or done[0]):
                    frames.append(camera.frame(env.sim.qpos[0].cpu().numpy()))
                ended |= done
                if ended.all():
                    break
                td = step_mdp(td)
        end[~ended] = pos[~ended]  # never done within max_steps: a time-out
        walked = distance_walked(start, end, env.trails.terminus[tile])
    finally:
        if camera is not None:
            camera.close()
        env.close()
        if was_training:
            actor.train()
    video = write_video(frames, out_path, 1.0 / (env.dt * RENDER_EVERY))
    strip = write_filmstrip(frames, out_path.with_name(f"{out_path.stem}_filmstrip.png"))
    return {"video": video, "filmstrip": strip, "distance": float(walked[0]),
            "fell": bool(fell[0]), "mean_distance": float(walked.mean()),
            "frames": len(frames)}


def main(cfg: DictConfig, out_dir: Path) -> dict:
    """``mode=play``: film ``checkpoint``'s oracle (the untrained one without it)."""
    from legoh.eval.cli import build_actor

    if cfg.algo.name != "oracle":
        raise ValueError("mode=play films an oracle (algo=oracle): a student needs the "
                         "depth env of the benchmark, which this mode does not build")
    checkpoint = OmegaConf.select(cfg, "checkpoint", default=None)
    if not checkpoint:
        warnings.warn("no checkpoint given (checkpoint=<path>): playing an untrained actor",
                      stacklevel=2)
    actor, _ = build_actor(cfg, checkpoint)
    result = render_policy_video(cfg, actor, out_dir / "play.mp4")
    who = Path(checkpoint).name if checkpoint else "untrained actor"
    print(f"[legoh] {who}: robot 0 walked {result['distance']:.2f} m toward the terminus "
          f"and {'fell' if result['fell'] else 'did not fall'} (mean DW of "
          f"{PLAY_ROBOTS} robots: {result['mean_distance']:.2f} m)")
    print(f"[legoh] video:     {result['video']}")
    print(f"[legoh] filmstrip: {result['filmstrip']}")
    return result
