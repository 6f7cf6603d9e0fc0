"""``python run.py mode=play viewer=web [checkpoint=...] [trail=...]``: record the policy's
rollout, serve it (``legoh.viewer.server``), print the URL, serve until Ctrl-C or SIGTERM."""

from __future__ import annotations

import logging
import signal
import threading
from collections.abc import Sequence
from pathlib import Path

from omegaconf import DictConfig

from legoh.config.compose import CONF_DIR, compose_config
from legoh.play import PLAY_ROBOTS, Rollout, record_rollout
from legoh.viewer.server import WebViewer

# hike: the training map (all five categories, 100 tiles); the page offers its parts
TRAINING_ONLY = ("hike",)


def trail_names() -> list[str]:
    """The trails the page's selector offers: ``conf/trail/*.yaml``, the training map out."""
    names = sorted(p.stem for p in Path(CONF_DIR, "trail").glob("*.yaml"))
    return [n for n in names if n not in TRAINING_ONLY]


def for_trail(overrides: Sequence[str], trail: str) -> list[str]:
    """The command line's ``overrides`` with ``trail`` chosen instead of its trail; its
    ``trail.*`` settings (levels, variants, ...) carry over to the new one."""
    kept = [o for o in overrides if not o.lstrip("+~").startswith("trail=")]
    return [*kept, f"trail={trail}"]


def make_viewer(cfg: DictConfig, checkpoint: str | None, overrides: Sequence[str] = (),
                robots: int = PLAY_ROBOTS, seconds: float | None = None,
                level: int | None = None) -> WebViewer:
    """A running :class:`WebViewer` of ``checkpoint``'s policy (an untrained one without)
    on ``cfg``'s trail; ``overrides`` (the command line's) rebuild the config of another
    trail the page selects. ``robots``, ``seconds``, ``level``: as ``record_rollout``."""
    from legoh.config.algo import Stage
    from legoh.eval.cli import build_actor, for_checkpoint

    cfg, checkpoint = for_checkpoint(cfg, checkpoint)  # a student: its own camera
    policy, env_fn = build_actor(cfg, checkpoint)
    student = None if env_fn is None else policy
    actor = policy if student is None else student.policy

    def run(run_cfg: DictConfig, run_level: int) -> Rollout:
        # an oracle does not see depth: the env's camera is recorded to show what one would
        return record_rollout(run_cfg, actor, seconds, robots, run_level, student, depth=True)

    def compose(trail: str) -> DictConfig:
        return for_checkpoint(compose_config(*for_trail(overrides, trail)), checkpoint)[0]

    label = ("robot's depth view" if cfg.algo.stage != Stage.oracle
             else "env's depth camera (the oracle does not see it)")
    return WebViewer(cfg, run, compose, trail_names(), host=cfg.web.host, port=cfg.web.port,
                     level=level, depth_label=label)


def main(cfg: DictConfig, overrides: Sequence[str] = ()) -> None:
    """Serve ``cfg.checkpoint``'s rollout until Ctrl-C (SIGINT) or SIGTERM."""
    from legoh.play import warn_untrained

    checkpoint = cfg.checkpoint or None
    warn_untrained(checkpoint)
    # Hydra's console handler would print every page's connection and disconnection
    logging.getLogger("websockets").setLevel(logging.WARNING)
    print("[legoh] recording the rollout (the page replays it) ...", flush=True)
    viewer = make_viewer(cfg, checkpoint, overrides, robots=int(cfg.play.robots))
    stop = threading.Event()
    previous = {s: signal.signal(s, lambda *_: stop.set())
                for s in (signal.SIGINT, signal.SIGTERM)}
    print(f"[legoh] web viewer: {viewer.url}  (Ctrl-C ends it)", flush=True)
    try:
        while not stop.wait(0.5):  # a signal handler runs between these waits
            pass
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        viewer.close()
    print("[legoh] web viewer stopped", flush=True)
