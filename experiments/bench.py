"""The project's benchmarks behind one command; each adds a dated run to its results file.

    python experiments/bench.py --help                # the benchmarks
    python experiments/bench.py NAME --help           # one benchmark's arguments
    python experiments/bench.py NAME [args] [--note "..."] [--tag T] [--results DIR]

Every benchmark writes ``<results>/<stem>.{json,md}`` (``experiments/results/`` by default):
the json keeps every run (date, machine, conditions, results; newest first), the md shows
the newest run's tables and the dated history (``benches/common.py``). Absolute numbers
depend on the machine and on what else runs on it: compare rows of one run.
"""

from __future__ import annotations

import argparse
import importlib
import os
import shlex
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# before mujoco or warp are imported: headless rendering, and the tests' kernel cache
os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".warp_cache"))
sys.path[:0] = [str(ROOT / "experiments"), str(ROOT)]

from benches import BENCHMARKS  # noqa: E402


def parser() -> argparse.ArgumentParser:
    """The CLI: one sub-command per benchmark (its module's arguments, loaded on demand)."""
    top = argparse.ArgumentParser(
        description=__doc__.splitlines()[0], formatter_class=argparse.RawTextHelpFormatter,
        epilog="benchmarks:\n" + "\n".join(f"  {name:12s} {about}"
                                            for name, (_, about) in BENCHMARKS.items()))
    top.add_argument("name", choices=list(BENCHMARKS), metavar="NAME",
                     help="the benchmark to run (listed below)")
    return top


def bench_parser(name: str, module) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=f"bench.py {name}", description=module.__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    module.add_arguments(p)
    shared = p.add_argument_group("shared by every benchmark")
    shared.add_argument("--note", default="", help="a line on the conditions of this run")
    shared.add_argument("--tag", default="", help="a short label for this run in the history")
    shared.add_argument("--results", type=Path, default=None,
                        help="folder of the results file (default experiments/results)")
    shared.add_argument("--torch-threads", type=int, default=module.TORCH_THREADS,
                        help="torch's threads (default: the benchmark's, "
                             f"{module.TORCH_THREADS or 'torch default'})")
    return p


SHARED = ("note", "tag", "results")


def main(argv: list[str] | None = None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0].startswith("-"):
        parser().parse_args(argv)  # --help, or the error naming the missing benchmark
        return
    name = parser().parse_args(argv[:1]).name
    module = importlib.import_module(f"benches.{BENCHMARKS[name][0]}")
    args = bench_parser(name, module).parse_args(argv[1:])
    sys.stdout.reconfigure(line_buffering=True)  # progress shows as it happens

    import torch
    from benches import common

    if args.torch_threads:
        torch.set_num_threads(args.torch_threads)
    results = module.measure(args)
    conditions = {k: str(v) if isinstance(v, Path) else v
                  for k, v in vars(args).items() if k not in SHARED}
    machine = getattr(module, "machine", common.machine_line)()
    run = common.new_run(results, machine, conditions,
                         kind=module.kind(args) if hasattr(module, "kind") else "",
                         tag=args.tag, note=args.note,
                         command=shlex.join(["python", "experiments/bench.py", *argv]))
    folder = args.results or common.RESULTS
    common.add_run(folder, module.RESULTS, run, module.markdown, module.TITLE,
                   getattr(module, "summary", None))
    print(module.markdown(run))
    print(f"added a run to {folder / module.RESULTS}.json and .md")


if __name__ == "__main__":
    main()
