"""The paper's benchmark metrics (SR, TC, TR, MEV, TTF, T2R), and our DW and FR, as plain
functions.

Formulas and the choices the paper leaves open are in ``docs/metrics.md``. In short, each
robot's **first episode** in the record counts (the steps up to and including its first
``done``; a robot never done counts as a timeout at the record's end), and

- SR  (%)  = 100 * mean_n success_n, success_n = reached at the episode's last step
- TC  (%)  = 100 * mean_n (expert waypoints ahead of the spawn, terminus excluded, that the
             torso's xy path passed within ``tc_radius``) / (waypoints ahead); robots with
             none ahead, and records without paths, are left out (NaN)
- TR  (%)  = 100 * mean_n (progress_end - progress_start) / (1 - progress_start), clipped
             to [0, 1] (1 for a success): the share of the path from the spawn covered
- MEV (%)  = 100 * (sum edge foot-contacts + sum unsafe-collision steps)
                  / (sum foot-contacts + sum unsafe-collision steps), pooled over robots
- TTF (s)  = mean over robots that fell of the time of the fall (NaN if none fell)
- T2R (s)  = mean over successful robots of the episode duration (NaN if none succeeded)
- DW  (m)  = mean_n distance walked toward the terminus: |start_n - terminus_n| -
             |end_n - terminus_n| in xy (NaN when the record has no positions)
- FR  (%)  = 100 * mean_n fall_n: falls, so a policy that never falls (TTF n/a) is scored

Inputs are per-step arrays of shape (T, N): the ``("next", "info", ...)`` signals of each
step (the state the step led to, before any auto-reset) and ``("next", "done")``; TC also
needs each robot's path and the waypoints ahead of it (:func:`trail_completion`), TR each
robot's progress at the reset, DW its start and end positions (:func:`distance_walked`).
"""

from __future__ import annotations

import csv
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

# the paper's six in Table 8's order, then ours
METRICS = ("SR", "TC", "TR", "MEV", "TTF", "T2R", "DW", "FR")
UNITS = {"SR": "%", "TC": "%", "TR": "%", "MEV": "%", "TTF": "s", "T2R": "s", "DW": "m",
         "FR": "%"}
HIGHER_IS_BETTER = {"SR": True, "TC": True, "TR": True, "MEV": False, "TTF": True,
                    "T2R": False, "DW": True, "FR": False}
SIGNALS = ("reached", "fell", "progress", "edge_contacts", "foot_contacts",
           "unsafe_collisions")
TC_RADIUS = 0.3  # m: a waypoint counts as passed within this of the torso (eval.tc_radius)


def column_title(metric: str) -> str:
    """Table header of a metric, e.g. ``"SR (%) ↑"``, ``"MEV (%) ↓"``."""
    return f"{metric} ({UNITS[metric]}) {'↑' if HIGHER_IS_BETTER[metric] else '↓'}"


@dataclass(frozen=True)
class RobotOutcomes:
    """Per-robot results of the first episode, each (N,)."""

    success: np.ndarray  # bool: reached the terminus
    fall: np.ndarray  # bool: ended by a fall (and not by reaching)
    duration: np.ndarray  # s: time from the start to the episode's end
    completion: np.ndarray  # [0, 1]: waypoints ahead passed / waypoints ahead (NaN: none)
    traverse: np.ndarray  # [0, 1]: share of the path from the spawn covered (1: success)
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


def waypoints_passed(path_xy: np.ndarray, waypoints_xy: np.ndarray, radius: float
                     ) -> np.ndarray:
    """Which waypoints (W,) bool the path came within ``radius`` of, measured to the
    path's segments (so a fast step between two samples cannot jump over a waypoint).

    Args:
        path_xy: (T, >=2) torso positions in order, world frame, m (only x, y are read).
        waypoints_xy: (W, >=2) world frame, m. radius: m.
    """
    wp = np.asarray(waypoints_xy, dtype=float)
    path = np.asarray(path_xy, dtype=float)
    if wp.size == 0 or path.size == 0:
        return np.zeros(len(wp), dtype=bool)
    wp, path = wp[:, :2], path[:, :2]
    a, ab = path[:-1], np.diff(path, axis=0)  # (S, 2) segments; none for one point
    if len(ab) == 0:
        a, ab = path, np.zeros_like(path)
    rel = wp[:, None, :] - a[None]  # (W, S, 2)
    frac = np.clip((rel * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12), 0.0, 1.0)
    gap = np.linalg.norm(rel - frac[..., None] * ab, axis=-1)  # (W, S) to each segment
    return gap.min(axis=1) <= radius


def trail_completion(paths: Sequence[np.ndarray], waypoints: Sequence[np.ndarray],
                     radius: float = TC_RADIUS) -> np.ndarray:
    """Per robot, the share of its counted waypoints that its torso passed within
    ``radius`` (:func:`waypoints_passed`); NaN for a robot with none to count.

    Args:
        paths: N arrays (T_n, >=2), each robot's torso path over its first episode, spawn
            first, world frame, m.
        waypoints: N arrays (W_n, 2), the expert waypoints to count for each robot: those
            ahead of its spawn, the terminus excluded (reaching it is SR).
        radius: m.

    Returns:
        (N,) float in [0, 1] or NaN.
    """
    if len(paths) != len(waypoints):
        raise ValueError(f"one path and one waypoint list per robot, got {len(paths)} "
                         f"paths and {len(waypoints)} waypoint lists")
    return np.array([waypoints_passed(p, w, radius).mean() if len(w) else np.nan
                     for p, w in zip(paths, waypoints, strict=True)], dtype=float)


def traverse_rate(progress_end: np.ndarray, progress_start: np.ndarray | float,
                  success: np.ndarray) -> np.ndarray:
    """Share (N,) of the path from each robot's spawn to the terminus it covered:
    ``(end - start) / (1 - start)`` clipped to [0, 1], 1 for a success. Progress is the
    fraction of the whole trail's path length from the trail start (``info/progress``)."""
    end = np.asarray(progress_end, dtype=float)
    start = np.broadcast_to(np.asarray(progress_start, dtype=float), end.shape)
    share = (end - start) / np.maximum(1.0 - start, 1e-9)
    return np.where(success, 1.0, np.clip(share, 0.0, 1.0))


def robot_outcomes(*, reached: np.ndarray, fell: np.ndarray, progress: np.ndarray,
                   edge_contacts: np.ndarray, foot_contacts: np.ndarray,
                   unsafe_collisions: np.ndarray, done: np.ndarray, dt: float,
                   distance: np.ndarray | None = None,
                   progress_start: np.ndarray | float | None = None,
                   paths: Sequence[np.ndarray] | None = None,
                   waypoints: Sequence[np.ndarray] | None = None,
                   tc_radius: float = TC_RADIUS) -> RobotOutcomes:
    """Per-robot outcomes of each robot's first episode.

    Args:
        reached, fell, done: (T, N) bool. progress: (T, N) float in [0, 1], fraction of
            the trail's path from the trail start.
        edge_contacts, foot_contacts: (T, N) int, feet in contact (on an edge / at all).
        unsafe_collisions: (T, N) int, non-foot bodies touching the world. dt: policy
            step, s.
        distance: (N,) m, :func:`distance_walked` of each robot's first episode; the
            signals carry no positions, so without it DW is NaN.
        progress_start: (N,) (or scalar) progress at the reset; None: 0, the trail start.
        paths, waypoints: :func:`trail_completion`'s inputs (each robot's torso path over
            its first episode, the waypoints ahead of its spawn); without both TC is NaN.
        tc_radius: m, :func:`trail_completion`'s radius.
    """
    arrs = [np.asarray(a) for a in (reached, fell, progress, edge_contacts,
                                    foot_contacts, unsafe_collisions, done)]
    shape = arrs[0].shape
    if len(shape) != 2 or any(a.shape != shape for a in arrs):
        raise ValueError(f"all signals must share one (T, N) shape, got "
                         f"{[a.shape for a in arrs]}")
    reached, fell, progress, edge, feet, unsafe, done = arrs
    t_len, n = shape
    done = done.astype(bool)
    ended = done.any(axis=0)
    last = np.where(ended, done.argmax(axis=0), t_len - 1)  # (N,) index of the final step
    in_episode = np.arange(t_len)[:, None] <= last[None, :]  # (T, N)
    cols = np.arange(n)
    success = reached.astype(bool)[last, cols]
    fall = fell.astype(bool)[last, cols] & ended & ~success
    completion = (np.full(n, np.nan) if paths is None or waypoints is None
                  else trail_completion(paths, waypoints, tc_radius))
    if completion.shape != (n,):
        raise ValueError(f"paths and waypoints must hold one entry per robot ({n}), got "
                         f"{completion.shape[0]}")
    traverse = traverse_rate(progress[last, cols], 0.0 if progress_start is None
                             else progress_start, success)
    unsafe_steps = np.where(in_episode, unsafe > 0, False).sum(axis=0)
    violations = np.where(in_episode, edge, 0).sum(axis=0) + unsafe_steps
    contacts = np.where(in_episode, feet, 0).sum(axis=0) + unsafe_steps
    return RobotOutcomes(success=success, fall=fall, duration=(last + 1) * float(dt),
                         completion=completion, traverse=traverse,
                         violations=violations.astype(float), contacts=contacts.astype(float),
                         distance=(np.full(n, np.nan) if distance is None
                                   else np.broadcast_to(np.asarray(distance, float), (n,))))


def _mean(x: np.ndarray) -> float:
    """Mean of the finite values; NaN when there are none."""
    x = x[np.isfinite(x)]
    return float(x.mean()) if x.size else float("nan")


def aggregate(out: RobotOutcomes, select: np.ndarray | None = None) -> dict[str, float]:
    """Metric -> value over the robots in ``select`` ((N,) bool; all when None)."""
    sel = np.ones_like(out.success, dtype=bool) if select is None else np.asarray(select, bool)
    if not sel.any():
        return dict.fromkeys(METRICS, float("nan"))
    contacts = out.contacts[sel].sum()
    return {
        "SR": 100.0 * out.success[sel].mean(),
        "TC": 100.0 * _mean(out.completion[sel]),
        "TR": 100.0 * out.traverse[sel].mean(),
        "MEV": 100.0 * out.violations[sel].sum() / contacts if contacts > 0 else 0.0,
        "TTF": _mean(out.duration[out.fall & sel]),
        "T2R": _mean(out.duration[out.success & sel]),
        "DW": _mean(out.distance[sel]),
        "FR": 100.0 * out.fall[sel].mean(),
    }


def episode_metrics(*, dt: float, groups=None, **inputs) -> dict:
    """The metrics of one run.

    Args:
        dt, inputs: as :func:`robot_outcomes`: the signals ``reached``, ``fell``,
            ``progress``, ``edge_contacts``, ``foot_contacts``, ``unsafe_collisions``,
            ``done`` (each (T, N)), and optionally ``distance`` (DW), ``progress_start``
            (TR from the spawn), ``paths`` and ``waypoints`` (TC). From the signals alone
            TC and DW are NaN and TR counts from the trail start.
        groups: optional (N,) labels (for example trail category names): then the result
            is ``{label: metrics}`` per label, as in the paper's Table 8.

    Returns:
        ``{"SR": %, "TC": %, "TR": %, "MEV": %, "TTF": s, "T2R": s, "DW": m, "FR": %}``
        (or one per group).
    """
    out = robot_outcomes(dt=dt, **inputs)
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

    NaN values (T2R of a run with no success, TTF of a run with no fall, TC and DW of a
    record without paths) are left out of that metric's statistics.
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
    :data:`METRICS` as ``mean ± std`` with the better direction in the header."""
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


def write_csv(path: str | Path, rows: Rows, label: str = "method",
              protocol: str | None = None) -> Path:
    """A CSV table: ``label`` then, per metric, ``"<title> mean"`` and ``"<title> std"``
    columns (e.g. ``"SR (%) ↑ mean"``), full precision, then a ``protocol`` column when
    ``protocol`` is given (``legoh.eval.protocol``); returns the path."""
    path = Path(path)
    header = [label] + [f"{column_title(m)} {s}" for m in METRICS for s in ("mean", "std")]
    tail = [] if protocol is None else [protocol]
    with path.open("w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(header + (["protocol"] if tail else []))
        for name, stats in rows.items():
            w.writerow([name, *(repr(float(v)) for m in METRICS for v in stats[m]), *tail])
    return path


def write_runs_csv(path: str | Path, runs: Sequence[Mapping[str, Mapping[str, float]]],
                   protocol: str | None = None) -> Path:
    """Every run's own values: ``run``, ``category`` (or ``overall``, ``level <l>``), then one
    column per metric (its title), then ``protocol`` when given. What :func:`write_csv`'s
    mean and std summarise, kept so that runs of several jobs pool exactly (a metric NaN in
    some runs included)."""
    path = Path(path)
    tail = [] if protocol is None else [protocol]
    with path.open("w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(["run", "category", *map(column_title, METRICS)]
                   + (["protocol"] if tail else []))
        for r, rows in enumerate(runs):
            for name, values in rows.items():
                w.writerow([r, name, *(repr(float(values[m])) for m in METRICS), *tail])
    return path
