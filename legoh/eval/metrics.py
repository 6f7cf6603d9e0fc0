"""The paper's benchmark metrics (SR, TC, TR, MEV, TTF, T2R), and our DW, as plain functions.

Formulas and the choices the paper leaves open are in ``docs/metrics.md``. In short, each
robot's **first episode** in the record counts (the steps up to and including its first
``done``; a robot never done counts as a timeout at the record's end), and

- SR  (%)  = 100 * mean_n success_n, success_n = reached at the episode's last step
- TC  (%)  = 100 * mean_n passed_n / count_n, passed_n = max waypoint index reached in the
             episode (count_n for a success)
- TR  (%)  = 100 * mean_n final progress_n (1 for a success)
- MEV (%)  = 100 * (sum edge foot-contacts + sum unsafe-collision steps)
                  / (sum foot-contacts + sum unsafe-collision steps), pooled over robots
- TTF (s)  = mean_n episode duration_n (the time of the fall, or of the reach, or the
             episode length for robots that neither fall nor reach)
- T2R (s)  = mean over successful robots of the episode duration (NaN if none succeeded)
- DW  (m)  = mean_n distance walked toward the terminus: |start_n - terminus_n| -
             |end_n - terminus_n| in xy (NaN when the record has no positions)

Inputs are per-step arrays of shape (T, N): the ``("next", "info", ...)`` signals of each
step (the state the step led to, before any auto-reset) and ``("next", "done")``; DW
also needs each robot's start and end positions (:func:`distance_walked`).
"""

from __future__ import annotations

import csv
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

METRICS = ("SR", "TC", "TR", "MEV", "TTF", "T2R", "DW")
UNITS = {"SR": "%", "TC": "%", "TR": "%", "MEV": "%", "TTF": "s", "T2R": "s", "DW": "m"}
HIGHER_IS_BETTER = {"SR": True, "TC": True, "TR": True, "MEV": False, "TTF": True,
                    "T2R": False, "DW": True}
SIGNALS = ("reached", "fell", "waypoint", "progress", "edge_contacts", "foot_contacts",
           "unsafe_collisions")


def column_title(metric: str) -> str:
    """Table header of a metric, e.g. ``"SR (%) ↑"``, ``"MEV (%) ↓"``."""
    return f"{metric} ({UNITS[metric]}) {'↑' if HIGHER_IS_BETTER[metric] else '↓'}"


@dataclass(frozen=True)
class RobotOutcomes:
    """Per-robot results of the first episode, each (N,)."""

    success: np.ndarray  # bool: reached the terminus
    fall: np.ndarray  # bool: ended by a fall (and not by reaching)
    duration: np.ndarray  # s: time from the start to the episode's end
    completion: np.ndarray  # [0, 1]: expert waypoints passed / waypoints of the trail
    traverse: np.ndarray  # [0, 1]: final progress along the trail (1 for a success)
    violations: np.ndarray  # edge foot-contacts + unsafe-collision steps
    contacts: np.ndarray  # foot-contacts + unsafe-collision steps
    distance: np.ndarray  # m: distance walked toward the terminus (NaN: no positions)


def distance_walked(start_xy: np.ndarray, end_xy: np.ndarray, terminus_xy: np.ndarray
                    ) -> np.ndarray:
    """Metres each robot got closer to its terminus: straight-line xy distance from the
    start minus that from the end position (negative: it moved away). Unlike TTF, it does
    not credit a robot that merely stands until the time-out.

    Args:
        start_xy, end_xy, terminus_xy: (N, 2) (or (N, >=2): only x, y are read), world
            frame, m. end_xy: where the robot is when its first episode ends.

    Returns:
        (N,) float, m.
    """
    start, end, goal = (np.asarray(a, dtype=float)[..., :2]
                        for a in (start_xy, end_xy, terminus_xy))
    return np.linalg.norm(goal - start, axis=-1) - np.linalg.norm(goal - end, axis=-1)


def robot_outcomes(*, reached: np.ndarray, fell: np.ndarray, waypoint: np.ndarray,
                   progress: np.ndarray, edge_contacts: np.ndarray,
                   foot_contacts: np.ndarray, unsafe_collisions: np.ndarray,
                   done: np.ndarray, waypoint_count: np.ndarray | int, dt: float,
                   distance: np.ndarray | None = None) -> RobotOutcomes:
    """Per-robot outcomes of each robot's first episode.

    Args:
        reached, fell, done: (T, N) bool. waypoint: (T, N) int, index of the current expert
            waypoint (= waypoints passed). progress: (T, N) float in [0, 1].
        edge_contacts, foot_contacts: (T, N) int, feet in contact (on an edge / at all).
        unsafe_collisions: (T, N) int, non-foot bodies touching the world.
        waypoint_count: (N,) or scalar, waypoints of each robot's trail (the terminus is
            the last one). dt: policy step, s.
        distance: (N,) m, :func:`distance_walked` of each robot's first episode; the
            signals carry no positions, so without it DW is NaN.
    """
    arrs = [np.asarray(a) for a in (reached, fell, waypoint, progress, edge_contacts,
                                    foot_contacts, unsafe_collisions, done)]
    shape = arrs[0].shape
    if len(shape) != 2 or any(a.shape != shape for a in arrs):
        raise ValueError(f"all signals must share one (T, N) shape, got "
                         f"{[a.shape for a in arrs]}")
    reached, fell, waypoint, progress, edge, feet, unsafe, done = arrs
    t_len, n = shape
    done = done.astype(bool)
    ended = done.any(axis=0)
    last = np.where(ended, done.argmax(axis=0), t_len - 1)  # (N,) index of the final step
    in_episode = np.arange(t_len)[:, None] <= last[None, :]  # (T, N)
    cols = np.arange(n)
    success = reached.astype(bool)[last, cols]
    fall = fell.astype(bool)[last, cols] & ended & ~success
    count = np.broadcast_to(np.asarray(waypoint_count), (n,)).astype(float)
    passed = np.where(in_episode, waypoint, 0).max(axis=0)
    completion = np.where(success, 1.0, np.clip(passed / np.maximum(count, 1.0), 0.0, 1.0))
    traverse = np.where(success, 1.0, np.clip(progress[last, cols], 0.0, 1.0))
    unsafe_steps = np.where(in_episode, unsafe > 0, False).sum(axis=0)
    violations = np.where(in_episode, edge, 0).sum(axis=0) + unsafe_steps
    contacts = np.where(in_episode, feet, 0).sum(axis=0) + unsafe_steps
    return RobotOutcomes(success=success, fall=fall, duration=(last + 1) * float(dt),
                         completion=completion, traverse=traverse,
                         violations=violations.astype(float), contacts=contacts.astype(float),
                         distance=(np.full(n, np.nan) if distance is None
                                   else np.broadcast_to(np.asarray(distance, float), (n,))))


def aggregate(out: RobotOutcomes, select: np.ndarray | None = None) -> dict[str, float]:
    """Metric -> value over the robots in ``select`` ((N,) bool; all when None)."""
    sel = np.ones_like(out.success, dtype=bool) if select is None else np.asarray(select, bool)
    if not sel.any():
        return dict.fromkeys(METRICS, float("nan"))
    contacts = out.contacts[sel].sum()
    wins = out.success & sel
    return {
        "SR": 100.0 * out.success[sel].mean(),
        "TC": 100.0 * out.completion[sel].mean(),
        "TR": 100.0 * out.traverse[sel].mean(),
        "MEV": 100.0 * out.violations[sel].sum() / contacts if contacts > 0 else 0.0,
        "TTF": float(out.duration[sel].mean()),
        "T2R": float(out.duration[wins].mean()) if wins.any() else float("nan"),
        "DW": float(out.distance[sel].mean()),
    }


def episode_metrics(*, waypoint_count: np.ndarray | int, dt: float, groups=None,
                    **signals: np.ndarray) -> dict:
    """The metrics of one run (DW is NaN: the signals carry no positions).

    Args:
        waypoint_count, dt, signals: as :func:`robot_outcomes` (``reached``, ``fell``,
            ``waypoint``, ``progress``, ``edge_contacts``, ``foot_contacts``,
            ``unsafe_collisions``, ``done``; each (T, N)).
        groups: optional (N,) labels (for example trail category names): then the result
            is ``{label: metrics}`` per label, as in the paper's Table 8.

    Returns:
        ``{"SR": %, "TC": %, "TR": %, "MEV": %, "TTF": s, "T2R": s, "DW": m}`` (or one per
        group).
    """
    out = robot_outcomes(waypoint_count=waypoint_count, dt=dt, **signals)
    if groups is None:
        return aggregate(out)
    groups = np.asarray(groups)
    return {g.item() if hasattr(g, "item") else g: aggregate(out, groups == g)
            for g in np.unique(groups)}


def signals_from_rollout(td, time_dim: int = -1) -> dict[str, np.ndarray]:
    """(T, N) numpy signals from a rollout TensorDict (``env.rollout`` or a collector).

    Reads ``("next", "info", <signal>)`` and ``("next", "done")``; ``time_dim`` is the
    batch dim that is time (TorchRL puts it last: batch (N, T)).
    """
    nxt = td["next"]

    def arr(key) -> np.ndarray:
        x = nxt[key].detach().cpu()
        x = x.reshape(*x.shape[: td.batch_dims])  # drop a trailing (1,) of done
        return np.moveaxis(x.numpy(), time_dim, 0)

    return {**{s: arr(("info", s)) for s in SIGNALS}, "done": arr("done")}


def summarize(runs: Sequence[Mapping[str, float]]) -> dict[str, tuple[float, float]]:
    """Mean and sample std (ddof=1; 0 for a single run) of each metric over runs.

    NaN values (T2R of a run with no success, DW of a record without positions) are left
    out of that metric's statistics.
    """
    result = {}
    for m in METRICS:
        vals = np.array([r[m] for r in runs], dtype=float)
        vals = vals[np.isfinite(vals)]
        if vals.size == 0:
            result[m] = (float("nan"), float("nan"))
        else:
            std = float(vals.std(ddof=1)) if vals.size > 1 else 0.0
            result[m] = (float(vals.mean()), std)
    return result


Rows = Mapping[str, Mapping[str, tuple[float, float]]]


def _cell(mean: float, std: float, digits: int) -> str:
    return "n/a" if not np.isfinite(mean) else f"{mean:.{digits}f} ± {std:.{digits}f}"


def to_markdown(rows: Rows, label: str = "Method", title: str | None = None,
                digits: int = 2) -> str:
    """A Markdown table: one row per key of ``rows`` (methods or categories), columns
    SR, TC, TR, MEV, TTF, T2R, DW as ``mean ± std`` with the better direction in the header."""
    lines = [f"**{title}**", ""] if title else []
    lines.append("| " + " | ".join([label, *map(column_title, METRICS)]) + " |")
    lines.append("|" + "---|" * (len(METRICS) + 1))
    for name, stats in rows.items():
        lines.append("| " + " | ".join([name, *(_cell(*stats[m], digits) for m in METRICS)])
                     + " |")
    return "\n".join(lines) + "\n"


def write_markdown(path: str | Path, rows: Rows, label: str = "Method",
                   title: str | None = None, digits: int = 2) -> Path:
    """Write :func:`to_markdown` to ``path``; returns the path."""
    path = Path(path)
    path.write_text(to_markdown(rows, label, title, digits), encoding="utf-8")
    return path


def write_csv(path: str | Path, rows: Rows, label: str = "method") -> Path:
    """A CSV table: ``label`` then, per metric, ``"<title> mean"`` and ``"<title> std"``
    columns (e.g. ``"SR (%) ↑ mean"``), full precision; returns the path."""
    path = Path(path)
    header = [label] + [f"{column_title(m)} {s}" for m in METRICS for s in ("mean", "std")]
    with path.open("w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(header)
        for name, stats in rows.items():
            w.writerow([name, *(repr(float(v)) for m in METRICS for v in stats[m])])
    return path
