"""Shared fixtures: composed configs through Hydra's compose API (the same path as run.py)."""

import os
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import DictConfig

os.environ.setdefault("MUJOCO_GL", "egl")
# MuJoCo Warp's compiled kernels, kept between runs (the first compile takes minutes)
os.environ.setdefault("WARP_CACHE_PATH", str(Path(__file__).resolve().parents[1] / ".warp_cache"))

from legoh.config import register_configs  # noqa: E402

CONF_DIR = str(Path(__file__).resolve().parents[1] / "conf")
register_configs()


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--update-snapshots", action="store_true",
                     help="rewrite tests/snapshots/*.yaml from the current configs")
    parser.addoption("--warp-device", default=os.environ.get("LEGOH_WARP_DEVICE", "cpu"),
                     help="Warp device of tests/test_warp_sim.py: cpu (default) | cuda | cuda:N")


@pytest.fixture
def update_snapshots(request: pytest.FixtureRequest) -> bool:
    return bool(request.config.getoption("--update-snapshots"))


def compose_config(*overrides: str) -> DictConfig:
    """The config run.py would see for these command-line overrides."""
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        return compose("config", overrides=list(overrides))
