"""The benchmark protocol's version: written into every benchmark file and shipping card, so
that figures of two versions are never compared side by side (docs/metrics.md, "Benchmark
v2").

- **v1** (until issue 44): a robot was jittered 0.3 m off its spawn waypoint and its height
  read under its base (a foot, or the whole robot, could start over a pit); any waypoint
  2-10 m from the terminus, obstacle ahead or not; the shipping protocol drew 2 variants a
  level. Files and cards that name no protocol were written under v1.
- **v2**: a robot starts on its waypoint (no xy jitter; the heading jitter only where every
  sole stays on footing), its height read from the support under its soles, with its
  category's obstacle on the path ahead (``legoh.envs.mdp.spawns``); 5 variants a level
  (appendix Table 8's 25 scenes); the trails of ``trail.geometry=v2`` (docs/terrain.md,
  "Trails that teach": Gap and Ditch widths and pit depths, hurdle heights ramp with level).
  Scored on another geometry, a file names it: ``v2+geometry-v1``.
"""

from __future__ import annotations

import csv
import platform
import warnings
from collections.abc import Mapping
from pathlib import Path

PROTOCOL = "v2"  # the protocol this code scores under
LEGACY = "v1"  # what a file or card that names no protocol was scored under
GEOMETRY = "v2"  # the trail geometry (trail.geometry) of the protocol's scenes
COLUMN = "protocol"  # the column of benchmark.csv and benchmark_runs.csv that names it


def protocol_of(cfg) -> str:
    """The protocol a benchmark under run config ``cfg`` scores on: :data:`PROTOCOL`, with
    the trail geometry appended when it is not the protocol's own (v2)."""
    geometry = getattr(cfg.trail, "geometry", GEOMETRY)
    geometry = str(getattr(geometry, "value", geometry))  # an enum in a composed config
    return PROTOCOL if geometry == GEOMETRY else f"{PROTOCOL}+geometry-{geometry}"


def machine() -> str:
    """The CPU and torch's CPU kernel set a benchmark ran on, for its title: rollouts replay
    bit for bit on one machine but not across vector units (docs/metrics.md,
    "Reproducibility"), so a reader can tell whether two files could have agreed."""
    import torch

    name = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            name = next(line.split(":", 1)[1].strip() for line in f
                        if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return f"{name}, torch kernels {torch.backends.cpu.get_cpu_capability()}"


class ProtocolMismatch(ValueError):
    """Figures of two benchmark protocols were about to be compared."""


def of_card(card: Mapping) -> str:
    """The protocol a shipping card (``pretrained/<robot>_<stage>.json``) was scored on."""
    return str(card.get(COLUMN, LEGACY))


def of_csv(path: str | Path) -> str:
    """The protocol of a ``benchmark.csv`` or ``benchmark_runs.csv`` (its ``protocol``
    column; :data:`LEGACY` for a file written before that column)."""
    with Path(path).open(newline="", encoding="utf-8") as f:
        reader = csv.DictReader(f)
        if COLUMN not in (reader.fieldnames or []):
            return LEGACY
        found = {row[COLUMN] for row in reader}
    if len(found) != 1:
        raise ProtocolMismatch(f"{path} mixes benchmark protocols {sorted(found)}")
    return found.pop()


def same_protocol(sources: Mapping[str, str]) -> str:
    """The one protocol of ``sources`` (``{what: protocol}``); raises ProtocolMismatch naming
    each protocol and what was scored on it when they differ."""
    by = {}
    for what, version in sources.items():
        by.setdefault(version, []).append(what)
    if len(by) > 1:
        detail = "; ".join(f"{v}: {', '.join(names)}" for v, names in sorted(by.items()))
        raise ProtocolMismatch(f"benchmark protocols differ ({detail}): figures of two "
                               f"protocols are not comparable; re-score the older on "
                               f"{PROTOCOL} (docs/metrics.md)")
    return next(iter(by), PROTOCOL)


def warn_if_other(what: str, version: str) -> bool:
    """True when ``version`` is this code's :data:`PROTOCOL`; else a warning naming both
    (``what`` names the source, e.g. a card's path) and False."""
    if version == PROTOCOL:
        return True
    warnings.warn(f"{what} was scored on benchmark protocol {version}, this code scores on "
                  f"{PROTOCOL}: its figures are not comparable and are not shown beside "
                  f"this run's (re-score it: docs/metrics.md)", stacklevel=2)
    return False
