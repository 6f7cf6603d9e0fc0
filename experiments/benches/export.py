"""Deployment latency: one robot, one CPU core, the exported TorchScript file vs the eager
module in the same run.

    python experiments/bench.py export   # adds a run to experiments/results/bench_export.{md,json}

For each student (LEGO-H small/paper x GRU/causal transformer, EP-H, RMA-B): the median
time of ``encode`` (navigation, once per depth frame, 10 Hz) and ``act`` (locomotion, every
step, 50 Hz) at batch 1 on 1 torch thread. Real time at 50 Hz with depth at 10 Hz needs
(a) on average 10 encodes + 50 acts per second within one core: load = (10 enc + 50 act) /
1000 ms < 1; (b) a step that finishes within its 20 ms slot even when a frame arrives:
enc + act < 20 ms (or else the encoder must run beside the controller, where it has 100 ms).
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import torch

from legoh.export import DeployedStudent, example_inputs, export_student
from legoh.modules.students import StudentDims, make_student

RESULTS = "bench_export"
TITLE = "Deployment latency, one robot, 1 CPU thread (TorchScript export; median)"
TORCH_THREADS = 1
PROPRIO, ACTIONS = 39, 10  # H1 (the env's proprioception and leg joints)
CASES = [  # (label, student, preset, core, depth (T, H, W))
    ("LEGO-H small, GRU", "lego_h", "small", "gru", (4, 24, 32)),
    ("LEGO-H small, CT", "lego_h", "small", "transformer", (4, 24, 32)),
    ("LEGO-H paper, GRU", "lego_h", "paper", "gru", (4, 48, 64)),
    ("LEGO-H paper, CT", "lego_h", "paper", "transformer", (4, 48, 64)),
    ("EP-H", "ep_h", "small", "gru", (4, 24, 32)),
    ("RMA-B", "rma_b", "small", "gru", None),
]


def median_ms(fn, reps: int) -> float:
    for _ in range(3):
        fn()
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times)


def measure_case(label, name, preset, core, depth, tmp: Path) -> dict:
    dims = StudentDims(proprio=PROPRIO, history=10, depth=depth)
    student = make_student(name, dims, ACTIONS, 4.8, preset=preset, core=core)
    eager = DeployedStudent(student).eval()
    traced = torch.jit.load(str(export_student(student, tmp / "policy.pt")))
    x = example_inputs(student)
    enc = (x["depth"], x["goal"], x["proprio"], x["proprio_history"], x["state"])
    reps = 30 if preset == "paper" else 200
    row = {"label": label, "params_M": sum(p.numel() for p in eager.parameters()) / 1e6}
    with torch.no_grad():
        held, _ = eager.encode(*enc)
        act = (x["goal"], x["proprio"], x["proprio_history"], held)
        for kind, mod in (("eager", eager), ("script", traced)):
            row[f"encode_ms_{kind}"] = median_ms(lambda m=mod: m.encode(*enc), reps)
            row[f"act_ms_{kind}"] = median_ms(lambda m=mod: m.act(*act), 200)
    e, a = row["encode_ms_script"], row["act_ms_script"]
    row["core_load"] = (10 * e + 50 * a) / 1000.0
    row["frame_step_ms"] = e + a
    row["script_over_eager"] = ((row["encode_ms_eager"] + row["act_ms_eager"])
                                / (e + a))
    return row


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """No arguments of its own: every student of ``CASES``."""


def measure(args: argparse.Namespace) -> dict:
    """Each student of ``CASES``, exported to a temporary folder."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for case in CASES:
            rows.append(measure_case(*case, Path(tmp)))
            r = rows[-1]
            print(f"{r['label']:20s} encode {r['encode_ms_script']:7.2f} ms  act "
                  f"{r['act_ms_script']:6.3f} ms  load {r['core_load']:.2f}  frame step "
                  f"{r['frame_step_ms']:.1f} ms")
    return {"threads": 1, "batch": 1, "proprio": PROPRIO, "actions": ACTIONS, "rows": rows}


def summary(run: dict) -> str:
    return "frame step (ms): " + ", ".join(f"{r['label']} {r['frame_step_ms']:.1f}"
                                           for r in run["results"]["rows"])


def markdown(run: dict) -> str:
    lines = ["| Student | params (M) | encode (ms, 10 Hz) | act (ms, 50 Hz) | core load "
             "(10 enc + 50 act per s) | frame step enc + act (ms; slot 20) | 50 Hz real time "
             "| eager / TorchScript |", "|---|---|---|---|---|---|---|---|"]
    for r in run["results"]["rows"]:
        ok = ("yes" if r["frame_step_ms"] < 20 else
              "with the encoder beside the controller" if r["core_load"] < 1 else "no")
        lines.append(f"| {r['label']} | {r['params_M']:.2f} | {r['encode_ms_script']:.2f} | "
                     f"{r['act_ms_script']:.3f} | {r['core_load']:.2f} | "
                     f"{r['frame_step_ms']:.1f} | {ok} | {r['script_over_eager']:.2f} |")
    return "\n".join(lines) + "\n"
