"""The policies the repository ships: ``pretrained/<robot>_<stage>.pt``."""

from __future__ import annotations

from pathlib import Path

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


def shipped_oracle(robot: str) -> Path | None:
    """``pretrained/<robot>_oracle.pt`` when the repository ships one, else None."""
    try:
        return pretrained_path(robot)
    except FileNotFoundError:
        return None
