"""Run logs: per-iteration scalars to a CSV file, scalars and sampled trajectories to MCAP.

(Named ``logs`` so that ``import logging`` inside the package keeps meaning the standard
library.)

Durability: every row / message is flushed to the OS as it is written, so a run killed at
any point keeps everything logged before the kill (no fsync: a power cut may lose the
last seconds; a killed process does not).

CSV (:class:`ScalarCSV`): the first row fixes the columns (``iteration`` then the
scalar names, sorted). A later row with a **new** name widens the header, the earlier rows
blank in that column (a campaign resumed by newer code logs more); a missing name is
written as an empty cell; values are written at float32's precision, whole numbers exactly
(:func:`cell`). ``resume=True`` appends to an existing file under its header;
``resume=False`` refuses to overwrite one, naming the command that continues that run;
``until=N`` (a resumed run: its checkpoint's iteration) first drops rows after N, so the
file reads as one history.

MCAP (:class:`McapLog`): JSON messages with JSON-schema schemas on two channels,
``scalars`` (one message per iteration) and ``trajectory`` (one message per step of a
sampled robot trajectory: base pose, joint positions, goals). MCAP files cannot be
appended to (the summary and footer close the file), so each process start writes a new
segment ``<stem>-<NNN>.mcap`` (the next free NNN) beside earlier ones. Records are written
unchunked and flushed per message: a killed run leaves a segment without a footer, which
:func:`read_mcap` still reads (it falls back to a sequential read up to the cut).
"""

from __future__ import annotations

import csv
import json
import math
import re
import struct
import time
from collections.abc import Iterator, Mapping
from pathlib import Path
from types import TracebackType
from typing import BinaryIO

import numpy as np
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import Writer

ITERATION = "iteration"


def cell(value: float) -> str:
    """A scalar as a CSV cell: a whole number exactly (``912.0``: frame counts), anything
    else at float32's precision (the shortest text that reads back as the same float32):
    the losses and rates come from float32 tensors, and Python's 17-digit text of them
    made a 6M-frame study job's ``train.csv`` 26 MB, 16 with this (what git keeps of each
    recorded and parked job)."""
    value = float(value)
    if value.is_integer() or not math.isfinite(value) or abs(value) > FLOAT32_MAX:
        return repr(value)
    return str(np.float32(value))


FLOAT32_MAX = float(np.finfo(np.float32).max)


class ScalarCSV:
    """Append-only CSV of per-iteration scalars.

    Args:
        path: the CSV file. resume: append to an existing file (its header is kept);
            when False an existing file is an error.
        until: with ``resume``, first drop the rows after this iteration: those a killed
            run logged past its last checkpoint, which the resumed run logs again.
    """

    def __init__(self, path: str | Path, resume: bool = False, until: int | None = None
                 ) -> None:
        self.path = Path(path)
        self.columns: list[str] | None = None
        if self.path.exists() and self.path.stat().st_size > 0:
            if not resume:
                raise FileExistsError(f"{self.path} exists: another run wrote into this "
                                      f"folder. {_continue_hint(self.path.parent)}")
            if until is not None:
                cut_rows_after(self.path, until)
            with self.path.open(newline="", encoding="utf-8") as f:
                self.columns = next(csv.reader(f))
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = self.path.open("a", newline="", encoding="utf-8")
        self._writer = csv.writer(self._file)

    def write(self, iteration: int, scalars: Mapping[str, float]) -> None:
        """Append one row; the first row (of a fresh file) fixes the columns."""
        if self.columns is None:
            self.columns = [ITERATION, *sorted(scalars)]
            self._writer.writerow(self.columns)
        new = sorted(set(scalars) - set(self.columns))
        if new:  # a campaign resumed by newer code logs more: widen, earlier rows blank
            self._widen(new)
        row = {**{k: cell(v) for k, v in scalars.items()}, ITERATION: int(iteration)}
        self._writer.writerow([row.get(c, "") for c in self.columns])
        self._file.flush()

    def _widen(self, new: list[str]) -> None:
        """Rewrite the file (atomically) with ``new`` columns appended to the header."""
        self._file.close()
        with self.path.open(newline="", encoding="utf-8") as f:
            header, *rows = list(csv.reader(f))
        self.columns = [*header, *new]
        tmp = self.path.with_name(f".{self.path.name}.tmp")
        with tmp.open("w", newline="", encoding="utf-8") as f:
            csv.writer(f).writerows([self.columns, *(r + [""] * len(new) for r in rows)])
        tmp.replace(self.path)
        self._file = self.path.open("a", newline="", encoding="utf-8")
        self._writer = csv.writer(self._file)

    def close(self) -> None:
        """Close the file (rows are already flushed)."""
        self._file.close()

    def __enter__(self) -> ScalarCSV:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def cut_rows_after(path: Path, iteration: int) -> None:
    """Rewrite a scalar CSV without its rows after ``iteration`` (atomically; untouched when
    there are none), saying which were dropped."""
    with path.open(newline="", encoding="utf-8") as f:
        header, *rows = list(csv.reader(f))
    keep = [r for r in rows if r and int(r[0]) <= iteration]
    if len(keep) == len(rows):
        return
    tmp = path.with_name(f".{path.name}.tmp")
    with tmp.open("w", newline="", encoding="utf-8") as f:
        csv.writer(f).writerows([header, *keep])
    tmp.replace(path)
    dropped = [r[0] for r in rows if r and int(r[0]) > iteration]
    print(f"[legoh] {path}: dropped iteration(s) {dropped[0]}-{dropped[-1]} logged after the "
          f"checkpoint (iteration {iteration}); the resumed run logs them again")


def _continue_hint(folder: Path) -> str:
    """The command that continues the run in ``folder`` (its checkpoint named when there is
    one), or how to start a fresh run elsewhere."""
    ckpt = next(iter(sorted(folder.glob("*.pt"))), folder / "<checkpoint>.pt")
    return (f"Continue it with `python run.py <its overrides> resume={ckpt}`, or start a "
            f"new run in another folder (hydra.run.dir=...)")


SCALARS_SCHEMA = {
    "title": "legoh.Scalars", "type": "object",
    "properties": {
        "iteration": {"type": "integer"},
        "wall_time": {"type": "number", "description": "s since the epoch"},
        "scalars": {"type": "object", "additionalProperties": {"type": ["number", "null"]}},
    },
    "required": ["iteration", "scalars"],
}

TRAJECTORY_SCHEMA = {
    "title": "legoh.TrajectoryStep", "type": "object",
    "properties": {
        "iteration": {"type": "integer"},
        "env": {"type": "integer", "description": "index of the robot in the batch"},
        "step": {"type": "integer"},
        "time": {"type": "number", "description": "s since the trajectory's start"},
        "base_pos": {"type": "array", "items": {"type": "number"}, "minItems": 3,
                     "maxItems": 3, "description": "world frame, m"},
        "base_quat": {"type": "array", "items": {"type": "number"}, "minItems": 4,
                      "maxItems": 4, "description": "world frame, w x y z"},
        "joint_pos": {"type": "array", "items": {"type": "number"}, "description": "rad"},
        "goals": {"type": "array", "description": "(G, 2) goals, robot yaw frame, m",
                  "items": {"type": "array", "items": {"type": "number"}}},
    },
    "required": ["iteration", "env", "step", "time", "base_pos", "base_quat", "joint_pos",
                 "goals"],
}

SCALARS_TOPIC, TRAJECTORY_TOPIC = "scalars", "trajectory"


def _finite(x: float) -> float | None:
    """JSON has no NaN/inf: they become null."""
    x = float(x)
    return x if math.isfinite(x) else None


class McapLog:
    """One MCAP segment per process start in ``directory``: ``<stem>-<NNN>.mcap``.

    Args:
        directory: where segments live (created). stem: file name stem.
    """

    def __init__(self, directory: str | Path, stem: str = "log") -> None:
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        taken = [int(m.group(1)) for p in directory.glob(f"{stem}-*.mcap")
                 if (m := re.fullmatch(rf"{re.escape(stem)}-(\d+)\.mcap", p.name))]
        self.path = directory / f"{stem}-{max(taken, default=-1) + 1:03d}.mcap"
        self._file = self.path.open("xb")
        self._writer = Writer(self._file, use_chunking=False)
        self._writer.start(profile="", library="legoh")
        self._channels = {}
        for topic, schema in ((SCALARS_TOPIC, SCALARS_SCHEMA),
                              (TRAJECTORY_TOPIC, TRAJECTORY_SCHEMA)):
            sid = self._writer.register_schema(schema["title"], "jsonschema",
                                               json.dumps(schema).encode())
            self._channels[topic] = self._writer.register_channel(topic, "json", sid)
        self._seq = 0
        self._file.flush()

    def _put(self, topic: str, msg: dict, log_time_ns: int) -> None:
        self._writer.add_message(self._channels[topic], log_time=log_time_ns,
                                 data=json.dumps(msg).encode(), publish_time=log_time_ns,
                                 sequence=self._seq)
        self._seq += 1

    def log_scalars(self, iteration: int, scalars: Mapping[str, float]) -> None:
        """One ``scalars`` message; NaN/inf become null."""
        now = time.time_ns()
        self._put(SCALARS_TOPIC, {"iteration": int(iteration), "wall_time": now / 1e9,
                                  "scalars": {k: _finite(v) for k, v in scalars.items()}},
                  now)
        self._file.flush()

    def log_trajectory(self, iteration: int, base_pos: np.ndarray, base_quat: np.ndarray,
                       joint_pos: np.ndarray, goals: np.ndarray, dt: float,
                       env: int = 0) -> None:
        """One ``trajectory`` message per step of one robot's trajectory.

        Args:
            base_pos: (T, 3) m. base_quat: (T, 4) w x y z. joint_pos: (T, J) rad.
            goals: (T, G, 2) m (e.g. the expert goals). dt: step, s. env: robot index.
            Log times are the wall clock at the call plus ``step * dt``, so viewers play
            the trajectory back at its own pace.
        """
        arrs = [np.asarray(a, dtype=float) for a in (base_pos, base_quat, joint_pos, goals)]
        steps = {a.shape[0] for a in arrs}
        if len(steps) != 1:
            raise ValueError(f"trajectory arrays differ in length: {[a.shape for a in arrs]}")
        start = time.time_ns()
        for t, (p, q, j, g) in enumerate(zip(*arrs, strict=True)):
            self._put(TRAJECTORY_TOPIC, {
                "iteration": int(iteration), "env": int(env), "step": t, "time": t * dt,
                "base_pos": p.tolist(), "base_quat": q.tolist(), "joint_pos": j.tolist(),
                "goals": g.tolist()}, start + int(round(t * dt * 1e9)))
        self._file.flush()

    def close(self) -> None:
        """Write the summary and footer (a segment without them is still readable)."""
        if not self._file.closed:
            self._writer.finish()
            self._file.close()

    def __enter__(self) -> McapLog:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


def read_mcap(path: str | Path) -> Iterator[tuple[str, str, dict]]:
    """Yield ``(topic, schema name, decoded message)`` of a segment, in file order.

    A finished segment is read through its index (``mcap.reader.make_reader``); one cut
    short by a killed process is read sequentially up to the cut.
    """
    with Path(path).open("rb") as f:
        try:
            reader = make_reader(f)
            reader.get_summary()
            items = list(reader.iter_messages(log_time_order=False))
        except McapError:
            f.seek(0)
            items = _read_until_cut(f)
    for schema, channel, message in items:
        yield channel.topic, schema.name, json.loads(message.data)


def _read_until_cut(f: BinaryIO) -> list[tuple[Schema, Channel, Message]]:
    """Records of an unfinished, unchunked segment, read in order up to where it stops."""
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    items = []
    try:
        for rec in StreamReader(f).records:
            if isinstance(rec, Schema):
                schemas[rec.id] = rec
            elif isinstance(rec, Channel):
                channels[rec.id] = rec
            elif isinstance(rec, Message):
                channel = channels[rec.channel_id]
                items.append((schemas[channel.schema_id], channel, rec))
    except (McapError, struct.error):
        pass  # the cut: a missing footer or a half-written last record
    return items
