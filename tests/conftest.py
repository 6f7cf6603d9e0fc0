"""Shared fixtures: composed configs through Hydra's compose API (the same path as run.py)."""

import os
from pathlib import Path

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")
# MuJoCo Warp's compiled kernels, kept between runs (the first compile takes minutes)
os.environ.setdefault("WARP_CACHE_PATH", str(Path(__file__).resolve().parents[1] / ".warp_cache"))

from legoh.config import register_configs  # noqa: E402
from legoh.config.compose import CONF_DIR, compose_config  # noqa: E402, F401 (tests import them)

register_configs()


@pytest.fixture(autouse=True, scope="module")
def _release_memory_after_each_module():
    """Give a test module's memory back to the OS when it ends: an xdist worker runs ~40
    modules of envs, renderers and models, and glibc keeps freed arenas mapped, so two
    workers reached 8.5 + 10.7 GB resident and the kernel killed one (2026-12-06, 24 GB)."""
    yield
    import ctypes
    import gc

    gc.collect()
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except OSError:  # not glibc (macOS): nothing to trim
        pass


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--update-snapshots", action="store_true",
                     help="rewrite tests/snapshots/*.yaml from the current configs")
    parser.addoption("--warp-device", default=os.environ.get("LEGOH_WARP_DEVICE", "cpu"),
                     help="Warp device of tests/test_warp_sim.py: cpu (default) | cuda | cuda:N")


@pytest.fixture
def update_snapshots(request: pytest.FixtureRequest) -> bool:
    return bool(request.config.getoption("--update-snapshots"))


@pytest.fixture
def copying_collector(monkeypatch) -> None:
    """From now on the in-process collector is torchrl's default, which yields a fresh copy
    of each batch (legoh's yields its own buffer: ``train/collect.py``)."""
    from torchrl.collectors import Collector

    from legoh.train import collect

    class Copying(Collector):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **{**kwargs, "return_same_td": False})

    monkeypatch.setattr(collect, "Collector", Copying)
