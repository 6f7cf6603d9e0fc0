"""legoh entry point: compose the config, then run the chosen stage.

    python run.py                      # default: robot=h1 trail=randommix algo=oracle
    python run.py robot=g1 trail=ditch
"""

import logging
import os
import sys

if sys.platform.startswith("linux"):  # headless rendering (stand, play): before mujoco loads
    os.environ.setdefault("MUJOCO_GL", "egl")
# PyOpenGL (mujoco's renderer imports it) logs at INFO whether its optional accelerator
# loaded; Hydra's console handler would print that line at the start of every run
logging.getLogger("OpenGL.acceleratesupport").setLevel(logging.WARNING)

import hydra  # noqa: E402
from omegaconf import DictConfig  # noqa: E402

from legoh.config import register_configs  # noqa: E402

register_configs()


@hydra.main(version_base="1.3", config_path="conf", config_name="config")
def main(cfg: DictConfig) -> None:
    from legoh.app import run

    run(cfg)


if __name__ == "__main__":
    main()
