"""Stage 1: the oracle, trained with PPO on privileged inputs.

Read it top to bottom: build the env and the networks, collect a batch with torchrl's
Collector, compute advantages with GAE, run the PPO epochs, fit the adaptation module, log,
checkpoint. A killed run resumes from its last checkpoint with ``resume=PATH``.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf
from tqdm import tqdm

from legoh import keys
from legoh.checkpoint import load_checkpoint, make_payload, restore_rng, save_checkpoint
from legoh.envs.hiking_env import HikingEnv, make_env
from legoh.logs import McapLog, ScalarCSV
from legoh.modules.actor_critic import (
    OracleInputDims,
    OracleNetConfig,
    make_oracle_actor_critic,
)
from legoh.modules.encoders import make_adaptation_module
from legoh.objectives.adaptation import adaptation_loss
from legoh.objectives.ppo import make_ppo, ppo_update
from legoh.runs import GracefulStop, iterations_left, mujoco_log_in, run_lock, warn_diverged
from legoh.train.collect import (
    make_collector,
    mirror_curriculum,
    policy_device,
    sync_weights,
)


@dataclass
class OracleRun:
    """What a training run leaves behind."""

    actor: torch.nn.Module
    checkpoint: Path
    csv: Path
    mcap: Path
    iterations: int


def build_oracle(env: HikingEnv, cfg: DictConfig):
    """Actor, critic and adaptation module sized from the env's specs."""
    dims = OracleInputDims.from_spec(env.observation_spec)
    net = OracleNetConfig(init_std=cfg.algo.init_noise_std)
    actor, critic = make_oracle_actor_critic(dims, env.num_actions, cfg.algo.tanh_bound, net)
    adaptation = make_adaptation_module(dims.proprio, dims.history)
    return dims, actor, critic, adaptation


def batch_scalars(batch) -> dict[str, float]:
    """Per-iteration means of what the env reported: rewards, each term, levels, outcomes."""
    nxt = batch["next"]
    done = nxt["done"].float()
    ended = nxt[keys.EPISODE_STEPS][nxt["done"].squeeze(-1)]
    stats = {
        "reward": float(nxt["reward"].mean()),
        # mean length of the episodes that ended in this batch; NaN when none did (the
        # frames-over-dones ratio it replaces read as the whole batch then)
        "episode_frames": float(ended.float().mean()) if ended.numel() else float("nan"),
        "level_mean": float(nxt[keys.LEVEL].float().mean()),
        "reached_frac": float(nxt[keys.REACHED].float().sum() / max(done.sum().item(), 1.0)),
        "fell_frac": float(nxt[keys.FELL].float().sum() / max(done.sum().item(), 1.0)),
        "diverged": float(nxt[keys.DIVERGED].sum()),  # envs reset for a diverged simulation
        "progress": float(nxt[keys.PROGRESS].float().mean()),
    }
    for name, value in nxt[keys.REWARD_TERMS].items():
        stats[f"reward/{name}"] = float(value.mean())
    return stats


def train_oracle(cfg: DictConfig, out_dir: Path, resume: str | None = None,
                 on_iteration=None, resume_hint: str | None = None) -> OracleRun:
    """Train the oracle for ``cfg.algo.total_frames`` env steps; returns the trained actor.

    ``on_iteration(it, stats, actor)``, if given, runs after each iteration is logged (the
    learn-to-walk benchmark evaluates milestones there); returning True stops training.
    SIGINT / SIGTERM end the run after the iteration under way with a checkpoint, closed
    logs and the command that resumes it (``resume_hint``; default ``python run.py ...
    resume=<checkpoint>``), then exit (:class:`legoh.runs.GracefulStop`). A second run into
    ``out_dir`` while this one lives is refused (:func:`legoh.runs.run_lock`).
    """
    from legoh.threads import torch_threads

    with (run_lock(out_dir), mujoco_log_in(out_dir), torch_threads(cfg.algo.torch_threads),
          GracefulStop() as stop):
        return _train_oracle(cfg, out_dir, resume, on_iteration, stop, resume_hint)


def _train_oracle(cfg: DictConfig, out_dir: Path, resume: str | None,
                  on_iteration, stop: GracefulStop, resume_hint: str | None) -> OracleRun:
    algo = cfg.algo
    out_dir.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(cfg.seed)
    gen = torch.Generator().manual_seed(cfg.seed)
    device = policy_device(cfg)  # the learner's; the envs step on the CPU
    env = make_env(cfg, num_envs=algo.num_envs)
    dims, actor, critic, adaptation = build_oracle(env, cfg)
    for module in (actor, critic, adaptation):
        module.to(device)
    loss, gae = make_ppo(actor, critic, algo)
    optimizer = torch.optim.Adam(loss.parameters(), lr=algo.lr)
    adapt_optim = torch.optim.Adam(adaptation.parameters(), lr=algo.adaptation_lr)
    layout = dims.as_layout()
    models = {"actor": actor, "critic": critic, "adaptation": adaptation}
    optims = {"ppo": optimizer, "adaptation": adapt_optim}

    start = 0
    if resume:
        state = load_checkpoint(resume, expect_robot=cfg.robot.name, expect_layout=layout)
        start = restore_training(state, models, optims, env)
        print(f"[legoh] resumed from {resume} at iteration {start}")

    frames_per_batch = algo.num_envs * algo.steps_per_env
    iterations = max(1, algo.total_frames // frames_per_batch)
    left = iterations_left(start, iterations, frames_per_batch, algo.total_frames, resume)
    collector = make_collector(cfg, functools.partial(make_env, cfg), actor, frames_per_batch,
                               left * frames_per_batch, env=env)
    csv = ScalarCSV(out_dir / "train.csv", resume=bool(resume), until=start)
    mcap = McapLog(out_dir, stem="train")
    ckpt_path = out_dir / "oracle.pt"
    resolved = OmegaConf.to_container(cfg, resolve=True, enum_to_str=True)

    def checkpoint(iteration: int) -> None:
        payload = make_payload(
            models=models, optimizers=optims, iteration=iteration, robot=cfg.robot.name,
            layout=layout, config=resolved,
            curriculum={"level": env.level.tolist(), "global_steps": env.global_steps})
        save_checkpoint(ckpt_path, payload)

    bar = tqdm(total=iterations, initial=start, desc="oracle PPO", unit="it")
    it = start
    tick = time.perf_counter()
    for batch in stop.batches(collector):
        # (envs, time) on the learner's device, whatever the collector
        batch = batch.reshape(-1, batch.shape[-1]).to(device)
        with torch.no_grad():
            gae(batch)
        stats = ppo_update(loss, optimizer, batch.reshape(-1), algo, gen, actor=actor)
        adapt = adaptation_loss(adaptation, actor, batch.reshape(-1), gen)
        adapt_optim.zero_grad()
        adapt.backward()
        adapt_optim.step()
        stats["loss_adaptation"] = float(adapt.detach())
        sync_weights(collector)  # the workers act with the updated actor from the next batch
        mirror_curriculum(collector, env, batch)  # workers' levels -> checkpoint
        stats.update(batch_scalars(batch))
        now = time.perf_counter()
        stats["frames_per_s"] = frames_per_batch / (now - tick)
        tick = now
        it += 1
        record_iteration(it, iterations, stats, batch, algo, csv, mcap, env.dt, checkpoint)
        bar.update(1)
        ep = stats["episode_frames"]
        bar.set_postfix(fps=f"{stats['frames_per_s']:.0f}", reward=f"{stats['reward']:.3f}",
                        ep_len="-" if np.isnan(ep) else f"{ep * env.dt:.1f}s",
                        fell=f"{stats['fell_frac']:.2f}", level=f"{stats['level_mean']:.2f}")
        if on_iteration is not None and on_iteration(it, stats, actor):
            checkpoint(it)
            break
    bar.close()
    collector.shutdown()
    csv.close()
    mcap.close()
    if it == start or stop.signum:  # nothing trained, or a signal: leave a checkpoint behind
        checkpoint(it)
    stop.exit_if_signalled(ckpt_path, resume_hint)
    return OracleRun(actor=actor, checkpoint=ckpt_path, csv=csv.path, mcap=mcap.path,
                     iterations=it)


def restore_training(state: dict, models: dict, optims: dict, env) -> int:
    """Load a checkpoint's modules, optimisers, curriculum and RNG into a run; returns the
    iteration to continue from."""
    for name, module in models.items():
        module.load_state_dict(state["models"][name])
    for name, opt in optims.items():
        opt.load_state_dict(state["optimizers"][name])
    env.level[:] = torch.as_tensor(state["curriculum"]["level"])
    env.global_steps = int(state["curriculum"]["global_steps"])
    restore_rng(state["rng"])
    return int(state["iteration"])


def record_iteration(it: int, iterations: int, stats: dict, batch, algo, csv: ScalarCSV,
                     mcap: McapLog, dt: float, checkpoint) -> None:
    """An iteration's scalars to CSV and MCAP; a trajectory every ``algo.trajectory_every``
    and a checkpoint (``checkpoint(it)``) every ``algo.checkpoint_every`` iterations and
    at the last one."""
    csv.write(it, stats)
    mcap.log_scalars(it, stats)
    warn_diverged(csv.path.parent, it, stats.get("diverged", 0.0))
    if it % algo.trajectory_every == 0 or it == iterations:
        log_trajectory(mcap, it, batch, dt)
    if it % algo.checkpoint_every == 0 or it == iterations:
        checkpoint(it)


def log_trajectory(mcap: McapLog, iteration: int, batch, dt: float, env_index: int = 0) -> None:
    """Record one robot's path through the batch (base pose, joints, goals) to MCAP."""
    nxt = batch["next"][env_index].cpu()
    proprio = nxt[keys.PROPRIO]
    num_actions = batch["action"].shape[-1]
    mcap.log_trajectory(
        iteration,
        base_pos=nxt[keys.BASE_POS].numpy(),
        base_quat=nxt[keys.BASE_QUAT].numpy(),
        joint_pos=proprio[:, 6:6 + num_actions].numpy(),  # relative to the default pose
        goals=nxt[keys.EXPERT_GOALS].numpy(),
        dt=dt,
        env=env_index,
    )
