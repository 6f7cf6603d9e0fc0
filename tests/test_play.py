"""mode=play: a policy's episode rendered headless (EGL) to a video and a filmstrip, and the
renderer it films with (legoh/video.py: camera, trail markers, caption, depth view)."""

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import imageio.v2 as imageio
import numpy as np
import pytest
import torch
from omegaconf import OmegaConf
from tensordict.nn import TensorDictModule

from legoh import keys, play, video
from legoh.envs.robots import build_robot_spec
from legoh.eval.benchmark import make_eval_env
from tests.conftest import compose_config

ROOT = Path(__file__).resolve().parents[1]
TINY = ("trail=flat", "trail.levels=1", "trail.variants=1", "eval.seconds=1",
        "eval.levels=[0]", "eval.variants=1")


def test_play_mode_through_run_py_writes_video_and_filmstrip(tmp_path: Path) -> None:
    """The command a user types, untrained policy, 1 s: a non-empty video, a filmstrip of
    several frames side by side, and both paths printed."""
    out = tmp_path / "run"
    proc = subprocess.run(
        [sys.executable, "run.py", "mode=play", *TINY, f"hydra.run.dir={out}"], cwd=ROOT,
        capture_output=True, text=True, timeout=600,
        env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert proc.returncode == 0, proc.stderr[-3000:]
    ext = ".mp4" if importlib.util.find_spec("imageio_ffmpeg") else ".gif"
    clip, strip = out / f"play{ext}", out / "play_filmstrip.png"
    assert clip.stat().st_size > 0 and str(clip) in proc.stdout and str(strip) in proc.stdout
    picture = imageio.imread(strip)
    assert picture.shape[0] == video.HEIGHT >= 480 and picture.shape[1] > video.WIDTH >= 640
    assert picture.std() > 0  # not a blank frame: the scene was drawn


def test_render_policy_video_of_a_standing_robot(tmp_path: Path) -> None:
    """For scripts, on an in-memory policy: zero actions hold the default pose, so robot 0
    does not fall and walks ~0 m; one frame at the reset, then one per 2 steps for 1 s. A
    ``.gif`` path asks for a GIF."""
    cfg = compose_config(*TINY)
    actions = build_robot_spec(OmegaConf.to_object(cfg.robot))[1].num_actions
    zero = TensorDictModule(lambda obs: torch.zeros(len(obs), actions),
                            in_keys=[keys.PROPRIO], out_keys=[keys.ACTION])
    result = play.render_policy_video(cfg, zero, tmp_path / "clip.gif", robots=2)
    assert result["video"] == tmp_path / "clip.gif"
    assert result["filmstrip"] == tmp_path / "clip_filmstrip.png"
    assert not result["fell"] and abs(result["distance"]) < 0.1
    steps = round(cfg.eval.seconds * 50)  # 50 Hz policy
    assert result["frames"] == 1 + steps // play.RENDER_EVERY
    frames = imageio.mimread(result["video"])
    assert len(frames) == result["frames"] and frames[0].shape[:2] == (video.HEIGHT,
                                                                       video.WIDTH)
    strip = imageio.imread(result["filmstrip"])
    assert strip.shape[1] == video.FILMSTRIP_FRAMES * video.WIDTH
    assert not np.array_equal(frames[0], np.zeros_like(frames[0]))


def test_play_films_a_student_with_its_depth_view_beside_the_robot(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """mode=play of a stage-2 student (untrained: no checkpoint) runs it in its own depth env
    and puts the depth frame it sees beside the robot: frames wider than the view."""
    monkeypatch.setattr("legoh.policies.pretrained.PRETRAINED_DIR", tmp_path / "none")
    with pytest.warns(UserWarning, match="untrained"):
        result = play.main(compose_config("algo=unified", *TINY), tmp_path)
    frames = imageio.mimread(result["video"])
    assert frames[0].shape[:2] == (video.HEIGHT, video.WIDTH + video.PANEL_WIDTH)
    panel = frames[0][:, video.WIDTH:]
    assert panel.std() > 0  # the depth frame and its labels were drawn


def _close_to(image: np.ndarray, rgb: tuple[float, float, float], tol: int = 40) -> int:
    """Pixels of ``image`` within ``tol`` (0-255, every channel) of the colour ``rgb``."""
    return int((np.abs(image.astype(int) - np.array(rgb) * 255).max(axis=-1) <= tol).sum())


@pytest.fixture(scope="module")
def filmed():
    """A camera on robot 0 of a one-robot flat-trail eval env, and the env's model state."""
    cfg = compose_config(*TINY)
    env = make_eval_env(OmegaConf.merge(cfg, {"eval": {"robots": 1}}))
    td = env.reset()
    groups = env.scene.model.geom_group.copy()
    tile = env.terrain.tiles[int(td[keys.TILE][0])]
    camera = video.FollowCamera(
        video.render_model(OmegaConf.to_object(cfg.robot), env.terrain, cfg.sim.dt,
                           cfg.sim.hfield_chunk),
        env.robot.base_body, tile, env.robot.nominal_base_height)
    yield env, camera, tile, groups
    camera.close()
    env.close()


def test_frame_draws_waypoints_and_the_terminus_flag(filmed) -> None:
    """A frame is at least 640 x 480; at the trail's start the robot's current waypoint is
    drawn yellow (the terminus, 22 m on, is not), and near the end its red flag shows; the
    env's model is untouched (the camera renders a model of its own)."""
    env, camera, tile, groups = filmed
    qpos = env.sim.qpos[0].cpu().numpy().copy()
    qpos[:2] = tile.start[:2]  # at the trail's start, 22 m from its terminus
    frame = camera.frame(qpos, goal=0)
    assert frame.shape == (video.HEIGHT, video.WIDTH, 3) and frame.shape[:2] >= (480, 640)
    assert _close_to(frame, video.NEXT_WAYPOINT) > 20
    assert _close_to(frame, video.FLAG, tol=60) == 0  # the terminus is out of view
    camera.heading = None  # a jump: no smoothing from the last frame
    qpos[:2] = tile.terminus[:2] - [3.0, 0.0]
    near_end = camera.frame(qpos, goal=len(tile.waypoints) - 1)
    assert _close_to(near_end, video.FLAG, tol=60) > 50
    assert camera.model is not env.scene.model
    np.testing.assert_array_equal(env.scene.model.geom_group, groups)


def test_caption_and_depth_panel_are_burnt_in(filmed) -> None:
    """The caption changes the frame's pixels (and differs with its text); a depth frame
    adds the colour-mapped panel beside the view, brighter where it is near."""
    env, camera, *_ = filmed
    view = camera.frame(env.sim.qpos[0].cpu().numpy())
    line = video.caption_line("h1", "flat", 0, 1.25, 0.4)
    assert line.startswith("H1") and "flat" in line and "1.2 s" in line and "0.4 m" in line
    captioned = video.compose(view, line)
    assert captioned.shape == view.shape and not np.array_equal(captioned, view)
    assert not np.array_equal(captioned, video.compose(view, video.caption_line(
        "h1", "flat", 0, 2.5, 0.4)))
    depth = np.full((24, 32), 0.5)  # normalised: everything at the far plane ...
    depth[:, :16] = -0.5  # ... but the left half at 0 m
    both = video.compose(view, line, depth, far=3.0)
    assert both.shape == (video.HEIGHT, video.WIDTH + video.PANEL_WIDTH, 3)
    np.testing.assert_array_equal(both[: video.HEIGHT - 40, : video.WIDTH],
                                  captioned[: video.HEIGHT - 40])
    panel = both[:, video.WIDTH:].astype(int).sum(axis=-1)
    row = panel[video.HEIGHT // 3]
    assert row[video.PANEL_WIDTH // 2 - 40] > row[video.PANEL_WIDTH // 2 + 40]


def test_camera_heading_follows_the_trail_not_the_robot() -> None:
    """Along a straight leg the heading is the leg's, wherever beside it the robot stands;
    before a left bend it turns early (the chord to the point 2.5 m on); at the end it
    keeps the last leg's."""
    trail = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]])
    assert video._trail_heading(trail, np.array([3.0, -2.0]), 2.5) == pytest.approx(0.0)
    bend = video._trail_heading(trail, np.array([9.0, 0.0]), 2.5)
    assert bend == pytest.approx(np.arctan2(1.5, 1.0))
    assert video._trail_heading(trail, np.array([10.0, 12.0]), 2.5) == pytest.approx(np.pi / 2)


def test_a_trunk_between_the_camera_and_the_robot_is_seen_through() -> None:
    """Forest: with a trunk 1.8 m behind the robot (on the camera's side) it is drawn
    faded; with the robot 1.8 m before it (the trunk ahead), it is solid again."""
    cfg = compose_config("trail=forest", *TINY[1:])
    env = make_eval_env(OmegaConf.merge(cfg, {"eval": {"robots": 1}}))
    try:
        tile = env.terrain.tiles[int(env.reset()[keys.TILE][0])]
        camera = video.FollowCamera(
            video.render_model(OmegaConf.to_object(cfg.robot), env.terrain, cfg.sim.dt,
                               cfg.sim.hfield_chunk),
            env.robot.base_body, tile, env.robot.nominal_base_height)
        qpos = env.sim.qpos[0].cpu().numpy().copy()
        trunk = camera.trunks[0]
        for side in (1.8, -1.8):
            for _ in range(4):  # the camera's heading depends on where the robot stands
                az = np.radians(camera.cam.azimuth)
                qpos[:2] = camera.model.geom_pos[trunk, :2] + side * np.array([np.cos(az),
                                                                               np.sin(az)])
                camera.heading = None
                camera.frame(qpos)
            assert camera.model.geom_rgba[trunk, 3] == pytest.approx(
                video.SEE_THROUGH if side > 0 else 1.0)
        camera.close()
    finally:
        env.close()


@pytest.mark.skipif(importlib.util.find_spec("imageio_ffmpeg") is None,
                    reason="MP4 needs imageio-ffmpeg")
def test_videos_are_encoded_at_the_stated_rate_factor(tmp_path: Path) -> None:
    """x264 writes its settings into the stream: the film is at VIDEO_CRF (imageio's
    quality=7 meant crf 15, which made a 192 s film 26 MB)."""
    rng = np.random.default_rng(0)
    frames = [rng.integers(0, 255, (64, 64, 3), dtype=np.uint8) for _ in range(8)]
    path = video.write_video(frames, tmp_path / "clip.mp4", fps=10.0)
    assert path.suffix == ".mp4"
    assert f"crf={video.VIDEO_CRF}.0".encode() in path.read_bytes()


def test_play_film_picks_the_robot_whose_episode_ended_as_asked() -> None:
    """``play.film``: an index films that robot; an outcome films the earliest robot whose
    episode ended so (robot 0 when none did); anything else names the key and the choices."""
    from types import SimpleNamespace

    rollout = SimpleNamespace(outcome=["reached", "fell", "time-out", "fell"],
                              end=np.array([80, 120, 1500, 40]))
    assert play.pick_robot(rollout, "2") == 2 and play.pick_robot(rollout, 1) == 1
    assert play.pick_robot(rollout, "fell") == 3  # robot 3 fell first (step 40)
    assert play.pick_robot(rollout, "time-out") == 2
    assert play.pick_robot(SimpleNamespace(outcome=["reached"], end=np.array([9])),
                           "fell") == 0
    for bad in ("4", "-1", "falls"):
        with pytest.raises(ValueError, match=rf"play.film='{bad}'.*0..3.*play.robots=4"):
            play.pick_robot(rollout, bad)


def test_play_robots_must_be_a_count() -> None:
    """play.robots=0 fails at validation, naming the key, value and range."""
    from legoh.config import validate

    with pytest.raises(ValueError, match=r"play\.robots=0 .*1 <= x"):
        validate(compose_config("play.robots=0"))
