"""TC-ViTs size: parameters, FLOPs and CPU latency of each preset x core, beside the paper.

For presets small / paper and cores gru / transformer (H1: proprio 39; G1's 45 is also
counted):
  * parameters, in total and per part (encoder, CNN, mixer, core, heads);
  * forward FLOPs for one robot (batch 1) from ``torch.utils.flop_counter.FlopCounterMode``,
    which counts a multiply-add as 2 FLOPs; many papers report MACs as "FLOPs", so the count
    / 2 is given too. The paper reports 0.686 G (GRU) and 0.785 G (causal transformer);
  * one-robot forward latency on 1 CPU thread (median over repeats, no grad);
  * for the small preset, a 64-env forward + backward on 1 thread (the training shape; 1
    thread because 2 threads on 2 shared cores suffer badly from oversubscription).

    python experiments/bench.py model-size [--quick]

Adds a run to experiments/results/model_size.{json,md}. Latencies depend on the machine (and on
whatever else runs on it); compare the rows of one run with each other.
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch
from torch.utils.flop_counter import FlopCounterMode

from legoh.modules.tcvit import TCViTs, tcvit_config

RESULTS = "model_size"
TITLE = "TC-ViTs size"
TORCH_THREADS = 1  # latencies on 1 thread (measure sets it too)
PROPRIO = {"h1": 39, "g1": 45}  # the env's observation spec ("obs", "proprio")
PAPER = {"gru": {"params": 31.25e6, "flops": 0.686e9},  # appendix 3.1 / Table 1
         "transformer": {"params": 55.92e6, "flops": 0.785e9}}
PRESETS, CORES = ("small", "paper"), ("gru", "transformer")
TRAIN_ENVS = 64  # the unified stage's CPU batch the small preset is sized for


def inputs(net: TCViTs, batch: int, proprio: int) -> tuple[torch.Tensor, ...]:
    """Random (depth, goal, proprio, state) for ``batch`` robots; the state is a mid-episode
    one (full of past for the transformer core), so every path is exercised."""
    cfg = net.cfg
    depth = torch.rand(batch, cfg.frames, cfg.height, cfg.width) - 0.5
    goal, prop = torch.randn(batch, 4) * 5.0, torch.randn(batch, proprio)
    state = net.initial_state(batch)
    with torch.no_grad():
        for _ in range(cfg.core_context + 1):
            state = net(depth, goal, prop, state)["state"]
    return depth, goal, prop, state


def count_params(module: torch.nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())


def median_ms(fn, repeats: int) -> float:
    """Median wall time of ``fn()`` in ms, after two warm-up calls."""
    for _ in range(2):
        fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append((time.perf_counter() - start) * 1e3)
    return statistics.median(times)


def measure_one(preset: str, core: str, repeats: int) -> dict:
    torch.manual_seed(0)
    cfg = tcvit_config(preset, core)
    net = TCViTs(cfg, PROPRIO["h1"]).eval()
    parts = {"encoder": net.encoder, "cnn": net.cnn, "mix": net.mix, "core": net.core}
    row = {
        "preset": preset, "core": core, "image": f"{cfg.width}x{cfg.height}x{cfg.frames}",
        "tokens": cfg.patches * cfg.frames,
        "params": count_params(net),
        "params_g1": count_params(TCViTs(cfg, PROPRIO["g1"])),
        "params_parts": {k: count_params(m) for k, m in parts.items()}
        | {"heads": count_params(net) - sum(count_params(m) for m in parts.values())},
    }
    one = inputs(net, 1, PROPRIO["h1"])
    # count in train mode: in eval, nn.TransformerEncoderLayer takes a fused fast path that
    # FlopCounterMode does not see (it reports ~3% of the work). Dropout is 0, so the maths
    # is the same in both modes.
    with FlopCounterMode(display=False) as counter, torch.no_grad():
        net.train()(*one)
    net.eval()
    row["flops_torch"] = counter.get_total_flops()
    row["macs"] = row["flops_torch"] / 2
    torch.set_num_threads(1)
    with torch.no_grad():
        row["latency_ms_1thread"] = median_ms(lambda: net(*one), repeats)
    if preset == "small":
        net.train()
        batch = inputs(net, TRAIN_ENVS, PROPRIO["h1"])

        def step() -> None:
            out = net(*batch)
            sum(v.sum() for k, v in out.items() if k != "state").backward()

        row["train_ms_64env_1thread"] = median_ms(step, max(3, repeats // 4))
    paper = PAPER[core]
    row["paper_params"], row["paper_flops"] = paper["params"], paper["flops"]
    row["params_ratio"] = row["params"] / paper["params"]
    return row


def markdown(run: dict) -> str:
    rows, repeats = run["results"]["rows"], run["results"]["repeats"]
    lines = [
        f"Latency: median of {repeats} "
        "one-robot forwards on 1 CPU thread, no grad. FLOPs: torch's FlopCounterMode "
        "(multiply-add = 2 FLOPs) for one robot; MACs = FLOPs / 2. Paper: appendix 3.1. "
        "Proprioception: H1 (39); G1 (45) in its own column.", "",
        "| preset | core | input (WxHxT) | tokens | params | params G1 | paper params | ratio "
        "| torch GFLOPs | GMACs (= /2) | paper \"GFLOPs\" | latency ms (1 thread) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        paper = (f"{r['paper_params'] / 1e6:.2f} M", f"{r['params_ratio']:.3f}",
                 f"{r['paper_flops'] / 1e9:.3f}") if r["preset"] == "paper" else ("-", "-", "-")
        lines.append(
            f"| {r['preset']} | {r['core']} | {r['image']} | {r['tokens']} "
            f"| {r['params'] / 1e6:.3f} M | {r['params_g1'] / 1e6:.3f} M | {paper[0]} "
            f"| {paper[1]} | {r['flops_torch'] / 1e9:.3f} | {r['macs'] / 1e9:.3f} | {paper[2]} "
            f"| {r['latency_ms_1thread']:.2f} |")
    lines += ["", "Parameters by part (M):", "",
              "| preset | core | encoder | cnn | mix | core | heads |",
              "|---|---|---|---|---|---|---|"]
    for r in rows:
        p = {k: f"{v / 1e6:.3f}" for k, v in r["params_parts"].items()}
        lines.append(f"| {r['preset']} | {r['core']} | {p['encoder']} | {p['cnn']} | {p['mix']} "
                     f"| {p['core']} | {p['heads']} |")
    by = {(r["preset"], r["core"]): r for r in rows}
    pg, pt = by["paper", "gru"], by["paper", "transformer"]
    lines += [
        "",
        f"Transformer core minus GRU core, paper preset: {(pt['params'] - pg['params']) / 1e6:.2f}"
        f" M params (paper 24.67 M), {(pt['macs'] - pg['macs']) / 1e9:.3f} GMACs "
        f"(paper 0.099 G).",
    ]
    for core in CORES:
        r = by["small", core]
        lines.append(f"Small, {core}: {TRAIN_ENVS}-env forward + backward on 1 thread "
                     f"{r['train_ms_64env_1thread']:.1f} ms (median).")
    lines.append("Latency, paper / small: " + ", ".join(
        f"{c} {by['paper', c]['latency_ms_1thread'] / by['small', c]['latency_ms_1thread']:.1f}x"
        for c in CORES) + ".")
    return "\n".join(lines) + "\n"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--quick", action="store_true", help="few repeats (a smoke run)")


def kind(args: argparse.Namespace) -> str:
    return "quick" if args.quick else ""


def measure(args: argparse.Namespace) -> dict:
    """Every preset x core."""
    repeats = 5 if args.quick else 50
    rows = []
    for preset in PRESETS:
        for core in CORES:
            rows.append(measure_one(preset, core, repeats))
            r = rows[-1]
            print(f"{preset:5s} {core:11s} {r['params'] / 1e6:8.3f} M params  "
                  f"{r['flops_torch'] / 1e9:6.3f} GFLOPs (torch)  {r['macs'] / 1e9:6.3f} GMACs  "
                  f"{r['latency_ms_1thread']:7.2f} ms")
    return {"repeats": repeats, "rows": rows}


def summary(run: dict) -> str:
    return "latency (ms, 1 thread): " + ", ".join(
        f"{r['preset']} {r['core']} {r['latency_ms_1thread']:.2f}" for r in run["results"]["rows"])
