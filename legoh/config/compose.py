"""The run config outside ``run.py``: Hydra's compose API on the repository's ``conf/``.

Tests, experiments and tools compose exactly what ``python run.py <overrides>`` would see::

    from legoh.config.compose import compose_config
    cfg = compose_config("robot=g1", "trail=flat", "algo.num_envs=8")
"""

from __future__ import annotations

from pathlib import Path

from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from omegaconf import DictConfig

from legoh.config import register_configs

CONF_DIR = str(Path(__file__).resolve().parents[2] / "conf")  # the repository's config tree


def compose_config(*overrides: str) -> DictConfig:
    """The config ``run.py`` would see for these command-line overrides (also from inside
    a running ``run.py``, whose Hydra already holds the same ``conf/``: the web viewer
    composes another trail's config that way)."""
    register_configs()
    if GlobalHydra.instance().is_initialized():
        return compose("config", overrides=list(overrides))
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        return compose("config", overrides=list(overrides))
