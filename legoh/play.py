"""``mode=play``: watch a policy hike. One robot's first episode as a video and a filmstrip.

The policy runs deterministically on ``play.robots`` robots of the evaluation env (``conf/eval``:
episodes of ``eval.seconds``, on the hardest of ``eval.levels``, the level that the
benchmark's ``trajectories.png`` shows). ``legoh/video.py`` films it: a camera behind and
beside the robot on a dressed copy of the env's scene (the same terrain map and robot, with
visual meshes, sky and shadows), the expert waypoints and the terminus drawn in, a caption
on each frame (robot, trail, level, time, distance walked) and, for a policy with depth, its
depth view beside the picture. Rendering is headless (EGL on Linux). ``play.film`` picks the
robot filmed: robot 0 by default, or the first that fell (``play.film=fell``: where a policy
fails, seen at once), timed out or reached.

The rollout is recorded first (:func:`record_rollout`: every robot's pose at every step)
and filmed after (:func:`film`); ``viewer=web`` (``legoh/viewer``) replays the same record
in a browser page.
"""

from __future__ import annotations

import os
import sys

if sys.platform.startswith("linux"):  # headless; must precede mujoco's first import
    os.environ.setdefault("MUJOCO_GL", "egl")

import warnings  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402
from omegaconf import DictConfig, OmegaConf  # noqa: E402
from torchrl.envs.utils import ExplorationType, set_exploration_type, step_mdp  # noqa: E402

from legoh import keys  # noqa: E402
from legoh.envs.terrain import TerrainMap  # noqa: E402
from legoh.envs.terrain.terrain_map import Tile  # noqa: E402
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
PLAY_ROBOTS = 4  # robots a film rolls out (the default of play.robots; others: the mean DW)
OUTCOMES = ("reached", "fell", "time-out")  # how a robot's episode ends (Rollout.outcome)


@dataclass
class Rollout:
    """A recorded play rollout: every robot's pose at each policy step (0: the reset), until
    every robot has ended its first episode. Replayed by the video (:func:`film`) and the
    web viewer (``legoh/viewer``), so neither steps the env while it draws.

    Index ``[t, i]``: step ``t`` (``t * dt`` s after the reset), robot ``i``. A robot's
    rows after its ``end`` step are where the env kept it, not part of its episode.
    """

    qpos: np.ndarray  # (T+1, N, nq) float64: MuJoCo generalised positions (world frame, m)
    goal: np.ndarray  # (T+1, N) int: index of the robot's current expert waypoint
    walked: np.ndarray  # (T+1, N) float: m closer to its terminus than at the reset (DW)
    depth: np.ndarray | None  # (T+1, N, h, w) float32: newest depth frame (normalised)
    end: np.ndarray  # (N,) int: the step each robot's episode ended on (T: never, time-out)
    outcome: list[str]  # per robot: "reached", "fell" or "time-out"
    tiles: list[Tile]  # per robot, the trail tile it hikes
    level: int  # the trail level all robots are on
    dt: float  # s per policy step
    terrain: TerrainMap  # the env's map (all tiles)
    base_body: str  # the robot's base body (cameras follow it)
    base_height: float  # m, the robot's nominal base height
    depth_far: float  # m, the depth frames' far plane

    @property
    def steps(self) -> int:
        """Policy steps recorded after the reset (T)."""
        return len(self.qpos) - 1


def record_rollout(cfg: DictConfig, actor, seconds: float | None = None,
                   robots: int = PLAY_ROBOTS, level: int | None = None, student=None,
                   depth: bool = False) -> Rollout:
    """Run ``actor`` (a TensorDict policy writing ``"action"``; deterministic mode) on
    ``robots`` robots of the evaluation env until each has ended its first episode (reach,
    fall or time-out, as in the benchmark), recording every robot's pose at every step.

    Args:
        cfg: composed run config (robot, trail, env, eval). seconds: episode length
            (default ``eval.seconds``). level: trail level (default: the hardest of
            ``eval.levels``).
        student: a stage-2 :class:`~legoh.modules.students.Student` whose policy ``actor``
            is: its evaluation env (depth on, its recurrent state primed).
        depth: also record the env's depth camera for a policy that does not see it (an
            oracle); a student's frames are always recorded.
    """
    seconds = float(cfg.eval.seconds if seconds is None else seconds)
    level = int(max(cfg.eval.levels) if level is None else level)
    run_cfg = OmegaConf.merge(cfg, {"eval": {"robots": robots, "seconds": seconds}})
    if depth and student is None:  # the camera only: the oracle's inputs stay its own
        run_cfg = OmegaConf.merge(run_cfg, {"env": {"depth": {"enabled": True}}})
    env = (make_eval_env(run_cfg) if student is None
           else student_eval_env_fn(run_cfg, student)(0))
    was_training = getattr(actor, "training", False)
    if was_training:
        actor.eval()
    try:
        env.set_level(level)
        td = env.reset()
        start, tile = td[keys.BASE_POS].cpu().numpy().copy(), td[keys.TILE].cpu().numpy().copy()
        terminus = env.trails.terminus[tile]
        qpos, goal, pos, frames = [], [], [], []

        def keep(obs) -> None:
            """Append this step's poses (and depth frames) of every robot."""
            qpos.append(env.sim.qpos.cpu().numpy().astype(np.float64))
            goal.append(obs[keys.WAYPOINT].reshape(robots).cpu().numpy().copy())
            pos.append(obs[keys.BASE_POS].cpu().numpy().copy())
            if keys.DEPTH in obs.keys(True):
                frames.append(obs[keys.DEPTH][:, -1].cpu().numpy().astype(np.float32))

        keep(td)
        end = np.full(robots, -1)
        outcome = ["time-out"] * robots
        with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC), \
                torch_threads(1):
            for step in range(env.max_steps):
                td = env.step(actor(td))  # no auto-reset: each robot stays where it ended
                nxt = td["next"]
                keep(nxt)
                done = nxt[keys.DONE].reshape(robots).cpu().numpy() & (end < 0)
                reached = nxt[keys.REACHED].reshape(robots).cpu().numpy()
                fell = nxt[keys.FELL].reshape(robots).cpu().numpy() & ~reached
                for i in np.flatnonzero(done):
                    end[i] = step + 1
                    outcome[i] = "fell" if fell[i] else "reached" if reached[i] else "time-out"
                if (end >= 0).all():
                    break
                td = step_mdp(td)
        steps = len(qpos) - 1
        end[end < 0] = steps  # never done within max_steps: a time-out
        pos = np.stack(pos)
        walked = np.stack([distance_walked(start, p, terminus) for p in pos])
        return Rollout(qpos=np.stack(qpos), goal=np.stack(goal).astype(int), walked=walked,
                       depth=np.stack(frames) if frames else None, end=end, outcome=outcome,
                       tiles=[env.terrain.tiles[t] for t in tile],
                       level=int(env.trails.level[tile[0]]), dt=float(env.dt),
                       terrain=env.terrain, base_body=env.robot.base_body,
                       base_height=float(env.robot.nominal_base_height),
                       depth_far=float(cfg.env.depth.far))
    finally:
        env.close()
        if was_training:
            actor.train()


def pick_robot(rollout: Rollout, film: str | int) -> int:
    """The robot ``play.film`` names: an index, or an outcome (the first robot whose episode
    ended so, the earliest-ending one; robot 0 when none did)."""
    n, film = len(rollout.outcome), str(film)
    if film in OUTCOMES:
        hits = [i for i in range(n) if rollout.outcome[i] == film]
        return min(hits, key=lambda i: (rollout.end[i], i)) if hits else 0
    if film.isdigit() and int(film) < n:
        return int(film)
    raise ValueError(f"play.film={film!r}: expected a robot index 0..{n - 1} (play.robots={n}) "
                     f"or one of {', '.join(OUTCOMES)}")


def film_steps(end: int) -> list[int]:
    """The steps a video shows of an episode that ended on step ``end``: the reset, every
    ``RENDER_EVERY``-th step (real time at 25 fps) and the last."""
    return [0, *(s for s in range(1, end + 1) if s % RENDER_EVERY == 0 or s == end)]


def film(cfg: DictConfig, rollout: Rollout, robot: int = 0) -> list[np.ndarray]:
    """The video frames of ``robot``'s episode in ``rollout`` (see :mod:`legoh.video`)."""
    camera = FollowCamera(
        render_model(OmegaConf.to_object(cfg.robot), rollout.terrain, cfg.sim.dt,
                     cfg.sim.hfield_chunk),
        rollout.base_body, rollout.tiles[robot], rollout.base_height)
    end = int(rollout.end[robot])
    try:
        frames = []
        for step in film_steps(end):
            view = camera.frame(rollout.qpos[step, robot], int(rollout.goal[step, robot]))
            text = caption_line(cfg.robot.name, cfg.trail.name, rollout.level, step * rollout.dt,
                                float(rollout.walked[step, robot]),
                                rollout.outcome[robot] if step == end else "")
            depth = None if rollout.depth is None else rollout.depth[step, robot]
            frames.append(compose(view, text, depth, rollout.depth_far))
        return frames
    finally:
        camera.close()


def render_policy_video(cfg: DictConfig, actor, out_path: str | Path,
                        seconds: float | None = None, robots: int = PLAY_ROBOTS,
                        level: int | None = None, student=None, robot: str | int = 0) -> dict:
    """Run ``actor`` as :func:`record_rollout` does and film one robot's episode.

    Args:
        cfg, seconds, robots, level, student: as :func:`record_rollout` (a student's film
            shows the depth frame it sees beside the robot).
        robot: whom to film, as ``play.film`` (:func:`pick_robot`): an index or an outcome.
        out_path: the video (``.mp4``; a ``.gif`` beside it without imageio-ffmpeg); the
            filmstrip goes next to it as ``<stem>_filmstrip.png``.

    Returns:
        ``{"video": Path, "filmstrip": Path, "robot": the index filmed, "distance": m it
        walked toward its terminus (DW), "fell": bool, "outcomes": every robot's outcome,
        "mean_distance": DW over all robots, "frames": int}``.
    """
    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    rollout = record_rollout(cfg, actor, seconds, robots, level, student)
    who = pick_robot(rollout, robot)
    frames = film(cfg, rollout, who)
    video = write_video(frames, out_path, 1.0 / (rollout.dt * RENDER_EVERY))
    strip = write_filmstrip(frames, out_path.with_name(f"{out_path.stem}_filmstrip.png"))
    walked = rollout.walked[rollout.end, np.arange(robots)]
    return {"video": video, "filmstrip": strip, "robot": who, "distance": float(walked[who]),
            "fell": rollout.outcome[who] == "fell", "outcomes": list(rollout.outcome),
            "mean_distance": float(walked.mean()), "frames": len(frames)}


def warn_untrained(checkpoint: str | None) -> None:
    """Say so when no checkpoint was given: the policy played is an untrained one."""
    if not checkpoint:
        warnings.warn("no checkpoint given (checkpoint=<path>): playing an untrained actor",
                      stacklevel=3)


def main(cfg: DictConfig, out_dir: Path) -> dict:
    """``mode=play``: film ``checkpoint``'s oracle (the untrained one without it)."""
    from legoh.eval.cli import build_actor, for_checkpoint

    checkpoint = OmegaConf.select(cfg, "checkpoint", default=None)
    warn_untrained(checkpoint)
    cfg, checkpoint = for_checkpoint(cfg, checkpoint)  # a student's film: its own camera
    policy, env_fn = build_actor(cfg, checkpoint)
    robots, pick = int(cfg.play.robots), str(cfg.play.film)
    if env_fn is None:  # an oracle
        result = render_policy_video(cfg, policy, out_dir / "play.mp4", robots=robots,
                                     robot=pick)
    else:  # a student (algo=unified, ep_h, ...): its depth env, its depth view in the film
        result = render_policy_video(cfg, policy.policy, out_dir / "play.mp4", robots=robots,
                                     student=policy, robot=pick)
    who = Path(checkpoint).name if checkpoint else "untrained actor"
    counts = ", ".join(f"{result['outcomes'].count(o)} {o}" for o in OUTCOMES)
    print(f"[legoh] {who}: robot {result['robot']} (play.film={pick}) walked "
          f"{result['distance']:.2f} m toward the terminus and "
          f"{'fell' if result['fell'] else 'did not fall'}; {robots} robots: {counts}, "
          f"mean DW {result['mean_distance']:.2f} m")
    print(f"[legoh] video:     {result['video']}")
    print(f"[legoh] filmstrip: {result['filmstrip']}")
    return result
