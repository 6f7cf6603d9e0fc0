"""Stage 1: the oracle, trained with PPO on privileged inputs.

Read it top to bottom: build the env and the networks; the update is GAE, the PPO epochs
and the adaptation module's fit; :class:`legoh.train.runner.OnPolicyRunner` does the rest
(collect, log, checkpoint). A killed run resumes from its last checkpoint with
``resume=PATH``.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass
from pathlib import Path

import torch
from omegaconf import DictConfig

from legoh.checkpoint import load_checkpoint
from legoh.envs.hiking_env import HikingEnv, make_env
from legoh.modules.actor_critic import (
    OracleInputDims,
    OracleNetConfig,
    make_oracle_actor_critic,
)
from legoh.modules.encoders import make_adaptation_module
from legoh.objectives.adaptation import adaptation_loss
from legoh.objectives.ppo import make_ppo, ppo_update
from legoh.runs import GracefulStop
from legoh.train.runner import OnPolicyRunner, training_session


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
    net = OracleNetConfig(init_std=cfg.algo.init_noise_std,
                          critic=tuple(int(size) for size in cfg.algo.critic_hidden))
    actor, critic = make_oracle_actor_critic(dims, env.num_actions, cfg.algo.tanh_bound, net)
    adaptation = make_adaptation_module(dims.proprio, dims.history)
    return dims, actor, critic, adaptation


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
    with training_session(cfg, out_dir) as stop:
        return _train_oracle(cfg, out_dir, resume, on_iteration, stop, resume_hint)


def _train_oracle(cfg: DictConfig, out_dir: Path, resume: str | None,
                  on_iteration, stop: GracefulStop, resume_hint: str | None) -> OracleRun:
    algo = cfg.algo
    torch.manual_seed(cfg.seed)
    gen = torch.Generator().manual_seed(cfg.seed)
    env = make_env(cfg, num_envs=algo.num_envs)
    dims, actor, critic, adaptation = build_oracle(env, cfg)
    runner = OnPolicyRunner(cfg, out_dir, env, {}, {}, dims.as_layout(), "oracle.pt",
                            extra={"critic_hidden": [int(x) for x in algo.critic_hidden]},
                            desc="oracle PPO")
    for module in (actor, critic, adaptation):
        module.to(runner.device)
    loss, gae = make_ppo(actor, critic, algo)
    optimizer = torch.optim.Adam(loss.parameters(), lr=algo.lr)
    adapt_optim = torch.optim.Adam(adaptation.parameters(), lr=algo.adaptation_lr)
    runner.models.update(actor=actor, critic=critic, adaptation=adaptation)
    runner.optims.update(ppo=optimizer, adaptation=adapt_optim)
    if resume:
        runner.resume(load_checkpoint(resume, expect_robot=cfg.robot.name,
                                      expect_layout=runner.layout))
        print(f"[legoh] resumed from {resume} at iteration {runner.iteration}")

    def update(batch) -> dict:
        clock = [time.perf_counter()]
        gae(batch)
        clock.append(time.perf_counter())
        stats = ppo_update(loss, optimizer, batch.reshape(-1), algo, gen, exact_kl=True,
                           lagged=bool(cfg.collector.overlap))
        clock.append(time.perf_counter())
        adapt = adaptation_loss(adaptation, actor, batch.reshape(-1), gen)
        adapt_optim.zero_grad()
        adapt.backward()
        adapt_optim.step()
        clock.append(time.perf_counter())
        stats["loss_adaptation"] = float(adapt.detach())
        stats.update({f"time/{name}": t1 - t0 for name, t0, t1
                      in zip(("gae", "ppo", "adaptation"), clock[:-1], clock[1:], strict=True)})
        return stats

    it = runner.learn(actor, functools.partial(make_env, cfg), update, stop, resume,
                      on_iteration=None if on_iteration is None
                      else lambda i, stats: on_iteration(i, stats, actor),
                      postfix=lambda stats: {"level": f"{stats['level_mean']:.2f}"})
    stop.exit_if_signalled(runner.checkpoint_path, resume_hint)
    return OracleRun(actor=actor, checkpoint=runner.checkpoint_path, csv=runner.csv_path,
                     mcap=runner.mcap_path, iterations=it)


