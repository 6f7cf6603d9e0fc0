"""``mode=stand`` (legoh/stand.py): renders headless whatever the shell sets."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="EGL is the Linux default")
def test_stand_renders_headless_without_mujoco_gl(tmp_path: Path) -> None:
    """legoh.stand imported first, with no MUJOCO_GL and no display, still renders.

    Failed before with: mujoco.FatalError / GLFW "X11: The DISPLAY environment variable is
    missing" (stand.py set MUJOCO_GL after ``import mujoco``, too late)."""
    script = textwrap.dedent(f"""
        from pathlib import Path
        from legoh import stand
        from hydra import compose, initialize_config_dir
        from legoh.config import register_configs
        register_configs()
        with initialize_config_dir(config_dir={str(ROOT / "conf")!r}, version_base="1.3"):
            cfg = compose("config", overrides=["mode=stand", "stand_seconds=0.05"])
        stand.main(cfg, Path({str(tmp_path)!r}))
    """)
    env = {k: v for k, v in os.environ.items()
           if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM", "DISPLAY", "WAYLAND_DISPLAY")}
    env["OMP_NUM_THREADS"] = "1"
    done = subprocess.run([sys.executable, "-c", script], cwd=ROOT, env=env, text=True,
                          capture_output=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert (tmp_path / "h1_standing.png").stat().st_size > 0


def test_a_run_starts_without_third_party_log_lines(tmp_path: Path) -> None:
    """``python run.py`` prints only legoh's lines. Failed before with PyOpenGL's
    "[OpenGL.acceleratesupport][INFO] - No OpenGL_accelerate module loaded" at every start
    (Hydra's console handler shows INFO from any logger)."""
    done = subprocess.run([sys.executable, "run.py", "mode=stand", "stand_seconds=0.05",
                           f"hydra.run.dir={tmp_path}"], cwd=ROOT, text=True,
                          capture_output=True, timeout=300,
                          env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert done.returncode == 0, done.stderr[-2000:]
    lines = (done.stdout + done.stderr).splitlines()
    assert lines and all(line.startswith("[legoh]") for line in lines), lines
