"""PPO from torchrl's parts (GAE, ClipPPOLoss) with rsl_rl's adaptive learning rate.

The update is a plain function so a newcomer can read it top to bottom: epochs x random
minibatches, the summed ``loss_*`` terms, gradient clipping, and a learning rate that
follows the KL between the old and new policy. Logged values are means over all minibatches.

``algo.update_precision=bfloat16`` runs the minibatch forward passes under CPU/CUDA autocast
(matrix products in bfloat16, the loss reductions and the KL in float32): 2.2x faster
forward+backward on a CPU with AMX (experiments/results/bench_train.md), learning measured
in docs/oracle.md. The backward pass follows the forward's dtypes; weights and Adam stay
float32.
"""

from __future__ import annotations

import math
from collections import defaultdict
from pathlib import Path

import torch
from tensordict import TensorDictBase
from torchrl.objectives import ClipPPOLoss
from torchrl.objectives.value import GAE

from legoh.config.algo import OracleConfig
from legoh.modules.actor_critic import LOC, SCALE, STATE_VALUE

LR_BOUNDS = (1e-5, 1e-2)  # rsl_rl's clamp for the adaptive learning rate
PROX_LOG_PROB = "proximal_log_prob"  # a lagged batch's log-prob under the update's start
# cap of pi_theta / pi_behav on a lagged batch (use_current_policy_as_proximal): a row acted
# in the behaviour policy's tail but near the current mean would otherwise weigh ~unbounded
MAX_IMPORTANCE_RATIO = 2.0


class KeepDistPPOLoss(ClipPPOLoss):
    """torchrl's ClipPPOLoss that keeps the minibatch's current policy distribution
    (``last_dist``): the exact KL reads it instead of running the actor a second time
    (that forward was ~15 % of an update).

    On a lagged batch (``PROX_LOG_PROB`` present, :func:`use_current_policy_as_proximal`)
    it is decoupled PPO as torchrl's ``delay_actor=True, max_importance_ratio=`` computes it
    (the same terms, ``tests/test_train_oracle.py``), but with the proximal log-probability
    computed once per update: torchrl runs the proximal actor on every minibatch, which made
    a lagged update 1.4x a plain one (N = 256, 3 epochs, bfloat16).
    """

    last_dist = None

    def _log_weight(self, tensordict, adv_shape):
        prox = tensordict.get(PROX_LOG_PROB, None)
        if prox is None:
            out = super()._log_weight(tensordict, adv_shape=adv_shape)
        else:
            behaviour = tensordict.get(self.tensor_keys.sample_log_prob)
            log_prob, dist, _ = self._get_cur_log_prob(tensordict)
            log_weight = (log_prob - prox).unsqueeze(-1)  # clipped: pi_theta / pi_prox
            # pi_prox / pi_behav, lifted so that pi_theta / pi_behav <= the cap (torchrl's rule)
            log_is = torch.minimum((prox - behaviour).unsqueeze(-1),
                                   math.log(MAX_IMPORTANCE_RATIO) - log_weight.detach())
            out = (log_weight, dist, (prox - log_prob).unsqueeze(-1), log_is)
        self.last_dist = out[1]
        return out


class OnePassGAE:
    """torchrl's GAE, with the critic run once per observation rather than twice.

    torchrl's GAE evaluates the critic on ``obs`` and on ``("next", obs)``; in a collected
    (envs, time) batch the next observation of step t is the observation of step t + 1
    except where the episode ended at t (the next one is the terminal, pre-reset
    observation) and at the batch's last step. So the values of ``obs`` shifted by one step
    serve as next values, and the critic runs on the next observations of those rows only
    (~1/T of them). Exact: tests compare it with torchrl's two-pass GAE; the second pass
    was ~9 % of an update (docs/oracle.md, "The loop").
    """

    def __init__(self, critic, gamma: float, lmbda: float) -> None:
        self.critic = critic
        self.gae = GAE(gamma=gamma, lmbda=lmbda, value_network=None, average_gae=False)

    @torch.no_grad()
    def __call__(self, batch: TensorDictBase) -> TensorDictBase:
        """Writes ``state_value``, ``("next","state_value")``, ``advantage`` and
        ``value_target`` into ``batch`` (shape (envs, time)) and returns it."""
        keys = self.critic.in_keys
        value = self.critic(batch.select(*keys).clone())[STATE_VALUE]
        nxt = batch["next"]
        fresh = nxt["done"].squeeze(-1).clone()  # next obs is not obs[t + 1]
        fresh[..., -1] = True
        next_value = torch.empty_like(value)
        next_value[..., :-1, :] = value[..., 1:, :]
        next_value[fresh] = self.critic(nxt.select(*keys)[fresh].clone())[STATE_VALUE]
        batch.set(STATE_VALUE, value)
        nxt.set(STATE_VALUE, next_value)
        return self.gae(batch)


def make_ppo(actor, critic, cfg: OracleConfig) -> tuple[ClipPPOLoss, OnePassGAE]:
    """ClipPPOLoss (advantages normalised per minibatch, values clipped when
    ``cfg.clip_value``) and GAE over the critic."""
    loss = KeepDistPPOLoss(actor, critic, clip_epsilon=cfg.clip_epsilon,
                           entropy_coeff=cfg.entropy_coef, critic_coeff=cfg.value_coef,
                           loss_critic_type="l2", clip_value=bool(cfg.clip_value),
                           normalize_advantage=True)
    loss.set_keys(sample_log_prob="sample_log_prob")
    return loss, OnePassGAE(critic, cfg.gamma, cfg.gae_lambda)


def loss_keys(loss: ClipPPOLoss, exact_kl: bool) -> list:
    """The keys a minibatch needs: the networks' inputs, the action and its log-prob, the
    advantage and targets (and the acting policy's loc/scale for the exact KL). Gathering
    only these, not the batch's ~100 keys (next observations, info, reward terms), cut
    the minibatch indexing from ~15 % of an update (docs/oracle.md)."""
    k = loss.tensor_keys
    keys = {*loss.actor_network.in_keys, *loss.critic_network.in_keys, k.action,
            k.sample_log_prob, k.advantage, k.value_target, k.value}
    return sorted(keys | ({LOC, SCALE} if exact_kl else set()), key=str)


def adapt_learning_rate(lr: float, kl: float, desired_kl: float) -> float:
    """rsl_rl's rule: shrink the step when the policy moved too far, grow it when too little."""
    if kl > 2.0 * desired_kl:
        lr /= 1.5
    elif 0.0 < kl < desired_kl / 2.0:
        lr *= 1.5
    return min(max(lr, LR_BOUNDS[0]), LR_BOUNDS[1])


def gaussian_kl(loc0: torch.Tensor, scale0: torch.Tensor, loc1: torch.Tensor,
                scale1: torch.Tensor) -> torch.Tensor:
    """Mean over the batch of KL(old || new) between diagonal Gaussians, summed over actions
    (rsl_rl's exact KL: the sampled estimate of a 1.5k-frame minibatch is noisy)."""
    kl = (torch.log(scale1 / scale0) + (scale0**2 + (loc0 - loc1) ** 2) / (2 * scale1**2)
          - 0.5)
    return kl.sum(-1).mean()


def use_current_policy_as_proximal(loss: ClipPPOLoss, data: TensorDictBase) -> None:
    """Decoupled PPO (Hilton et al., 2021) for a lagged batch.

    With ``collector.overlap`` a batch is acted by the weights of the update before the
    last one (the behaviour policy). The weights this update starts from become the
    proximal policy: clipping, the KL and the adaptive learning rate measure the step from
    them, and the surrogate is weighted by pi_theta / pi_behav (capped at
    :data:`MAX_IMPORTANCE_RATIO`). Clipping against the behaviour policy instead counted the
    previous update's step too (the oracle's learning rate then halved each step,
    docs/oracle.md); leaving out the behaviour weight (our first version) let a student's
    actions, acted many stds (0.2) off the policy the update starts from, push huge
    log-probability gradients: the update ran away (docs/unified.md, "Speed"). The
    weight makes such rows count ~0. Writes the proximal log-probability
    (``PROX_LOG_PROB``, read by :class:`KeepDistPPOLoss`) and loc and scale (the exact KL).
    """
    with torch.no_grad():
        dist = loss.actor_network.get_dist(data.select(*loss.actor_network.in_keys).clone())
        data.set(PROX_LOG_PROB, dist.log_prob(data["action"]))
        data.set(LOC, dist.base_dist.loc)
        data.set(SCALE, dist.base_dist.scale)


def fast_bfloat16(device_type: str) -> bool:
    """Whether bfloat16 matrix products are fast on this device: a CUDA GPU that supports
    them, or a CPU with AMX or AVX512-BF16 (elsewhere bfloat16 is emulated, slower than
    float32)."""
    if device_type == "cuda":
        return torch.cuda.is_bf16_supported()
    try:
        flags = Path("/proc/cpuinfo").read_text().split()
    except OSError:  # not Linux: no cheap way to know, stay with float32
        return False
    return "amx_bf16" in flags or "avx512_bf16" in flags


def use_bfloat16(precision: str, device_type: str) -> bool:
    """``algo.update_precision`` (float32 | bfloat16 | auto) resolved for a device."""
    return precision == "bfloat16" or (precision == "auto" and fast_bfloat16(device_type))


def ppo_update(loss: ClipPPOLoss, optimizer: torch.optim.Optimizer, data: TensorDictBase,
               cfg: OracleConfig, generator: torch.Generator | None = None,
               scale: float = 1.0, exact_kl: bool = False, lagged: bool = False
               ) -> dict[str, float]:
    """Epochs of minibatch updates on a flat batch that already holds GAE advantages.

    ``scale`` multiplies the summed loss (the unified stage's w1); logged values are unscaled.
    ``exact_kl`` (the acting policy's ``("hidden","action_loc"/"action_scale")`` stored in
    ``data`` by the collector): the learning rate follows the exact KL between the acting
    and the current policy; else torchrl's sampled ``kl_approx``. ``lagged``: the batch was
    acted with the weights of an earlier update (``collector.overlap``); see
    :func:`use_current_policy_as_proximal`.
    """
    # lagged: the exact KL from the proximal policy. The sampled kl_approx is taken over
    # the behaviour policy's actions, not the proximal one's: on a student's lagged batch
    # it read 1-5 and pinned the learning rate at its floor
    exact_kl = exact_kl or lagged
    data = data.select(*loss_keys(loss, exact_kl))
    if lagged:
        use_current_policy_as_proximal(loss, data)
    sums: dict[str, float] = defaultdict(float)
    count = 0
    size = data.shape[0] // cfg.minibatches
    device_type = next(loss.parameters()).device.type
    bf16 = use_bfloat16(str(getattr(cfg.update_precision, "value", cfg.update_precision)),
                        device_type)
    for _ in range(cfg.epochs):
        order = torch.randperm(data.shape[0], generator=generator)
        for k in range(cfg.minibatches):
            batch = data[order[k * size:(k + 1) * size]]
            with torch.autocast(device_type, dtype=torch.bfloat16, enabled=bf16):
                out = loss(batch)
            if exact_kl:
                new = loss.last_dist.base_dist  # the Normal under IndependentNormal
                with torch.no_grad():
                    out["kl_exact"] = gaussian_kl(batch[LOC], batch[SCALE], new.loc.float(),
                                                  new.scale.float())
            total = scale * sum(v for key, v in out.items() if key.startswith("loss_"))
            optimizer.zero_grad()
            total.backward()
            grad_norm = torch.nn.utils.clip_grad_norm_(loss.parameters(), cfg.max_grad_norm)
            optimizer.step()
            kl = float(out["kl_exact" if exact_kl else "kl_approx"].detach())
            if cfg.desired_kl > 0:
                lr = adapt_learning_rate(optimizer.param_groups[0]["lr"], kl, cfg.desired_kl)
                for group in optimizer.param_groups:
                    group["lr"] = lr
            for key, value in out.items():
                if value.numel() == 1:
                    sums[key] += float(value.detach())
            sums["grad_norm"] += float(grad_norm)
            count += 1
    stats = {key: value / count for key, value in sums.items()}
    stats["lr"] = optimizer.param_groups[0]["lr"]
    return stats
