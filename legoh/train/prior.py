"""The action prior of stage 2 (HLM's masked VAE, or the vanilla-VAE ablation): built,
pre-trained on the oracle's own rollouts, then trained in alternation with distillation.

Pre-training (``algo.prior_pretrain_frames``): before the first iteration the oracle acts
alone (its mean action) in stage 2's env for that many frames and the VAE takes
``algo.prior_pretrain_steps`` steps on those actions, so HLM's first gradients come from an
encoder that has seen the teacher's joint structure, not from a random one. Then, every
iteration, ``algo.vae_steps`` steps on that iteration's labels (the paper: trained
"alternating with distillation"). docs/hlm.md.
"""

from __future__ import annotations

import functools
import math

import torch
from omegaconf import DictConfig
from torchrl.envs import EnvBase
from torchrl.envs.utils import ExplorationType, set_exploration_type

from legoh.modules.actor_critic import LOC


def make_prior(cfg: DictConfig, action_dim: int):
    """The action prior of ``algo.prior``: (VAE or None, its optimiser, the HLM loss)."""
    prior = cfg.algo.prior
    if prior == "none":
        return None, None, None
    if prior not in ("hlm", "vae"):
        raise ValueError(f"unknown algo.prior {prior!r}; choose one of ['hlm', 'vae', 'none']")
    from legoh.modules.vae import ActionVAE, ActionVAEConfig

    vae = ActionVAE(action_dim, ActionVAEConfig(masked=prior == "hlm"))
    optim = torch.optim.Adam(vae.parameters(), lr=cfg.algo.vae_lr)
    w = cfg.algo.weights
    bound = cfg.env.action_clip
    loss = functools.partial(_prior_loss, vae, bound, w.c_mt, w.c_ms, cfg.algo.hlm_margin,
                             prior)
    return vae, optim, loss


def _prior_loss(vae, bound, c_mt, c_ms, margin, prior, teacher, student):
    """HLM's terms (masked VAE); with the vanilla VAE only the latent similarity remains:
    a vanilla VAE has no masked negative, so the triplet term has nothing to push away."""
    from legoh.objectives.hlm import hlm_loss

    out = hlm_loss(vae, teacher, student, bound, c_mt=c_mt, c_ms=c_ms, margin=margin)
    if prior == "vae":
        out = out.exclude(*[k for k in out.keys() if "triplet" in k])
    return out


def train_prior(vae, optim, teacher: torch.Tensor, cfg: DictConfig, gen: torch.Generator,
                steps: int | None = None, size: int | None = None) -> dict[str, float]:
    """``steps`` (default ``algo.vae_steps``) minibatch steps of the prior on the oracle's
    actions ``teacher`` (B, A), minibatches of ``size`` rows (default ``algo.vae_batch``,
    at most B / ``algo.minibatches``); the last step's values as ``prior/*`` scalars. The
    VAE is left frozen (it scores the student)."""
    from legoh.objectives.hlm import vae_loss

    w = cfg.algo.weights
    stats: dict[str, float] = {}
    size = size or max(1, min(cfg.algo.vae_batch, teacher.shape[0] // cfg.algo.minibatches))
    vae.requires_grad_(True)
    for _ in range(cfg.algo.vae_steps if steps is None else steps):
        idx = torch.randint(0, teacher.shape[0], (size,), generator=gen)
        out = vae_loss(vae, teacher[idx], cfg.env.action_clip, generator=gen)
        total = w.w5 * out["loss_recon"] + w.w6 * out["loss_kl"]
        optim.zero_grad()
        total.backward()
        optim.step()
        stats = {f"prior/{k}": float(v.detach()) for k, v in out.items() if v.numel() == 1}
    vae.requires_grad_(False)  # frozen while it scores the student
    return stats


def teacher_actions(env: EnvBase, oracle, frames: int) -> torch.Tensor:
    """The oracle's mean actions (frames', A), frames' >= ``frames``, from the oracle acting
    alone (deterministically) in ``env`` from a reset: the teacher's own states, the
    actions HLM's prior should know before it scores a student."""
    steps = math.ceil(frames / env.batch_size[0])
    device = next(oracle.parameters()).device  # the learner's; the env's may differ

    def act(td):
        return oracle(td.to(device)).to(env.device)

    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        rollout = env.rollout(steps, policy=act, break_when_any_done=False)
    return rollout.get(LOC).reshape(-1, rollout.get(LOC).shape[-1])


def reconstruction_error(vae, actions: torch.Tensor, bound: float) -> float:
    """Mean |error| (action units) of the VAE's reconstruction of full ``actions`` (B, A),
    the latent's mean decoded: comparable between VAEs of different action ranges."""
    with torch.no_grad():
        was = vae.training
        vae.eval()
        x = vae.to_unit(actions, bound)
        recon = vae.from_unit(vae(x, torch.zeros_like(x, dtype=torch.bool))["recon"], bound)
        vae.train(was)
    return float((recon - actions).abs().mean())


def pretrain_prior(vae, optim, env: EnvBase, oracle, cfg: DictConfig, gen: torch.Generator
                   ) -> dict[str, float]:
    """Pre-train the prior on ``algo.prior_pretrain_frames`` of the oracle's own actions in
    ``env``: fit its action range to them (per joint, :meth:`ActionVAE.fit_action_range`),
    then ``algo.prior_pretrain_steps`` steps of ``algo.vae_batch`` rows. Returns the number of
    actions and the reconstruction error (action units) of the fresh and the trained VAE
    and of each joint's mean, the best constant guess."""
    algo = cfg.algo
    actions = teacher_actions(env, oracle, algo.prior_pretrain_frames)
    bound = cfg.env.action_clip
    before = reconstruction_error(vae, actions, bound)
    vae.fit_action_range(actions, bound)
    train_prior(vae, optim, actions, cfg, gen, steps=algo.prior_pretrain_steps,
                size=min(algo.vae_batch, actions.shape[0]))
    return {"actions": actions.shape[0], "recon_error_before": before,
            "recon_error_after": reconstruction_error(vae, actions, bound),
            "recon_error_mean_guess": float((actions - actions.mean(0)).abs().mean())}
