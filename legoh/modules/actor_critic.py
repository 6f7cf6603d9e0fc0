"""The oracle's actor and critic (appendix 6.1), assembled from TensorDict modules.

Actor inputs (concatenated, in this order): proprioception ``("obs","proprio")`` (P),
the scandot latent z_tea ``("teacher","latent")`` (32, from the scandot encoder), the raw
privileged vector ``("obs","privileged")`` (K), the privileged latent (20) and the expert
goals ``("expert","goals")`` (3, 2) flattened to 6. MLP 512-256-128, ELU, Tanh out.

Action distribution: a diagonal **Normal** with a learned, state-independent std (as
Extreme Parkour and rsl_rl), not a TanhNormal. Why: (1) the paper's policy is theirs and
they train with a Normal; (2) the env clips actions to its bound anyway, so squashing
buys nothing, while TanhNormal's log-prob needs an atanh of the stored action, which is
ill-conditioned near the bound and needs a Jacobian term; (3) a state-independent std is
the exploration knob PPO's entropy bonus acts on. The mean is linear (rsl_rl, mjlab) by
default, its last layer started at 1/100 of its usual scale so the untrained policy holds
the default pose; ``algo.tanh_bound=B`` gives the paper's Tanh output as ``B * tanh(h)``.
With B = the action clip (4.8) the untrained mean swung joints by ~1 rad, the first PPO
update had a KL of ~9.5 and the robot fell in 1.3 s (docs/oracle.md). Samples are not
clipped here (their log-prob stays exact), the env clips them.

The critic has the same shape with its own scandot and privileged encoders (value
gradients never move the actor's z_tea) and a linear output: a Tanh on a value head
would cap returns at 1, so we deviate from the appendix's "same architecture" there.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import torch
from tensordict.nn import (
    AddStateIndependentNormalScale,
    TensorDictModule,
    TensorDictSequential,
)
from torch import nn
from torchrl.modules import IndependentNormal, ProbabilisticActor

from legoh.keys import (
    ACTION,
    COMMAND,
    EXPERT_GOALS,
    PRIVILEGED,
    PROPRIO,
    PROPRIO_HISTORY,
    SCANDOTS,
    TEACHER_LATENT,
)
from legoh.modules.encoders import (
    PRIV_LATENT,
    PRIV_LATENT_EST,
    make_adaptation_module,
    make_privileged_encoder,
    make_scandot_encoder,
    mlp,
)

LOC, SCALE = ("hidden", "action_loc"), ("hidden", "action_scale")
LOG_PROB = "sample_log_prob"
STATE_VALUE = "state_value"
CRITIC_SCAN, CRITIC_PRIV = ("hidden", "critic_scan_latent"), ("hidden", "critic_priv_latent")


@dataclass(frozen=True)
class OracleNetConfig:
    """Network sizes of the oracle stage; defaults from the paper (appendix 6.1) and,
    where it is silent, from Extreme Parkour."""

    scan_encoder: tuple[int, ...] = (128, 64, 32)  # scandots -> z_tea (Tanh out)
    priv_encoder: tuple[int, ...] = (64, 20)  # privileged -> latent (ELU)
    actor: tuple[int, ...] = (512, 256, 128)  # hidden sizes, ELU
    critic: tuple[int, ...] = (512, 256, 128)  # hidden sizes, ELU, linear value out
    adaptation_channels: int = 10  # base channels of the history conv (Extreme Parkour)
    raw_privileged: bool = True  # feed the raw privileged vector too (the paper does)
    init_std: float = 1.0  # initial action std, action units (Extreme Parkour)
    min_std: float = 1e-4  # floor of the std, action units


@dataclass(frozen=True)
class OracleInputDims:
    """Per-env input sizes: proprio P, scandots, privileged K, expert goals (G, 2), history."""

    proprio: int
    privileged: int
    scandots: int = 132
    expert_goals: tuple[int, int] = (3, 2)
    history: int = 10
    command: int = 2

    @classmethod
    def from_spec(cls, observation_spec) -> OracleInputDims:
        """Sizes read from an env's observation ``Composite`` (batch dims first)."""
        def last(key, n: int = 1) -> tuple[int, ...]:
            return tuple(observation_spec[key].shape[-n:])

        hist, proprio = last(PROPRIO_HISTORY, 2)
        return cls(proprio=last(PROPRIO)[0], privileged=last(PRIVILEGED)[0],
                   scandots=last(SCANDOTS)[0], expert_goals=last(EXPERT_GOALS, 2),
                   history=hist, command=last(COMMAND)[0])

    @classmethod
    def from_layout(cls, layout: dict) -> OracleInputDims:
        """Sizes from a checkpoint's layout (``as_layout``'s inverse)."""
        def get(key) -> tuple[int, ...]:
            return tuple(layout["/".join(key)])

        hist, proprio = get(PROPRIO_HISTORY)
        return cls(proprio=get(PROPRIO)[0], privileged=get(PRIVILEGED)[0],
                   scandots=get(SCANDOTS)[0], expert_goals=get(EXPERT_GOALS),
                   history=hist, command=get(COMMAND)[0])

    def head_width(self, cfg: OracleNetConfig) -> int:
        """Input width of the actor and critic MLPs."""
        return sum(_head_inputs(self, cfg, TEACHER_LATENT, PRIV_LATENT)[1])

    def as_layout(self) -> dict[str, tuple[int, ...]]:
        """Observation layout (key -> per-env shape), as stored in checkpoints."""
        return {"/".join(PROPRIO): (self.proprio,), "/".join(PRIVILEGED): (self.privileged,),
                "/".join(SCANDOTS): (self.scandots,),
                "/".join(PROPRIO_HISTORY): (self.history, self.proprio),
                "/".join(EXPERT_GOALS): self.expert_goals, "/".join(COMMAND): (self.command,)}


class ConcatMLP(nn.Module):
    """Flattens each input's trailing ``event_dims[i]`` dims, concatenates, applies an MLP.

    Args:
        in_sizes: flattened size of each input. event_dims: trailing dims per input.
        hidden: hidden sizes (ELU). out_dim: output size. out_act: module class or None.
    """

    def __init__(self, in_sizes: Sequence[int], event_dims: Sequence[int],
                 hidden: Sequence[int], out_dim: int, out_act: type[nn.Module] | None) -> None:
        super().__init__()
        self.event_dims = tuple(event_dims)
        self.net = mlp(sum(in_sizes), [*hidden, out_dim], out_act)

    def forward(self, *xs: torch.Tensor) -> torch.Tensor:
        """Inputs (B..., *event) -> (B..., out_dim)."""
        flat = [x.flatten(start_dim=x.ndim - n) if n > 1 else x
                for x, n in zip(xs, self.event_dims, strict=True)]
        return self.net(torch.cat(flat, dim=-1))


class GaussianPolicyHead(nn.Module):
    """Mean ``bound * tanh(MLP(x))`` (the paper's Tanh output in action units) and a
    learned state-independent std (``exp`` of a log-std parameter, floored at ``min_std``).

    Inputs as :class:`ConcatMLP`; outputs ``(loc, scale)``, each (B..., A). ``bound`` None:
    a linear mean.
    """

    def __init__(self, body: ConcatMLP, action_dim: int, bound: float | None, init_std: float,
                 min_std: float) -> None:
        super().__init__()
        self.body = body
        self.bound = None if bound is None else float(bound)
        last = [m for m in body.net.modules() if isinstance(m, nn.Linear)][-1]
        with torch.no_grad():  # near-zero initial mean: the untrained policy stands
            last.weight.mul_(0.01)
            last.bias.zero_()
        self.std = AddStateIndependentNormalScale(action_dim, scale_mapping="exp",
                                                  scale_lb=min_std,
                                                  init_value=math.log(init_std))

    def forward(self, *xs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Observations -> (loc, scale), (B..., A) each."""
        h = self.body(*xs)
        return self.std(h if self.bound is None else self.bound * torch.tanh(h))


def _head_inputs(dims: OracleInputDims, cfg: OracleNetConfig, scan_key, priv_key
                 ) -> tuple[list, list[int], list[int]]:
    """(keys, flattened sizes, event dims) of the MLP inputs, in the documented order."""
    goals = dims.expert_goals[0] * dims.expert_goals[1]
    rows = [(PROPRIO, dims.proprio, 1), (scan_key, cfg.scan_encoder[-1], 1)]
    if cfg.raw_privileged:
        rows.append((PRIVILEGED, dims.privileged, 1))
    rows += [(priv_key, cfg.priv_encoder[-1], 1), (EXPERT_GOALS, goals, 2),
             (COMMAND, dims.command, 1)]
    keys, sizes, events = (list(c) for c in zip(*rows, strict=True))
    return keys, sizes, events


def head_input_offset(dims: OracleInputDims, cfg: OracleNetConfig, key) -> int:
    """The first column of input ``key`` in the actor and critic MLPs' input."""
    keys, sizes, _ = _head_inputs(dims, cfg, TEACHER_LATENT, PRIV_LATENT)
    return sum(sizes[: keys.index(key)])


def make_oracle_actor_critic(dims: OracleInputDims, action_dim: int, action_bound: float | None,
                             cfg: OracleNetConfig | None = None, *,
                             use_adaptation: bool = False, action_spec=None,
                             ) -> tuple[ProbabilisticActor, TensorDictSequential]:
    """Build the oracle's actor and critic.

    Args:
        dims: input sizes (``OracleInputDims.from_spec(env.observation_spec)``).
        action_dim: A. action_bound: None for a linear mean, else ``bound * tanh``.
        cfg: network sizes. action_spec: optional, attached to the actor (not enforced).
        use_adaptation: take the privileged latent from the adaptation module (proprio
            history) instead of the privileged encoder. The adaptation module takes the
            encoder's place (same position in the sequence), so the scandot encoder and
            the MLP keep their parameter names and a privileged actor's state dict loads
            with ``strict=False`` (only the latent source differs). With
            ``cfg.raw_privileged`` the actor still reads ``("obs","privileged")``; set it
            False for a policy free of privileged input.

    Returns:
        actor: reads proprio, scandots, privileged, expert goals (and the history if
            ``use_adaptation``); writes z_tea ``("teacher","latent")`` (B, 32), the latent
            (B, 20), ``("hidden","action_loc"/"action_scale")`` (B, A), ``"action"`` (B, A)
            and ``"sample_log_prob"`` (B,).
        critic: reads the same observations (always the privileged encoder); writes
            ``"state_value"`` (B, 1).
    """
    cfg = cfg or OracleNetConfig()
    scan = make_scandot_encoder(dims.scandots, cfg.scan_encoder, TEACHER_LATENT)
    if use_adaptation:
        latent_key = PRIV_LATENT_EST
        latent = make_adaptation_module(dims.proprio, dims.history, cfg.priv_encoder[-1],
                                        cfg.adaptation_channels, latent_key)
    else:
        latent_key = PRIV_LATENT
        latent = make_privileged_encoder(dims.privileged, cfg.priv_encoder, latent_key)
    keys, sizes, events = _head_inputs(dims, cfg, TEACHER_LATENT, latent_key)
    body = ConcatMLP(sizes, events, cfg.actor, action_dim, None)
    head = TensorDictModule(
        GaussianPolicyHead(body, action_dim, action_bound, cfg.init_std, cfg.min_std),
        keys, [LOC, SCALE])
    actor = ProbabilisticActor(
        TensorDictSequential(scan, latent, head), in_keys={"loc": LOC, "scale": SCALE},
        out_keys=[ACTION], spec=action_spec, distribution_class=IndependentNormal,
        distribution_kwargs={"tanh_loc": False}, return_log_prob=True, log_prob_key=LOG_PROB,
    )

    c_scan = make_scandot_encoder(dims.scandots, cfg.scan_encoder, CRITIC_SCAN)
    c_priv = make_privileged_encoder(dims.privileged, cfg.priv_encoder, CRITIC_PRIV)
    keys, sizes, events = _head_inputs(dims, cfg, CRITIC_SCAN, CRITIC_PRIV)
    value = TensorDictModule(ConcatMLP(sizes, events, cfg.critic, 1, None), keys, [STATE_VALUE])
    critic = TensorDictSequential(c_scan, c_priv, value)
    return actor, critic
