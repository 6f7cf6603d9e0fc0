"""``mode=play``: watch a policy hike. Robot 0's first episode as a video and a filmstrip.

The policy runs deterministically on a few robots of the evaluation env (``conf/eval``:
episodes of ``eval.seconds``, on the hardest of ``eval.levels``, the level that the
benchmark's ``trajectories.png`` shows). ``legoh/video.py`` films it: a camera behind and
beside the robot on a dressed copy of the env's scene (the same terrain map and robot, with
visual meshes, sky and shadows), the expert waypoints and the terminus drawn in, a caption
on each frame (robot, trail, level, time, distance walked) and, for a policy with depth, its
depth view beside the picture. Rendering is headless (EGL on Linux).
"""

from __future__ import annotations

import os
import sys

if sys.platform.startswith("linux"):  # headless; must precede mujoco's first import
    os.environ.setdefault("MUJOCO_GL", "egl")

import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402
from omegaconf import DictConfig, OmegaConf  # noqa: E402
from torchrl.envs.utils import ExplorationType, set_exploration_type, step_mdp  # noqa: E402

from legoh import keys  # noqa: E402
from legoh.eval.benchmark import make_eval_env, student_eval_env_fn  # noqa: E402
from legoh.eval.metrics import distance_walked  # noqa: E402
from legoh.threads import torch_threads  # noqa: E402
from legoh.video import (  # noqa: E402
    FollowCamera,
    caption_line,
    compose,
    render_model,
    write_filmstrip,
    write_video,
)

RENDER_EVERY = 2  # policy steps per frame: 50 Hz policy -> 25 fps, real time
PLAY_ROBOTS = 4  # robots mode=play runs (robot 0 is filmed; the others give the mean DW)


def render_policy_video(cfg: DictConfig, actor, out_path: str | Path,
                        seconds: float | None = None, robots: int = PLAY_ROBOTS,
                        level: int | None = None, student=None) -> dict:
    """Run ``actor`` (a TensorDict policy writing ``"action"``; deterministic mode) on
    ``robots`` robots of the evaluation env until each has ended its first episode (reach,
    fall or time-out, as in the benchmark) and film robot 0's.

    Args:
        cfg: composed run config (robot, trail, env, eval). out_path: the video (``.mp4``;
            a ``.gif`` beside it without imageio-ffmpeg); the filmstrip goes next to it as
            ``<stem>_filmstrip.png``. seconds: episode length (default ``eval.seconds``).
        level: trail level (default: the hardest of ``eval.levels``).
        student: a stage-2 :class:`~legoh.modules.students.Student` whose policy ``actor``
            is: the film uses its evaluation env (depth on, its recurrent state primed) and
            shows the depth frame it sees beside the robot.

    Returns:
        ``{"video": Path, "filmstrip": Path, "distance": m robot 0 walked toward its
        terminus (DW), "fell": bool, "mean_distance": DW over all robots, "frames": int}``.
    """
    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    seconds = float(cfg.eval.seconds if seconds is None else seconds)
    level = int(max(cfg.eval.levels) if level is None else level)
    run_cfg = OmegaConf.merge(cfg, {"eval": {"robots": robots, "seconds": seconds}})
    env = (make_eval_env(run_cfg) if student is None
           else student_eval_env_fn(run_cfg, student)(0))
    camera = None
    was_training = getattr(actor, "training", False)
    if was_training:
        actor.eval()
    try:
        env.set_level(level)
        td = env.reset()
        start, tile = td[keys.BASE_POS].cpu().numpy().copy(), td[keys.TILE].cpu().numpy().copy()
        end, fell = start.copy(), np.zeros(robots, dtype=bool)
        ended = np.zeros(robots, dtype=bool)
        camera = FollowCamera(
            render_model(OmegaConf.to_object(cfg.robot), env.terrain, cfg.sim.dt,
                         cfg.sim.hfield_chunk),
            env.robot.base_body, env.terrain.tiles[tile[0]], env.robot.nominal_base_height)

        def shoot(obs, seconds: float, outcome: str = "") -> np.ndarray:
            """Robot 0 in ``obs`` (a step's results): the view, its depth, the caption."""
            walked = distance_walked(start[:1], obs[keys.BASE_POS][:1].cpu().numpy(),
                                     env.trails.terminus[tile[:1]])[0]
            depth = obs.get(keys.DEPTH, None)
            view = camera.frame(env.sim.qpos[0].cpu().numpy(), int(obs[keys.WAYPOINT][0]))
            text = caption_line(cfg.robot.name, cfg.trail.name, int(env.trails.level[tile[0]]),
                                seconds, float(walked), outcome)
            return compose(view, text, None if depth is None else depth[0, -1].cpu().numpy(),
                           float(cfg.env.depth.far))

        frames = [shoot(td, 0.0)]
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
                    outcome = ("" if not done[0] else "fell" if fell[0] else "reached"
                               if bool(nxt[keys.REACHED][0]) else "time-out")
                    frames.append(shoot(nxt, (step + 1) * env.dt, outcome))
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
    from legoh.eval.cli import build_actor, for_checkpoint

    checkpoint = OmegaConf.select(cfg, "checkpoint", default=None)
    if not checkpoint:
        warnings.warn("no checkpoint given (checkpoint=<path>): playing an untrained actor",
                      stacklevel=2)
    cfg, checkpoint = for_checkpoint(cfg, checkpoint)  # a student's film: its own camera
    policy, env_fn = build_actor(cfg, checkpoint)
    if env_fn is None:  # an oracle
        result = render_policy_video(cfg, policy, out_dir / "play.mp4")
    else:  # a student (algo=unified, ep_h, ...): its depth env, its depth view in the film
        result = render_policy_video(cfg, policy.policy, out_dir / "play.mp4", student=policy)
    who = Path(checkpoint).name if checkpoint else "untrained actor"
    print(f"[legoh] {who}: robot 0 walked {result['distance']:.2f} m toward the terminus "
          f"and {'fell' if result['fell'] else 'did not fall'} (mean DW of "
          f"{PLAY_ROBOTS} robots: {result['mean_distance']:.2f} m)")
    print(f"[legoh] video:     {result['video']}")
    print(f"[legoh] filmstrip: {result['filmstrip']}")
    return result
