"""HLM, the hierarchical loss metric set (main paper "HLM"; appendix 3.2, 6.1; docs/hlm.md).

Two parts, trained in alternation during distillation:

* :func:`vae_loss` trains the action VAE on the oracle's actions. The masked VAE rebuilds
  the full action from a copy with random joints hidden (or from the full copy, for part of
  the batch); the vanilla VAE (the ablation) always sees the full copy.
* :func:`hlm_loss` (and its TensorDict wrapper :class:`HLMLoss`) compares the student's
  action to the oracle's in the frozen encoder's latent space: a cosine-similarity loss
  between the two, and a triplet loss with the oracle as anchor, the student as positive and
  a masked copy of the student as negative.

Both return TensorDicts in torchrl's convention: ``loss_*`` entries (already weighted) are
summed by the caller, the rest are detached values for logging.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from tensordict import TensorDict, TensorDictBase
from torch import Tensor
from torchrl.objectives import LossModule

from legoh.keys import ACTION, TEACHER_ACTION
from legoh.modules.vae import ActionVAE, check_actions, random_joint_mask

HLM_MARGIN = 0.2  # cosine-distance margin of the triplet loss (ours; distances lie in [0, 2])


def _cosine_distance(a: Tensor, b: Tensor) -> Tensor:
    """1 - cos(a, b) over the last dim: (B, L), (B, L) -> (B,), in [0, 2]."""
    return 1.0 - F.cosine_similarity(a, b, dim=-1, eps=1e-8)


def vae_loss(vae: ActionVAE, oracle_action: Tensor, bound: float,
             generator: torch.Generator | None = None) -> TensorDict:
    """The VAE's own loss on a batch of oracle actions (B..., J) in [-bound, bound]
    (normalised by :meth:`ActionVAE.to_unit`: centred and scaled per joint once the VAE's
    action range is fitted).

    The target is always the full normalised oracle action. A masked VAE (``vae.cfg.masked``)
    sees, for a ``cfg.masked_rows`` share of rows, a copy with ``cfg.mask_ratio`` of the joints
    hidden; the other rows (and every row of a vanilla VAE) see the full action, so the encoder
    also embeds full actions well, as :func:`hlm_loss` needs.

    Returns:
        ``loss_recon``: binary cross-entropy against the [0, 1] targets (a natural fit for the
        sigmoid output), summed over joints, mean over the batch. ``loss_kl``: KL(q(z|a) ||
        N(0, I)) summed over the latent, mean over the batch, times ``cfg.kl_weight``.
        Logged: ``kl`` (unweighted), ``recon_mae`` (mean |error| in [0, 1] units, all joints),
        ``recon_mae_masked`` (hidden joints only; NaN when nothing was hidden).
    """
    cfg = vae.cfg
    check_actions(oracle_action, vae.num_joints, "oracle_action")
    target = vae.to_unit(oracle_action.detach(), bound).reshape(-1, vae.num_joints)
    rows = target.shape[0]
    mask = torch.zeros_like(target, dtype=torch.bool)
    if cfg.masked:
        mask = random_joint_mask(rows, vae.num_joints, cfg.mask_ratio, generator, target.device)
        draw_on = generator.device if generator is not None else target.device
        keep_rows = torch.rand(rows, 1, generator=generator, device=draw_on)
        mask &= (keep_rows < cfg.masked_rows).to(target.device)
    out = vae(target, mask)
    recon = F.binary_cross_entropy_with_logits(out["logits"], target, reduction="none")
    kl = 0.5 * (out["mu"].pow(2) + out["logvar"].exp() - 1.0 - out["logvar"]).sum(-1).mean()
    err = (out["recon"] - target).abs().detach()
    return TensorDict({
        "loss_recon": recon.sum(-1).mean(),
        "loss_kl": cfg.kl_weight * kl,
        "kl": kl.detach(),
        "recon_mae": err.mean(),
        "recon_mae_masked": err[mask].mean() if mask.any() else err.new_tensor(float("nan")),
    }, batch_size=[])


def frozen_encode(vae: ActionVAE, actions01: Tensor, mask: Tensor | None = None) -> Tensor:
    """mu (B, latent) of the VAE's encoder run with detached weights.

    Gradients reach ``actions01`` but never the VAE's parameters, and nothing on the VAE is
    changed (no ``requires_grad_`` toggling that a concurrent VAE update could trip over).
    """
    weights = {k: v.detach() for k, v in vae.encoder.named_parameters()}
    weights.update(dict(vae.encoder.named_buffers()))
    mu, _ = torch.func.functional_call(vae.encoder, weights, (actions01, mask))
    return mu


def hlm_loss(vae: ActionVAE, oracle_action: Tensor, student_action: Tensor, bound: float,
             c_mt: float = 0.85, c_ms: float = 0.15, margin: float = HLM_MARGIN,
             generator: torch.Generator | None = None) -> TensorDict:
    """HLM on (B..., J) raw actions in [-bound, bound] (normalised by the VAE's
    :meth:`~legoh.modules.vae.ActionVAE.to_unit`); the VAE stays frozen.

    The frozen encoder's means embed the oracle action (anchor, no gradient), the student
    action (positive) and a copy of the student action with ``vae.cfg.mask_ratio`` of its
    joints hidden (negative). Gradients flow into ``student_action`` through both.

    Returns (weighted ``loss_*`` entries, summed by the caller):
        ``loss_hlm_similarity`` = c_ms x mean(1 - cos(mu_oracle, mu_student)).
        ``loss_hlm_triplet`` = c_mt x mean(max(0, d(a, p) - d(a, n) + margin)) with the cosine
        distance d = 1 - cos, so the margin does not depend on the latent's scale.
        Logged: ``hlm_cos`` (mean cosine oracle-student), ``hlm_d_pos``, ``hlm_d_neg`` (mean
        distances anchor-positive and anchor-negative, unweighted).

    c_mt weighs the Masked Triplet term and c_ms the (Masked-VAE) Similarity term: Table 7
    gives only the two numbers; we read the subscripts as t(riplet) and s(imilarity), which
    also puts most of the weight (0.85) on the term that uses the masking (docs/hlm.md).
    """
    j = vae.num_joints
    check_actions(oracle_action, j, "oracle_action")
    check_actions(student_action, j, "student_action")
    if oracle_action.shape != student_action.shape:
        raise ValueError(f"oracle_action {tuple(oracle_action.shape)} and student_action "
                         f"{tuple(student_action.shape)} differ in shape")
    oracle = vae.to_unit(oracle_action.detach(), bound).reshape(-1, j)
    student = vae.to_unit(student_action, bound).reshape(-1, j)
    mask = random_joint_mask(student.shape[0], j, vae.cfg.mask_ratio, generator, student.device)
    with torch.no_grad():
        anchor = frozen_encode(vae, oracle)
    positive = frozen_encode(vae, student)
    negative = frozen_encode(vae, student, mask)
    d_pos = _cosine_distance(anchor, positive)
    d_neg = _cosine_distance(anchor, negative)
    triplet = torch.relu(d_pos - d_neg + margin)
    return TensorDict({
        "loss_hlm_similarity": c_ms * d_pos.mean(),
        "loss_hlm_triplet": c_mt * triplet.mean(),
        "hlm_cos": (1.0 - d_pos).mean().detach(),
        "hlm_d_pos": d_pos.mean().detach(),
        "hlm_d_neg": d_neg.mean().detach(),
    }, batch_size=[])


class HLMLoss(LossModule):
    """HLM as a plug-in loss: reads the student's and the oracle's actions from a TensorDict.

    It needs nothing from the student but an action in the raw policy range with its graph,
    so any student gains HLM without a change (the paper's EP-H + HLM). Run the student on
    the batch first so ``student_key`` holds a differentiable action: an action read back from
    a replay buffer has no graph and gives the student no gradient (warned once).

    Args:
        vae: a trained :class:`~legoh.modules.vae.ActionVAE`; it stays frozen here (train it
            with :func:`vae_loss` and its own optimiser). Registered as a submodule so it
            follows ``.to(device)`` and ``state_dict``: build the student's optimiser from the
            student's parameters, not from this module's.
        bound: the env's action clip (``env.action_clip``), the raw action range.
        c_mt, c_ms: weights of the triplet and similarity terms (appendix Table 7).
        margin: the triplet margin, in cosine distance.
        student_key: the student's action, e.g. ``"action"`` or its Gaussian mean ``"loc"``.
        teacher_key: the oracle's label, ``("teacher","action")``.
        generator: random source of the negatives' masks (the global one if None).

    Keys can also be changed with ``set_keys(student=..., teacher=...)``.
    """

    @dataclass
    class _AcceptedKeys:
        """Configurable TensorDict keys."""

        student: str | tuple[str, ...] = ACTION
        teacher: str | tuple[str, ...] = TEACHER_ACTION

    default_keys = _AcceptedKeys

    def __init__(self, vae: ActionVAE, bound: float, c_mt: float = 0.85, c_ms: float = 0.15,
                 margin: float = HLM_MARGIN, student_key=ACTION, teacher_key=TEACHER_ACTION,
                 generator: torch.Generator | None = None) -> None:
        super().__init__()
        self.vae = vae
        self.bound = bound
        self.c_mt, self.c_ms, self.margin = c_mt, c_ms, margin
        self.generator = generator
        self._warned = False
        self.set_keys(student=student_key, teacher=teacher_key)

    def _forward_value_estimator_keys(self, **kwargs) -> None:
        """No value estimator: nothing to forward."""

    @property
    def in_keys(self) -> list:
        """The two keys read."""
        return [self.tensor_keys.student, self.tensor_keys.teacher]

    @property
    def out_keys(self) -> list[str]:
        """The entries written (the ``loss_*`` terms first)."""
        return ["loss_hlm_similarity", "loss_hlm_triplet", "hlm_cos", "hlm_d_pos", "hlm_d_neg"]

    def forward(self, tensordict: TensorDictBase) -> TensorDict:
        """Batch with (B..., J) student and teacher actions -> scalar HLM terms."""
        student = tensordict.get(self.tensor_keys.student)
        teacher = tensordict.get(self.tensor_keys.teacher)
        if torch.is_grad_enabled() and not student.requires_grad and not self._warned:
            warnings.warn(f"HLMLoss: {self.tensor_keys.student!r} has no graph, so HLM gives the "
                          "student no gradient; run the student on the batch first",
                          stacklevel=2)
            self._warned = True
        return hlm_loss(self.vae, teacher, student, self.bound, self.c_mt, self.c_ms,
                        self.margin, self.generator)
