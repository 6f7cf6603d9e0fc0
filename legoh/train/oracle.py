"""Stage 1: the oracle, trained with PPO on privileged inputs.

Read it top to bottom: :class:`OraclePPO` is the learner (its update is GAE, the PPO
epochs and the adaptation module's fit); :func:`train_oracle` builds the env and the
algorithm and hands both to :class:`legoh.train.runner.OnPolicyRunner`, which does the rest
(collect, log, checkpoint, resume, signals). A killed run resumes from its last checkpoint
with ``resume=PATH``.
"""

from __future__ import annotations

import functools
import time
from pathlib import Path

import torch
from omegaconf import DictConfig

from legoh.checkpoint import CheckpointError
from legoh.envs.hiking_env import HikingEnv, make_env
from legoh.objectives.adaptation import adaptation_loss
from legoh.objectives.ppo import make_ppo, ppo_update
from legoh.policies.embodiment import with_checkpoint_body
from legoh.policies.oracle import LEGACY_CRITIC, build_oracle, load_oracle_checkpoint
from legoh.policies.pretrained import init_checkpoint
from legoh.train.algorithm import Algorithm, start_at_checkpoint_lr
from legoh.train.collect import overlapped, policy_device
from legoh.train.runner import OnPolicyRunner, Run, training_session


class OraclePPO(Algorithm):
    """PPO on the oracle's actor and critic, plus the adaptation module's regression of the
    privileged latent from the proprio history (its own optimiser)."""

    def __init__(self, cfg: DictConfig, env: HikingEnv, device: torch.device | None = None
                 ) -> None:
        algo = self.algo = cfg.algo
        self.cfg, self.name, self.label = cfg, "oracle", "oracle PPO"
        self.device = device or policy_device(cfg)
        self.dims, actor, critic, adaptation = build_oracle(env, cfg)
        self.models = {"actor": actor.to(self.device), "critic": critic.to(self.device),
                       "adaptation": adaptation.to(self.device)}
        self.actor = self.policy = actor
        self.loss, self.gae = make_ppo(actor, critic, algo)  # after the move: it holds params
        self.optimizers = {
            "ppo": torch.optim.Adam(self.loss.parameters(), lr=algo.lr),
            "adaptation": torch.optim.Adam(adaptation.parameters(), lr=algo.adaptation_lr)}
        self.layout = self.dims.as_layout()
        self.extra = {"critic_hidden": [int(x) for x in algo.critic_hidden]}
        self.gen = torch.Generator().manual_seed(cfg.seed)  # minibatch draws

    def update(self, batch) -> dict[str, float]:
        """GAE, the PPO epochs, then one step of the adaptation module."""
        clock = [time.perf_counter()]
        self.gae(batch)
        clock.append(time.perf_counter())
        flat = batch.reshape(-1)
        stats = ppo_update(self.loss, self.optimizers["ppo"], flat, self.algo, self.gen,
                           exact_kl=True, lagged=overlapped(self.cfg))
        clock.append(time.perf_counter())
        adapt = adaptation_loss(self.models["adaptation"], self.actor, flat, self.gen)
        optim = self.optimizers["adaptation"]
        optim.zero_grad()
        adapt.backward()
        optim.step()
        clock.append(time.perf_counter())
        stats["loss_adaptation"] = float(adapt.detach())
        stats.update({f"time/{name}": t1 - t0 for name, t0, t1
                      in zip(("gae", "ppo", "adaptation"), clock[:-1], clock[1:], strict=True)})
        return stats

    def read_checkpoint(self, path: str | Path) -> dict:
        """An oracle checkpoint of this robot and layout (older formats converted)."""
        return load_oracle_checkpoint(path, self.cfg, self.dims)

    def progress(self, stats: dict) -> dict[str, str]:
        return {"level": f"{stats['level_mean']:.2f}"}

    def warm_start(self, path: Path) -> dict:
        """Load the weights of checkpoint ``path`` (``init=``): same robot, layout, head and
        critic required (a mismatch names the field); optimisers, curriculum, randomisation
        gate and iteration start afresh, PPO at the learning rate the checkpoint had reached."""
        state = warm_start(self.cfg, path, self.dims, self.models)
        # a fresh Adam's first steps move every weight by about lr: at the configured lr
        # (1e-3) they undid a walker within 5 iterations (every episode a fall in < 1 s), so
        # PPO starts from the lr its adaptive schedule had reached
        start_at_checkpoint_lr(self.optimizers["ppo"], state)
        return state


def warm_start(cfg: DictConfig, path: Path, dims, models: dict) -> dict:
    """Load the weights of checkpoint ``path`` into a new run's ``models`` (``init=``): same
    robot, layout, head and critic required (a mismatch names the field)."""
    state = load_oracle_checkpoint(path, cfg, dims)
    want = {"algo.critic_hidden": [int(x) for x in cfg.algo.critic_hidden],
            "algo.tanh_bound": cfg.algo.tanh_bound}
    have = {"algo.critic_hidden": state.get("extra", {}).get("critic_hidden", LEGACY_CRITIC),
            "algo.tanh_bound": state.get("config", {}).get("algo", {}).get("tanh_bound")}
    for key in want:
        if want[key] != have[key]:
            raise CheckpointError(f"init={path}: it was trained with {key}={have[key]}, "
                                  f"this run has {key}={want[key]}; set {key}={have[key]}")
    for name, module in models.items():
        module.load_state_dict(state["models"][name])
    return state


def train_oracle(cfg: DictConfig, out_dir: Path, resume: str | None = None,
                 on_iteration=None, resume_hint: str | None = None) -> Run:
    """Train the oracle for ``cfg.algo.total_frames`` env steps; ``run.policy`` is its actor.

    ``on_iteration(it, stats, actor)``, if given, runs after each iteration is logged (the
    learn-to-walk benchmark evaluates milestones there); returning True stops training.
    SIGINT / SIGTERM end the run after the iteration under way with a checkpoint, closed
    logs and the command that resumes it (``resume_hint``; default ``python run.py ...
    resume=<checkpoint>``), then exit (:class:`legoh.runs.GracefulStop`). A second run into
    ``out_dir`` while this one lives is refused (:func:`legoh.runs.run_lock`).
    """
    if resume:  # a resumed run keeps the feet it trained on
        cfg = with_checkpoint_body(cfg, resume)
    with training_session(cfg, out_dir) as stop:
        env = make_env(cfg, num_envs=cfg.algo.num_envs)
        algorithm = OraclePPO(cfg, env)
        runner = OnPolicyRunner(cfg, env, algorithm, out_dir, functools.partial(make_env, cfg))
        if resume:
            runner.resume(resume)
        elif (init := init_checkpoint(cfg.init, cfg.robot.name)) is not None:
            algorithm.warm_start(init)
            print(f"[legoh] weights from {init} (init=); a fresh optimiser at lr "
                  f"{algorithm.optimizers['ppo'].param_groups[0]['lr']:.2e}, curriculum from "
                  f"level 0")
        hook = None if on_iteration is None else (
            lambda it, stats: on_iteration(it, stats, algorithm.actor))
        return runner.learn(stop, on_iteration=hook, resume_hint=resume_hint)
