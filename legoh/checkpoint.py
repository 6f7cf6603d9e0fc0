"""Checkpoints: written atomically, refused when they belong to another robot or layout.

A checkpoint is one ``torch.save`` file holding a dict (see :func:`make_payload`):

- ``format``: :data:`FORMAT_VERSION`
- ``models`` / ``optimizers``: name -> state dict
- ``iteration``: int; ``curriculum``: dict (levels etc., plain values or tensors)
- ``rng``: torch, numpy (global legacy generator) and Python ``random`` states
- ``config``: the resolved config as plain containers (``OmegaConf.to_container``)
- ``robot``: the robot's name; ``layout``: observation key -> per-env shape

Writes go to a temporary file in the same directory, which is flushed, fsynced and then
moved over the target with ``os.replace`` (atomic on POSIX and Windows), so a crash leaves
either the old checkpoint or the new one, never a partial file. Loads use
``torch.load(weights_only=True)``: only tensors and plain containers are unpickled (the
numpy RNG state is stored as a tensor for that reason).

Integrity: ``torch.load`` does not check the CRC32 its zip container stores per entry, so
bytes damaged on disk or in a copy would load as wild weights (a 5e34 reaching Adam). A load
first checks every entry's CRC (:func:`verify_zip`), then refuses any floating tensor that
is non-finite or larger than :data:`ABSURD` in magnitude, naming the file and the tensor.
"""

from __future__ import annotations

import os
import random
import tempfile
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch

FORMAT_VERSION = 1
REQUIRED = ("format", "models", "iteration", "robot", "layout")
# |value| above which a stored float is damage, not training: weights and Adam moments of a
# run with gradient clipping stay many orders below, while random bytes read as float32
# mostly land far above (up to 3e38) or are caught by the CRC anyway.
ABSURD = 1e10


class CheckpointError(RuntimeError):
    """A checkpoint that cannot be used: corrupt, or made for another robot or layout."""


def rng_state() -> dict[str, Any]:
    """The torch, numpy (global) and Python ``random`` RNG states, as safe-to-load values."""
    _, key, pos, has_gauss, gauss = np.random.get_state(legacy=True)
    return {"torch": torch.get_rng_state(),
            "numpy": {"key": torch.from_numpy(key.astype(np.int64)), "pos": int(pos),
                      "has_gauss": int(has_gauss), "cached_gaussian": float(gauss)},
            "python": random.getstate()}


def restore_rng(state: Mapping[str, Any]) -> None:
    """Set the RNGs back to a state from :func:`rng_state`."""
    torch.set_rng_state(state["torch"])
    n = state["numpy"]
    np.random.set_state(("MT19937", n["key"].numpy().astype(np.uint32), n["pos"],
                         n["has_gauss"], n["cached_gaussian"]))
    py = state["python"]
    random.setstate((py[0], tuple(py[1]), py[2]))


def normalize_layout(layout: Mapping) -> dict[str, tuple[int, ...]]:
    """Layout as ``{"obs/proprio": (63,), ...}``: tuple keys joined by '/', shapes tuples."""
    return {"/".join(k) if isinstance(k, tuple) else str(k): tuple(int(d) for d in v)
            for k, v in layout.items()}


def make_payload(*, models: Mapping[str, torch.nn.Module],
                 optimizers: Mapping[str, torch.optim.Optimizer] | None = None,
                 iteration: int, robot: str, layout: Mapping,
                 curriculum: Mapping | None = None, config: Mapping | None = None,
                 extra: Mapping | None = None) -> dict[str, Any]:
    """Assemble a checkpoint payload; RNG states are captured now.

    Args:
        models / optimizers: name -> module / optimizer (their state dicts are stored), or
            name -> state dict (an algorithm's ``state_dict()``).
        iteration: the last completed iteration. robot: robot name (e.g. ``"h1"``).
        layout: observation key -> per-env shape (e.g. ``OracleInputDims.as_layout()``).
        curriculum: curriculum state. config: resolved config (plain containers).
        extra: anything else to keep (plain values or tensors).
    """
    return {
        "format": FORMAT_VERSION,
        "models": {k: _state_of(m) for k, m in models.items()},
        "optimizers": {k: _state_of(o) for k, o in (optimizers or {}).items()},
        "iteration": int(iteration),
        "curriculum": dict(curriculum or {}),
        "rng": rng_state(),
        "config": dict(config or {}),
        "robot": str(robot),
        "layout": normalize_layout(layout),
        "extra": dict(extra or {}),
    }


def _state_of(obj: Any) -> Mapping:
    return obj if isinstance(obj, Mapping) else obj.state_dict()


def save_checkpoint(path: str | Path, payload: Mapping[str, Any]) -> Path:
    """Write ``payload`` to ``path`` atomically (temp file, fsync, ``os.replace``).

    Raises ``ValueError`` when a required key (:data:`REQUIRED`) is missing; on any
    failure while writing, the temporary file is removed and ``path`` is left untouched.
    """
    missing = [k for k in REQUIRED if k not in payload]
    if missing:
        raise ValueError(f"checkpoint payload lacks {missing}; build it with make_payload()")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            torch.save(dict(payload), f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    if hasattr(os, "O_DIRECTORY"):  # make the rename itself durable
        dir_fd = os.open(path.parent, os.O_RDONLY | os.O_DIRECTORY)
        try:
            os.fsync(dir_fd)
        finally:
            os.close(dir_fd)
    return path


def load_checkpoint(path: str | Path, expect_robot: str | None = None,
                    expect_layout: Mapping | None = None,
                    map_location: str | torch.device = "cpu") -> dict[str, Any]:
    """Read a checkpoint and check that it fits this run.

    Args:
        expect_robot: refuse a checkpoint trained on another robot (None: no check).
        expect_layout: refuse one whose observation layout differs (None: no check).

    Raises:
        FileNotFoundError: no file at ``path``.
        CheckpointError: unreadable (corrupt, truncated, not a legoh checkpoint), damaged
            (a zip entry fails its CRC; a tensor is non-finite or absurd: the message names
            it), or made for another robot or observation layout (the message names both).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no checkpoint at {path}")
    verify_zip(path)
    try:
        payload = torch.load(path, map_location=map_location, weights_only=True)
    except Exception as err:
        raise CheckpointError(f"{path} is not a readable checkpoint (corrupt or truncated?): "
                              f"{type(err).__name__}: {err}") from err
    if not isinstance(payload, dict) or any(k not in payload for k in REQUIRED):
        raise CheckpointError(f"{path} is not a legoh checkpoint (expected keys {REQUIRED})")
    check_values(path, payload)
    if payload["format"] != FORMAT_VERSION:
        raise CheckpointError(f"{path} has format {payload['format']}, this code reads "
                              f"{FORMAT_VERSION}")
    if expect_robot is not None and payload["robot"] != expect_robot:
        raise CheckpointError(f"{path} was trained on robot {payload['robot']!r}, "
                              f"but this run uses robot {expect_robot!r}")
    if expect_layout is not None:
        check_layout(path, expect_layout, payload["layout"])
    return payload


def check_layout(path: str | Path, expect: Mapping, layout: Mapping) -> None:
    """Refuse a checkpoint at ``path`` whose observation ``layout`` differs from
    ``expect``, naming the differing keys."""
    want, have = normalize_layout(expect), normalize_layout(layout)
    if want != have:
        diff = sorted(k for k in set(want) | set(have) if want.get(k) != have.get(k))
        raise CheckpointError(f"{path} has observation layout {have}, but this run has "
                              f"{want} (differing keys: {diff})")


def verify_zip(path: Path) -> None:
    """Refuse a checkpoint whose zip container is unreadable or has an entry failing its CRC.

    Raises ``CheckpointError`` naming the file and the damaged entry (``<archive>/data/N`` is
    a tensor storage, ``data.pkl`` the structure).
    """
    try:
        with zipfile.ZipFile(path) as archive:
            bad = archive.testzip()
    except (zipfile.BadZipFile, OSError, EOFError) as err:
        raise CheckpointError(f"{path} is not a readable checkpoint (corrupt or truncated?): "
                              f"{type(err).__name__}: {err}") from err
    if bad is not None:
        raise CheckpointError(f"{path} is damaged: zip entry {bad!r} fails its CRC check "
                              f"(the file changed after it was written; use an older copy)")


def check_values(path: Path, payload: Any, where: str = "") -> None:
    """Refuse non-finite or absurd (> :data:`ABSURD`) floating tensors, naming the first.

    ``where`` is the dotted location inside the payload, e.g. ``models/actor/0.weight``.
    """
    if isinstance(payload, torch.Tensor):
        if payload.is_floating_point() and payload.numel():
            finite = torch.isfinite(payload)
            if not bool(finite.all()):
                raise CheckpointError(f"{path}: tensor {where} holds non-finite values "
                                      f"({int((~finite).sum())} of {payload.numel()})")
            peak = float(payload.abs().max())
            if peak > ABSURD:
                raise CheckpointError(f"{path}: tensor {where} holds magnitude {peak:.3g}, above "
                                      f"{ABSURD:.0e}: damaged or from a diverged run")
    elif isinstance(payload, Mapping):
        for key, value in payload.items():
            check_values(path, value, f"{where}/{key}".lstrip("/"))
    elif isinstance(payload, list | tuple):
        for i, value in enumerate(payload):
            check_values(path, value, f"{where}/{i}".lstrip("/"))
