"""The GPU check's summary: one page and one figure from what gpu_check.sh wrote.

    python experiments/gpu_report.py experiments/results/gpu_check

Reads the newest Warp run of bench_env.json (physics ceiling, depth, env rates by N) and of
bench_warp_chunks.json (the chunk table), and the oracle run's train.csv (frames_per_s per
iteration: policy steps/s end to end, the target being >= 100k for the H1 oracle on
RandomMix), and writes summary.md and summary.png beside them.
"""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

TARGET = 100_000  # policy steps/s end to end, H1 oracle on RandomMix, one H100-class GPU


def newest_run(path: Path, section: str) -> dict | None:
    """The newest run in the results file ``path`` whose results hold ``section``."""
    if not path.exists():
        return None
    return next((run for run in json.loads(path.read_text())["runs"]
                 if section in run["results"]), None)


def training_rates(folder: Path) -> list[tuple[int, float]]:
    """(iteration, frames/s) of the oracle run, if one ran."""
    files = sorted(folder.glob("oracle_run/**/train.csv"))
    if not files:
        return []
    with files[0].open() as f:
        rows = list(csv.DictReader(f))
    return [(int(float(r.get("iteration", i))), float(r["frames_per_s"]))
            for i, r in enumerate(rows) if r.get("frames_per_s")]


def main(folder: Path) -> None:
    bench = newest_run(folder / "bench_env.json", "warp_rows")
    chunks = newest_run(folder / "bench_warp_chunks.json", "rows")
    train = training_rates(folder)
    lines = ["# GPU check", ""]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    if bench:
        rows = bench["results"]["warp_rows"]
        lines += [f"Machine: {bench['machine']}.", "",
                  "| N | physics steps/s | physics + depth@10Hz | env | env + depth |",
                  "|---|---|---|---|---|"]
        for r in rows:
            env = r["env_steps_per_s"]
            envd = r["env_depth_steps_per_s"]
            lines.append(f"| {r['num_envs']} | {r['ceiling_steps_per_s']:.0f} | "
                         f"{r['ceiling_depth_10hz_steps_per_s']:.0f} | "
                         f"{'n/a' if env is None else f'{env:.0f}'} | "
                         f"{'n/a' if envd is None else f'{envd:.0f}'} |")
        n = [r["num_envs"] for r in rows]
        axes[0].plot(n, [r["ceiling_steps_per_s"] for r in rows], "o-", label="physics")
        axes[0].plot(n, [r["ceiling_depth_10hz_steps_per_s"] for r in rows], "s-",
                     label="physics + depth 10 Hz")
        if all(r["env_steps_per_s"] for r in rows):
            axes[0].plot(n, [r["env_steps_per_s"] for r in rows], "^-", label="HikingEnv")
        axes[0].axhline(TARGET, ls="--", c="gray", label="target 100k")
        axes[0].set(xscale="log", xlabel="worlds N", ylabel="policy steps/s",
                    title="MuJoCo Warp, H1 RandomMix")
        axes[0].legend()
    if chunks:
        lines += ["", f"Chunk size ({chunks['results']['num_envs']} worlds):", "",
                  "| chunk m | fields | steps/s | depth ms/frame |", "|---|---|---|---|"]
        for r in chunks["results"]["rows"]:
            name = "one field" if r["nhfield"] == 1 else f"{r['chunk_m']:g}"
            lines.append(f"| {name} | {r['nhfield']} | {r['warp_steps_per_s']:.0f} "
                         f"| {r['warp_depth_s_per_frame'] * 1e3:.1f} |")
    if train:
        rates = [f for _, f in train]
        tail = rates[len(rates) // 2:]
        mean = sum(tail) / len(tail)
        lines += ["", f"Oracle training: {len(train)} iterations, "
                  f"{mean:.0f} policy steps/s end to end (mean of the second half; target "
                  f"{TARGET}: {'met' if mean >= TARGET else 'not met'})."]
        axes[1].plot([i for i, _ in train], rates)
        axes[1].axhline(TARGET, ls="--", c="gray")
        axes[1].set(xlabel="iteration", ylabel="policy steps/s", title="oracle training")
    else:
        lines += ["", "Oracle training: did not run (see gpu_check.log)."]
    fig.tight_layout()
    fig.savefig(folder / "summary.png", dpi=100)
    (folder / "summary.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("experiments/results/gpu_check"))
