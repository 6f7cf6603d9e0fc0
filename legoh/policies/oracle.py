"""The oracle's networks: actor, critic and adaptation module, fresh (sized from an env) or
from a checkpoint, which carries the network settings it was trained with."""

from __future__ import annotations

from pathlib import Path

import torch
from omegaconf import DictConfig, OmegaConf

from legoh.checkpoint import CheckpointError, check_layout, load_checkpoint
from legoh.config.algo import OracleConfig
from legoh.envs.mdp.observations import PRIVILEGED_WIDTH
from legoh.keys import PRIVILEGED
from legoh.modules.actor_critic import (
    OracleInputDims,
    OracleNetConfig,
    head_input_offset,
    make_oracle_actor_critic,
)
from legoh.modules.encoders import make_adaptation_module
from legoh.policies.pretrained import resolve_checkpoint

ORACLE_MODELS = ("actor", "critic", "adaptation")  # a checkpoint's model names


def oracle_networks(cfg: DictConfig, dims: OracleInputDims, num_actions: int) -> tuple:
    """(actor, critic, adaptation module) for inputs ``dims`` and ``num_actions`` joints,
    with the head and critic of ``cfg.algo``."""
    algo = cfg.algo
    net = OracleNetConfig(init_std=algo.init_noise_std,
                          critic=tuple(int(size) for size in algo.critic_hidden))
    actor, critic = make_oracle_actor_critic(dims, num_actions, algo.tanh_bound, net)
    return actor, critic, make_adaptation_module(dims.proprio, dims.history)


def build_oracle(env, cfg: DictConfig) -> tuple:
    """(dims, actor, critic, adaptation module) sized from ``env``'s specs."""
    dims = OracleInputDims.from_spec(env.observation_spec)
    return (dims, *oracle_networks(cfg, dims, env.num_actions))


def oracle_stage_config(cfg: DictConfig, **algo) -> DictConfig:
    """``cfg`` with the oracle stage's algo settings (defaults, then ``algo``): the config
    of a stage-2 run's teacher."""
    merged = OmegaConf.merge(cfg, {"algo": None})
    merged.algo = OmegaConf.structured(OracleConfig(**algo))
    return merged


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


# the critic of checkpoints from before extra["critic_hidden"] was written (the default then)
LEGACY_CRITIC = [512, 256, 128]


def oracle_net_config(cfg: DictConfig, state: dict) -> DictConfig:
    """``cfg`` with the network settings a checkpoint was trained with (the head's
    ``algo.tanh_bound``, ``algo.critic_hidden``): what rebuilds its actor and critic."""
    algo = state.get("config", {}).get("algo", {})
    critic = state.get("extra", {}).get("critic_hidden", algo.get("critic_hidden"))
    return OmegaConf.merge(cfg, {"algo": {
        "tanh_bound": algo.get("tanh_bound", cfg.algo.tanh_bound),
        "critic_hidden": list(critic or LEGACY_CRITIC)}})


def load_oracle(cfg: DictConfig, path: str | Path, num_actions: int,
                dims: OracleInputDims | None = None, need: tuple[str, ...] = ORACLE_MODELS
                ) -> tuple:
    """(actor, critic, adaptation module) of oracle checkpoint ``path``, rebuilt from its
    own network settings. ``dims``: the inputs the caller feeds (a checkpoint of another
    layout is refused, naming the keys); None: the checkpoint's own layout. ``need``: the
    models the file must hold (an evaluation needs only the actor); the others are loaded
    when present."""
    state = load_oracle_checkpoint(path, cfg, dims)
    dims = dims or OracleInputDims.from_layout(state["layout"])
    nets = oracle_networks(oracle_net_config(cfg, state), dims, num_actions)
    for name, module in zip(ORACLE_MODELS, nets, strict=True):
        if name in need or name in state["models"]:
            module.load_state_dict(state["models"][name])
    return nets


def load_oracle_actor(cfg: DictConfig, path: str | Path, env):
    """The actor of oracle checkpoint ``path`` (``pretrained``: the robot's shipped one) for
    ``env``; a checkpoint of another robot or observation layout is refused, naming the
    field."""
    path = resolve_checkpoint(str(path), cfg.robot.name)
    return load_oracle(cfg, path, env.num_actions, OracleInputDims.from_spec(env.observation_spec),
                       need=("actor",))[0]


def load_teacher(cfg: DictConfig, path: str | Path, env) -> tuple:
    """A stage-2 run's teacher: the frozen oracle actor (eval mode) and its critic (the
    student's critic starts from it). Settings the checkpoint lacks are the oracle stage's
    defaults, not the student's."""
    actor, critic, _ = load_oracle(oracle_stage_config(cfg), path, env.num_actions,
                                   OracleInputDims.from_spec(env.observation_spec),
                                   need=("actor", "critic"))
    actor.requires_grad_(False)
    return actor.eval(), critic
