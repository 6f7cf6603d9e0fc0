"""How large an oracle's raw mean actions are, per joint, on its own hiking states: the
labels a stage-2 student imitates (``algo.label_clip``, docs/unified.md).

    python experiments/oracle_actions.py --robot h1 [--checkpoint pretrained] [--recipe v2]
        [--label h1-v2] [--robots 32] [--steps 150]

The oracle acts (its mean, no noise) on ``--robots`` robots of the hike map (curriculum
levels as training starts them, randomisation as the recipe sets it; a robot whose episode
ends restarts) for ``--steps`` steps,
on the body its checkpoint trained on; per joint the RMS of its raw means, and overall the
RMS, the largest magnitude and the share of entries above 3 (the env clips at
``env.action_clip``; with ``effort_action_scale`` 0.5 the PD torque saturates from |a| ~ 2
at the default pose). Each run is appended to experiments/results/oracle_actions.json and
the table in oracle_actions.md is rewritten from it.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import torch  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "experiments"))

from learn_hike import RECIPES  # noqa: E402

from legoh.config.compose import compose_config  # noqa: E402
from legoh.envs.hiking_env import make_env  # noqa: E402
from legoh.policies.embodiment import with_checkpoint_body  # noqa: E402
from legoh.policies.oracle import load_oracle_actor  # noqa: E402
from legoh.policies.pretrained import resolve_checkpoint  # noqa: E402

RESULTS = ROOT / "experiments" / "results"


def rollout_actions(env, actor, steps: int) -> tuple[torch.Tensor, int]:
    """``actor``'s actions (steps, robots, joints) over ``steps`` steps of ``env``, a robot
    whose episode ended restarting, and how many episodes ended."""
    td, actions, ended = env.reset(), [], 0
    with torch.no_grad():
        for _ in range(steps):
            td = actor(td)
            actions.append(td["action"].clone())
            stepped, td = env.step_and_maybe_reset(td)
            ended += int(stepped["next", "done"].sum())
    return torch.stack(actions), ended


def action_stats(robot: str, checkpoint: str, recipe: str, robots: int, steps: int,
                 seed: int = 0) -> dict:
    """Per-joint RMS and overall figures of the oracle's raw mean actions (see above)."""
    preset, extra = RECIPES[recipe]
    path = resolve_checkpoint(checkpoint, robot)
    cfg = compose_config(f"robot={robot}", "trail=hike", f"env.reward_preset={preset}",
                         f"seed={seed}", *extra)
    cfg = with_checkpoint_body(cfg, path)
    env = make_env(cfg, num_envs=robots)
    try:
        a, ended = rollout_actions(env, load_oracle_actor(cfg, path, env), steps)
        joints = list(cfg.robot.leg_joints) + list(cfg.robot.get("upper_joints") or [])
    finally:
        env.close()
    rms = a.pow(2).mean((0, 1)).sqrt().tolist()
    return {"robot": robot, "checkpoint": str(path.relative_to(ROOT)) if path.is_relative_to(
                ROOT) else str(path), "recipe": recipe, "robots": robots, "steps": steps,
            "rms_per_joint": {(joints[i] if i < len(joints) else str(i)): round(v, 3)
                              for i, v in enumerate(rms)},
            "rms": round(a.pow(2).mean().sqrt().item(), 3),
            "max_abs": round(a.abs().max().item(), 2),
            "share_above_3": round((a.abs() > 3).float().mean().item(), 4),
            "episodes_ended": ended,
            "action_clip": float(cfg.env.action_clip)}


def write_table(runs: list[dict], path: Path) -> None:
    lines = ["# Oracles' raw mean actions on their hiking states", "",
             "Written by `experiments/oracle_actions.py` from `oracle_actions.json`.", "",
             "| label | checkpoint | recipe | RMS | max abs | share above 3 | env clip | "
             "RMS per joint |", "|---|---|---|---|---|---|---|---|"]
    for r in runs:
        joints = ", ".join(f"{k} {v:.2f}" for k, v in r["rms_per_joint"].items())
        lines.append(f"| {r['label']} | `{r['checkpoint']}` | {r['recipe']} | {r['rms']:.2f} | "
                     f"{r['max_abs']:.1f} | {100 * r['share_above_3']:.1f} % | "
                     f"{r['action_clip']:.0f} | {joints} |")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="h1")
    parser.add_argument("--checkpoint", default="pretrained")
    parser.add_argument("--recipe", choices=sorted(RECIPES), default="v2")
    parser.add_argument("--label", default=None, help="the row's name (default robot-recipe)")
    parser.add_argument("--robots", type=int, default=32)
    parser.add_argument("--steps", type=int, default=150)
    args = parser.parse_args()
    torch.set_num_threads(1)
    out = action_stats(args.robot, args.checkpoint, args.recipe, args.robots, args.steps)
    out["label"] = args.label or f"{args.robot}-{args.recipe}"
    store = RESULTS / "oracle_actions.json"
    runs = json.loads(store.read_text()) if store.is_file() else []
    runs = [r for r in runs if r["label"] != out["label"]] + [out]
    store.write_text(json.dumps(runs, indent=1) + "\n", encoding="utf-8")
    write_table(runs, RESULTS / "oracle_actions.md")
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
