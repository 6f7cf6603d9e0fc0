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
from omegaconf import DictConfig, OmegaConf

from legoh.checkpoint import CheckpointError, check_layout, load_checkpoint
from legoh.envs.hiking_env import HikingEnv, make_env
from legoh.envs.mdp.observations import PRIVILEGED_WIDTH
from legoh.keys import PRIVILEGED
from legoh.modules.actor_critic import (
    OracleInputDims,
    OracleNetConfig,
    head_input_offset,
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


PRETRAINED_DIR = Path(__file__).resolve().parents[2] / "pretrained"


def pretrained_path(robot: str, stage: str = "oracle") -> Path:
    """``pretrained/<robot>_<stage>.pt``, the file ``init=pretrained`` and
    ``checkpoint=pretrained`` pick."""
    path = PRETRAINED_DIR / f"{robot}_{stage}.pt"
    if not path.is_file():
        have = sorted(p.name for p in PRETRAINED_DIR.glob("*.pt"))
        raise FileNotFoundError(f"no pretrained {stage} for robot {robot!r} at {path} "
                                f"(shipped: {have})")
    return path


def resolve_checkpoint(value: str, robot: str, stage: str = "oracle") -> Path:
    """A checkpoint setting: ``pretrained`` (the shipped file of the robot) or a path."""
    return pretrained_path(robot, stage) if value == "pretrained" else Path(value)


def load_oracle_checkpoint(path: str | Path, cfg: DictConfig, dims: OracleInputDims | None = None
                           ) -> dict:
    """Read an oracle checkpoint for robot ``cfg.robot`` (and, given ``dims``, refuse a
    different observation layout, naming the keys). Checkpoints from before the privileged
    vector lost its category one-hot are converted exactly (:func:`fold_category_onehot`)."""
    state = fold_category_onehot(load_checkpoint(path, expect_robot=cfg.robot.name))
    if dims is not None:
        check_layout(path, dims.as_layout(), state["layout"])
    return state


def fold_category_onehot(state: dict) -> dict:
    """A checkpoint whose privileged vector ended in a one-hot of its trail's single
    category (older code): that input was the constant 1, so its weights are folded into
    the biases and the column dropped, which leaves every output unchanged."""
    key = "/".join(PRIVILEGED)
    cats = state.get("config", {}).get("trail", {}).get("categories", [])
    width = state["layout"].get(key, (PRIVILEGED_WIDTH,))[0]
    if width == PRIVILEGED_WIDTH:
        return state
    if width != PRIVILEGED_WIDTH + 1 or len(cats) != 1:
        raise CheckpointError(f"privileged inputs {width} wide for categories {cats}: only "
                              f"a one-category one-hot can be converted to {PRIVILEGED_WIDTH}")
    dims = OracleInputDims.from_layout(state["layout"])
    head = dims.head_width(OracleNetConfig())
    off = head_input_offset(dims, OracleNetConfig(), PRIVILEGED)
    for name in ("actor", "critic"):
        sd = dict(state["models"].get(name, {}))
        for wkey, w in list(sd.items()):
            if not wkey.endswith("weight") or w.ndim != 2 or w.shape[1] not in (width, head):
                continue
            col = width - 1 if w.shape[1] == width else off + width - 1
            bkey = wkey[: -len("weight")] + "bias"
            sd[bkey] = sd[bkey] + w[:, col]
            sd[wkey] = torch.cat([w[:, :col], w[:, col + 1:]], 1)
        state["models"][name] = sd
    state["layout"] = {**state["layout"], key: (PRIVILEGED_WIDTH,)}
    return state


def oracle_net_config(cfg: DictConfig, state: dict) -> DictConfig:
    """``cfg`` with the network settings a checkpoint was trained with (the head's
    ``algo.tanh_bound``, ``algo.critic_hidden``): what rebuilds its actor and critic."""
    algo = state.get("config", {}).get("algo", {})
    critic = state.get("extra", {}).get("critic_hidden", algo.get("critic_hidden"))
    return OmegaConf.merge(cfg, {"algo": {
        "tanh_bound": algo.get("tanh_bound", cfg.algo.tanh_bound),
        "critic_hidden": list(critic or cfg.algo.critic_hidden)}})


def load_oracle_actor(cfg: DictConfig, path: str | Path, env: HikingEnv):
    """The actor of oracle checkpoint ``path`` (``pretrained``: the robot's shipped one),
    rebuilt from the checkpoint's own network settings for ``env``; a checkpoint of another
    robot or observation layout is refused, naming the field."""
    path = resolve_checkpoint(str(path), cfg.robot.name)
    state = load_oracle_checkpoint(path, cfg, OracleInputDims.from_spec(env.observation_spec))
    _, actor, _, _ = build_oracle(env, oracle_net_config(cfg, state))
    actor.load_state_dict(state["models"]["actor"])
    return actor


def warm_start(cfg: DictConfig, path: Path, dims: OracleInputDims, models: dict) -> dict:
    """Load the weights of checkpoint ``path`` into a new run's ``models`` (``init=``): same
    robot, layout, head and critic required (a mismatch names the field); optimisers,
    curriculum, randomisation gate and iteration start afresh."""
    state = load_oracle_checkpoint(path, cfg, dims)
    want = {"algo.critic_hidden": [int(x) for x in cfg.algo.critic_hidden],
            "algo.tanh_bound": cfg.algo.tanh_bound}
    have = {"algo.critic_hidden": state.get("extra", {}).get("critic_hidden", [512, 256, 128]),
            "algo.tanh_bound": state.get("config", {}).get("algo", {}).get("tanh_bound")}
    for key in want:
        if want[key] != have[key]:
            raise CheckpointError(f"init={path}: it was trained with {key}={have[key]}, "
                                  f"this run has {key}={want[key]}; set {key}={have[key]}")
    for name, module in models.items():
        module.load_state_dict(state["models"][name])
    return state


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
        runner.resume(load_oracle_checkpoint(resume, cfg, dims))
        print(f"[legoh] resumed from {resume} at iteration {runner.iteration}")
    elif cfg.init:
        init = resolve_checkpoint(cfg.init, cfg.robot.name)
        state = warm_start(cfg, init, dims, runner.models)
        # a fresh Adam's first steps move every weight by about lr: at the configured lr
        # (1e-3) they undid a walker within 5 iterations (every episode a fall in < 1 s), so
        # PPO starts from the lr its adaptive schedule had reached
        lr = state.get("optimizers", {}).get("ppo", {}).get("param_groups", [{}])[0].get("lr")
        for group in optimizer.param_groups:
            group["lr"] = lr or group["lr"]
        print(f"[legoh] weights from {init} (init=); a fresh optimiser at lr "
              f"{optimizer.param_groups[0]['lr']:.2e}, curriculum from level 0")

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


