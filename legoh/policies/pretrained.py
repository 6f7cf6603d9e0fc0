"""The policies the repository ships: ``pretrained/<robot>_<stage>.pt``."""

from __future__ import annotations

import json
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from legoh.eval.protocol import LEGACY, PROTOCOL, warn_if_other

PRETRAINED_DIR = Path(__file__).resolve().parents[2] / "pretrained"


def pretrained_path(robot: str, stage: str = "oracle") -> Path:
    """``pretrained/<robot>_<stage>.pt``, the file ``init=pretrained`` and
    ``checkpoint=pretrained`` pick."""
    path = PRETRAINED_DIR / f"{robot}_{stage}.pt"
    if not path.is_file():
        have = sorted(p.name for p in PRETRAINED_DIR.glob("*.pt"))
        raise FileNotFoundError(f"no pretrained {stage} for robot {robot!r} at {path} "
                                f"(shipped: {have})")
    return path


def resolve_checkpoint(value: str, robot: str, stage: str = "oracle") -> Path:
    """A checkpoint setting: ``pretrained`` (the shipped file of the robot) or a path."""
    return pretrained_path(robot, stage) if value == "pretrained" else Path(value)


def shipped_stage(cfg: DictConfig) -> str:
    """Which shipped file ``checkpoint=pretrained`` means under ``cfg.algo``: ``oracle`` for
    stage 1, else the variant's name (``unified``, ``ep_h``, ...): ``<robot>_<name>.pt``."""
    return "oracle" if str(cfg.algo.stage) == "oracle" else str(cfg.algo.name)


def shipped_oracle(robot: str) -> Path | None:
    """``pretrained/<robot>_oracle.pt`` when the repository ships one, else None."""
    return shipped(robot, "oracle")


def shipped(robot: str, stage: str) -> Path | None:
    """``pretrained/<robot>_<stage>.pt`` when the repository ships one, else None."""
    try:
        return pretrained_path(robot, stage)
    except FileNotFoundError:
        return None


def init_checkpoint(value: str | None, robot: str, stage: str = "oracle") -> Path | None:
    """The checkpoint an ``init=`` setting starts a run of ``stage`` from (``oracle``, or a
    student's name: ``unified``, ``ep_h``, ...): None for ``none`` (or null); for
    ``pretrained``, the robot's shipped file of that stage, or None (from scratch, said on
    the console) when it ships none; else the path."""
    if value is None or str(value).lower() in ("none", "null", ""):
        return None
    if value != "pretrained":
        return Path(value)
    path = shipped(robot, stage)
    if path is None:
        print(f"[legoh] init=pretrained: no pretrained {stage} ships for robot {robot!r} "
              f"({PRETRAINED_DIR}); training from scratch")
    return path


def benchmark_protocol(cfg: DictConfig) -> dict:
    """What makes two benchmark tables comparable: the protocol's version
    (``legoh.eval.protocol``), robot, trail, the ``eval`` settings and the seed the
    evaluation follows."""
    return {"version": PROTOCOL, "robot": str(cfg.robot.name), "trail": str(cfg.trail.name),
            "seed": int(cfg.seed), "eval": OmegaConf.to_container(cfg.eval, resolve=True)}


def shipped_reference(cfg: DictConfig, stage: str = "oracle") -> dict | None:
    """The shipped policy's own rows (``{"overall" | "level <l>": {metric: [mean, std]}}``)
    on this run's benchmark protocol, from its card ``pretrained/<robot>_<stage>.json``
    (``experiments/ship_pretrained.py`` records the main job's protocol there); None when no
    card records this protocol. A card scored on another protocol version says so (a
    warning naming both versions)."""
    card = PRETRAINED_DIR / f"{cfg.robot.name}_{stage}.json"
    if not card.is_file():
        return None
    ref = json.loads(card.read_text()).get("main_job")
    if not ref:
        return None
    if not warn_if_other(f"{card}'s main_job reference", ref["protocol"].get("version", LEGACY)):
        return None
    if ref["protocol"] != benchmark_protocol(cfg):
        return None
    return ref["rows"]
