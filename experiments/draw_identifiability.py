"""How much of a robot's physics draw (Table 5: friction, base mass offset, CoM offset xyz,
motor strength) its own proprioception history tells: the information a student's history
estimate (``algo.history_latent``) can at best recover, by history length.

    python experiments/draw_identifiability.py --robot g1 [--robots 64] [--steps 1000]
        [--episode-s 4] [--histories 1 5 10 25 50] [--pool 128] [--iters 3000]

The shipped oracle acts (its mean, no noise), blind to the draw (its privileged input shows
the nominal one, ``env.randomization.observe_physics=false``: an oracle that knows the draw
would write it into its actions, which proprioception carries back; ``--informed``: it sees
the draw, results named ``<robot>-informed``), on ``--robots`` robots
of the hike map
(curriculum levels as training starts them) under Table 5's randomisation at full strength
from the first step, with a pool of ``--pool`` physics draws (training's default is 8; a
copy holds the hike map's terrain, ~70 MB for G1: 256 did not fit in 24 GiB) and episodes
of ``--episode-s`` seconds, so each robot meets several draws. Every step's
proprioception and draw are recorded. For each history length H, the windows of H steps that
do not cross an episode start are regressed onto the 6 standardised draw features by an MLP
(flattened window -> 256 -> 256 -> 6, Adam, ``--iters`` steps of 512 windows, stopped per
feature at its least error on a validating quarter of the draws). A quarter of the draws is
held out (never fitted nor validated on): their windows' R^2 per feature is the figure (0: no
better than the mean; 1: the draw read exactly), what a student meets in the benchmark,
whose draws are not its training pool's. Held out by robot instead, the MLP recognises a
robot from its trail inputs and reads back that robot's draw. Results:
``experiments/results/draw_identifiability/<robot>.{json,md,png}``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402
import torch  # noqa: E402
from torch import nn  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "experiments"))

from learn_hike import RECIPES  # noqa: E402

from legoh import keys  # noqa: E402
from legoh.config.compose import compose_config  # noqa: E402
from legoh.envs.hiking_env import make_env  # noqa: E402
from legoh.policies.embodiment import with_checkpoint_body  # noqa: E402
from legoh.policies.oracle import load_oracle_actor  # noqa: E402
from legoh.policies.pretrained import resolve_checkpoint  # noqa: E402

OUT = ROOT / "experiments" / "results" / "draw_identifiability"
FEATURES = ("friction", "mass offset", "CoM x", "CoM y", "CoM z", "motor strength")


def record(robot: str, robots: int, steps: int, pool: int, episode_s: float,
           informed: bool = False, recipe: str = "v2", seed: int = 0) -> dict[str, np.ndarray]:
    """The oracle's rollout: proprio (T, N, P), the draw's id (T, N) and features
    (T, N, 6), and whether the step starts an episode (T, N)."""
    preset, extra = RECIPES[recipe]
    path = resolve_checkpoint("pretrained", robot)
    cfg = compose_config(f"robot={robot}", "trail=hike", f"env.reward_preset={preset}",
                         f"seed={seed}", *extra, "env.randomization.schedule=steps",
                         "env.randomization.start_after_steps=0",
                         "env.randomization.delay_after_steps=0",
                         f"env.randomization.pool_size={pool}",
                         f"env.episode_length_s={episode_s}",
                         f"env.randomization.observe_physics={str(informed).lower()}")
    cfg = with_checkpoint_body(cfg, path)
    env = make_env(cfg, num_envs=robots)
    proprio, ids, draws, starts = [], [], [], []
    try:
        actor = load_oracle_actor(cfg, path, env)
        # the draws themselves: env.physics_features is what the oracle is shown (nominal
        # for every robot when it is blind)
        truth = torch.as_tensor(env.physics.as_features())
        td = env.reset()
        start = torch.ones(robots, dtype=torch.bool)
        with torch.no_grad():
            for _ in range(steps):
                proprio.append(td[keys.PROPRIO].float().clone())
                ids.append(env.sim.model_of_env.clone())
                draws.append(truth[env.sim.model_of_env])
                starts.append(start)
                stepped, td = env.step_and_maybe_reset(actor(td))  # a done robot restarts
                start = stepped["next", "done"].reshape(robots).clone()
    finally:
        env.close()
    return {"proprio": torch.stack(proprio).numpy(), "ids": torch.stack(ids).numpy(),
            "draws": torch.stack(draws).numpy(), "starts": torch.stack(starts).numpy()}


def windows(data: dict, history: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every window of ``history`` steps inside one episode (flattened), the draw's
    features at its last step and the draw's id."""
    p, d, s, k = data["proprio"], data["draws"], data["starts"], data["ids"]
    xs, ys, ks = [], [], []
    for r in range(p.shape[1]):
        since = 0  # steps since the episode started, the start included
        for t in range(len(p)):
            since = 1 if s[t, r] else since + 1
            if since >= history:
                xs.append(p[t - history + 1:t + 1, r].reshape(-1))
                ys.append(d[t, r])
                ks.append(k[t, r])
    return np.asarray(xs, np.float32), np.asarray(ys, np.float32), np.asarray(ks)


def held_out(ids: np.ndarray) -> np.ndarray:
    """Whether a window's draw is held out: every fourth draw id."""
    return ids % 4 == 0


def held_out_r2(data: dict, history: int, iters: int, seed: int = 0) -> list[float]:
    """R^2 per draw feature on the held-out draws' ``history``-step windows (``fit_r2``)."""
    return fit_r2(*windows(data, history), iters, seed)


def fit_r2(x: np.ndarray, y: np.ndarray, k: np.ndarray, iters: int, seed: int = 0
           ) -> list[float]:
    """R^2 per draw feature on the held-out draws' windows of an MLP regression from
    windows ``x`` to draws ``y`` (draw ids ``k``) fitted on the other draws' windows. A
    third of the fitted draws (ids 1 mod 4) only validates: per feature, the held-out
    predictions are those of the checkpoint (every 100 steps, the untrained net included)
    with the least validation error, so a feature the history does not tell reads ~0, not
    the overfit's negative R^2."""
    test, val = held_out(k), k % 4 == 1
    if np.ptp(y[test], axis=0).min() == 0:  # R^2 undefined: every robot shows one draw
        raise ValueError("the held-out draws do not vary: was the randomisation off?")
    fit = ~(test | val)
    mx, sx = x[fit].mean(0), x[fit].std(0) + 1e-6
    my, sy = y[fit].mean(0), y[fit].std(0) + 1e-6
    xs = torch.from_numpy((x - mx) / sx)
    ys = torch.from_numpy((y - my) / sy)
    xf, yf = xs[fit], ys[fit]
    torch.manual_seed(seed)
    net = nn.Sequential(nn.Linear(x.shape[1], 256), nn.ELU(), nn.Linear(256, 256), nn.ELU(),
                        nn.Linear(256, y.shape[1]))
    opt = torch.optim.Adam(net.parameters(), lr=1e-3, weight_decay=1e-5)
    gen = torch.Generator().manual_seed(seed)
    best_val = np.full(y.shape[1], np.inf)
    best_pred = np.zeros((int(test.sum()), y.shape[1]), np.float32)
    for step in range(iters + 1):
        if step % 100 == 0 or step == iters:
            with torch.no_grad():
                err = ((net(xs[val]) - ys[val]) ** 2).mean(0).numpy()
                better = err < best_val
                best_val[better] = err[better]
                best_pred[:, better] = net(xs[test]).numpy()[:, better]
        if step == iters:
            break
        i = torch.randint(len(xf), (512,), generator=gen)
        loss = ((net(xf[i]) - yf[i]) ** 2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
    yt = y[test]
    resid = ((best_pred * sy + my - yt) ** 2).sum(0)
    total = ((yt - yt.mean(0)) ** 2).sum(0) + 1e-12
    return [round(float(v), 3) for v in 1.0 - resid / total]


def stem(result: dict) -> str:
    """The results' file name: the robot, ``-informed`` when the oracle saw the draw."""
    return result["robot"] + ("-informed" if result["informed"] else "")


def write_outputs(result: dict) -> None:
    hs = result["histories"]
    lines = [f"# What {result['robot'].upper()}'s proprioception history tells of its "
             "physics draw", "",
             "Written by `experiments/draw_identifiability.py`: held-out R^2 of an MLP "
             "regression from the last H steps of proprioception to each draw feature "
             f"({result['robots']} robots x {result['steps']} steps of the shipped oracle, "
             f"{'seeing' if result['informed'] else 'blind to'} the draw, in "
             f"episodes of {result['episode_s']:g} s, {result['draws_met']} of a pool of "
             f"{result['pool']} draws met; every fourth draw held out, never fitted; each "
             "feature's fit stopped at its least error on another quarter of the draws).",
             "", "| H (steps) | windows (fit and validation / held out) | "
             + " | ".join(FEATURES) + " |",
             "|---|---|" + "---|" * len(FEATURES)]
    for h in hs:
        row = result["r2"][str(h)]
        lines.append(f"| {h} | {row['windows'][0]} / {row['windows'][1]} | "
                     + " | ".join(f"{v:.2f}" for v in row["r2"]) + " |")
    (OUT / f"{stem(result)}.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 4))
    for j, name in enumerate(FEATURES):
        ax.plot(hs, [result["r2"][str(h)]["r2"][j] for h in hs], "o-", label=name)
    ax.set_xlabel("history H (policy steps)")
    ax.set_ylabel("held-out R^2")
    ax.set_title(f"{result['robot'].upper()}: the physics draw from proprioception")
    ax.axhline(0, color="grey", lw=0.8)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(OUT / f"{stem(result)}.png", dpi=110)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="g1")
    parser.add_argument("--robots", type=int, default=64)
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--episode-s", type=float, default=4.0)
    parser.add_argument("--histories", type=int, nargs="+", default=[1, 5, 10, 25, 50])
    parser.add_argument("--pool", type=int, default=128)
    parser.add_argument("--iters", type=int, default=3000)
    parser.add_argument("--informed", action="store_true",
                        help="the oracle sees the draw (default: blind to it)")
    args = parser.parse_args()
    if min(args.histories) < 1 or max(args.histories) >= args.steps:
        parser.error(f"--histories must lie in [1, --steps), got {args.histories}")
    torch.set_num_threads(1)
    data = record(args.robot, args.robots, args.steps, args.pool, args.episode_s,
                  args.informed)
    result = {"robot": args.robot, "robots": args.robots, "steps": args.steps,
              "episode_s": args.episode_s, "pool": args.pool, "informed": args.informed,
              "iters": args.iters, "histories": args.histories, "features": list(FEATURES),
              "draws_met": int(len(np.unique(data["ids"]))), "r2": {}}
    for h in args.histories:
        x, y, k = windows(data, h)
        test = held_out(k)
        result["r2"][str(h)] = {"windows": [int((~test).sum()), int(test.sum())],
                                "r2": fit_r2(x, y, k, args.iters)}
        r2 = result["r2"][str(h)]["r2"]
        print(f"H={h}: " + ", ".join(f"{f} {v:.2f}" for f, v in zip(FEATURES, r2, strict=True)),
              flush=True)
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / f"{stem(result)}.json").write_text(json.dumps(result, indent=1) + "\n",
                                            encoding="utf-8")
    write_outputs(result)


if __name__ == "__main__":
    main()
