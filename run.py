"""legoh entry point: compose the config, then run the chosen stage.

    python run.py                      # default: robot=h1 trail=randommix algo=oracle
    python run.py robot=g1 trail=ditch
"""

import hydra
from omegaconf import DictConfig

from legoh.config import register_configs

register_configs()


@hydra.main(version_base="1.3", config_path="conf", config_name="config")
def main(cfg: DictConfig) -> None:
    from legoh.app import run

    run(cfg)


if __name__ == "__main__":
    main()
