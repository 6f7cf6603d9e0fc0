"""mode=play: a policy's episode rendered headless (EGL) to a video and a filmstrip."""

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

from legoh import keys, play
from legoh.envs.robots import build_robot_spec
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
    video, strip = out / f"play{ext}", out / "play_filmstrip.png"
    assert video.stat().st_size > 0 and str(video) in proc.stdout and str(strip) in proc.stdout
    picture = imageio.imread(strip)
    assert picture.shape[0] == play.HEIGHT and picture.shape[1] > play.WIDTH
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
    assert len(frames) == result["frames"] and frames[0].shape[:2] == (play.HEIGHT,
                                                                       play.WIDTH)
    strip = imageio.imread(result["filmstrip"])
    assert strip.shape[1] == play.FILMSTRIP_FRAMES * play.WIDTH
    assert not np.array_equal(frames[0], np.zeros_like(frames[0]))


def test_play_refuses_a_student(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="oracle"):
        play.main(compose_config("algo=unified"), tmp_path)
