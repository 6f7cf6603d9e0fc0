"""What every benchmark shares: the machine line, and one results file whose history lives
inside it.

``<results>/<name>.json`` holds ``{"benchmark": name, "runs": [...]}``, newest first; a run
is ``{date, kind, tag, note, machine, command, conditions, results}`` (``kind``: "" for
the standard run, else e.g. "quick" or a device; ``conditions``: the run's arguments).
``<name>.md`` shows the newest run of each kind in full and a dated list of all runs.
"""

from __future__ import annotations

import datetime
import json
import os
import platform
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "experiments" / "results"


def machine_line(**extra: object) -> str:
    """CPUs, processor, OS, Python, torch, MuJoCo (and the GPU where torch sees one), plus
    ``extra`` versions a benchmark depends on."""
    import mujoco
    import torch

    parts = [f"{os.cpu_count()} CPUs", platform.processor() or platform.machine(),
             platform.platform(), f"Python {platform.python_version()}",
             f"torch {torch.__version__}", f"MuJoCo {mujoco.__version__}"]
    if torch.cuda.is_available():
        parts.append(torch.cuda.get_device_name())
    parts += [f"{name} {version}" for name, version in extra.items()]
    return ", ".join(parts)


def new_run(results: dict, machine: str, conditions: dict, *, kind: str = "", tag: str = "",
            note: str = "", command: str = "", date: str | None = None) -> dict:
    """One entry of a results file's history, dated today unless ``date`` is given."""
    return {"date": date or datetime.date.today().isoformat(), "kind": kind, "tag": tag,
            "note": note, "machine": machine, "command": command, "conditions": conditions,
            "results": results}


def read_runs(path: Path) -> list[dict]:
    """The runs of the results file ``path`` (.json), newest first; none if it is absent."""
    return json.loads(path.read_text())["runs"] if path.exists() else []


def add_run(folder: Path, name: str, run: dict, markdown: Callable[[dict], str],
            title: str, summary: Callable[[dict], str] | None = None) -> list[dict]:
    """Put ``run`` first in ``folder/<name>.json`` and rewrite ``<name>.md`` from all runs
    (``markdown``: a run's tables; ``summary``: its line in the history). Returns the runs."""
    folder.mkdir(parents=True, exist_ok=True)
    runs = [run, *read_runs(folder / f"{name}.json")]
    write_runs(folder, name, runs, markdown, title, summary)
    return runs


def write_runs(folder: Path, name: str, runs: list[dict], markdown: Callable[[dict], str],
               title: str, summary: Callable[[dict], str] | None = None) -> None:
    """``folder/<name>.{json,md}`` from ``runs`` (newest first)."""
    (folder / f"{name}.json").write_text(
        json.dumps({"benchmark": name, "runs": runs}, indent=2) + "\n")
    (folder / f"{name}.md").write_text(history_markdown(name, runs, markdown, title, summary))


def history_markdown(name: str, runs: list[dict], markdown: Callable[[dict], str], title: str,
                     summary: Callable[[dict], str] | None = None) -> str:
    """The newest run of each kind (the standard run first) in full, then every run, one
    dated line each."""
    newest: dict[str, dict] = {}
    for run in runs:
        newest.setdefault(run.get("kind", ""), run)
    order = sorted(newest, key=lambda k: k != "")  # stable: other kinds by recency
    lines = [f"# {title}", "",
             f"Every run is kept in `{name}.json` (newest first, with its machine and "
             "conditions); `python experiments/bench.py --help` lists the benchmarks.", ""]
    for kind in order:
        run = newest[kind]
        lines += [f"## Newest run{f' ({kind})' if kind else ''}: {_label(run)}", ""]
        if run.get("note"):
            lines += [run["note"], ""]
        lines += [f"Machine: {run['machine']}."]
        if run.get("command"):
            lines += [f"Command: `{run['command']}`."]
        lines += ["", markdown(run).rstrip("\n"), ""]
    lines += ["## History", ""]
    for run in runs:
        kind = f" ({run['kind']})" if run.get("kind") else ""
        line = f"- {_label(run)}{kind}"
        if summary is not None:
            line += f": {summary(run)}"
        if run.get("note"):
            line += f". {run['note']}"
        lines.append(line)
    return "\n".join(lines) + "\n"


def _label(run: dict) -> str:
    return f"{run['date']}, `{run['tag']}`" if run.get("tag") else run["date"]
