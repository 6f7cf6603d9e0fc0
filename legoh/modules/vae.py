"""The action VAE behind HLM (appendix 6.1 "Masked VAE for HLM"; docs/hlm.md).

A VAE over one step's joint actions, normalised to [0, 1]. The encoder sees, per joint, the
value, a mask flag and a fixed sinusoidal position code, flattened; residual fully connected
blocks (ReLU) lead to two linear heads, the mean and log variance of the latent. The decoder
maps a latent through residual blocks to a sigmoid, so its output is bounded like its target.

The masked VAE (HLM) is trained to rebuild the FULL action from a copy with random joints
hidden, so its latent has to encode how joints depend on each other; the vanilla VAE (the
ablation "vanilla VAE prior") always sees the full action. Shapes: B is any batch shape,
J the number of joints.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor, nn

LOGVAR_RANGE = (-10.0, 10.0)  # keeps exp(logvar) finite early in training (std 7e-3 .. 150)
POS_BASE = 100.0  # wavelength base of the joint code: ~20 joints need far fewer than 10 000


@dataclass(frozen=True)
class ActionVAEConfig:
    """Sizes and training mode of the action VAE. The paper gives the layer types only
    (ResidualFC, ReLU, two linear heads, sigmoid out); every number here is ours."""

    hidden: int = 256  # width of every residual block
    blocks: int = 3  # residual blocks in the encoder, and again in the decoder
    latent: int = 32  # latent size, the space HLM compares actions in
    pos_dim: int = 8  # size of each joint's sinusoidal position code (even)
    masked: bool = True  # masked VAE (HLM) or vanilla VAE (the ablation)
    mask_ratio: float = 0.3  # fraction of joints hidden in a masked copy (at least one)
    masked_rows: float = 0.5  # share of a training batch given a masked copy; the rest full
    kl_weight: float = 1e-3  # beta: scales loss_kl (the ELBO's 1 lets the posterior collapse)

    def __post_init__(self) -> None:
        if self.pos_dim < 2 or self.pos_dim % 2:
            raise ValueError(f"pos_dim must be even and at least 2, got {self.pos_dim}")
        if not 0.0 < self.mask_ratio <= 1.0:
            raise ValueError(f"mask_ratio must be in (0, 1], got {self.mask_ratio}")
        if not 0.0 <= self.masked_rows <= 1.0:
            raise ValueError(f"masked_rows must be in [0, 1], got {self.masked_rows}")


class ResidualFC(nn.Module):
    """``relu(x + Linear(relu(Linear(x))))``: (B, width) -> (B, width)."""

    def __init__(self, width: int) -> None:
        super().__init__()
        self.net = nn.Sequential(nn.Linear(width, width), nn.ReLU(), nn.Linear(width, width))

    def forward(self, x: Tensor) -> Tensor:
        """(B, width) -> (B, width)."""
        return torch.relu(x + self.net(x))


def joint_position_codes(num_joints: int, dim: int) -> Tensor:
    """Transformer-style sinusoids of the joint index: (num_joints, dim), in [-1, 1]."""
    index = torch.arange(num_joints, dtype=torch.float32)[:, None]
    freq = POS_BASE ** (-torch.arange(0, dim, 2, dtype=torch.float32) / dim)
    angle = index * freq
    return torch.stack([angle.sin(), angle.cos()], dim=-1).reshape(num_joints, dim)


def random_joint_mask(batch: int, num_joints: int, ratio: float,
                      generator: torch.Generator | None = None,
                      device: torch.device | str | None = None) -> Tensor:
    """Hide ``max(1, round(ratio * num_joints))`` joints per row, chosen uniformly at random.

    Returns a (batch, num_joints) bool mask, True = hidden. A fixed count (not a coin per
    joint) keeps every row's difficulty the same and guarantees a masked joint in each row.
    The draw happens on the generator's device (cpu without one), so a cpu generator can
    seed masks for cuda actions; the mask is then moved to ``device`` (default: the draw's).
    """
    if not 0.0 < ratio <= 1.0:
        raise ValueError(f"mask ratio must be in (0, 1], got {ratio}")
    count = min(num_joints, max(1, round(ratio * num_joints)))
    draw_on = generator.device if generator is not None else device
    scores = torch.rand(batch, num_joints, generator=generator, device=draw_on)
    ranks = scores.argsort(dim=-1).argsort(dim=-1)  # a random permutation of 0..J-1 per row
    return (ranks < count).to(device if device is not None else scores.device)


def normalize_actions(action: Tensor, bound: float) -> Tensor:
    """Raw policy actions in [-bound, bound] -> [0, 1], clamped (the decoder's sigmoid range)."""
    if bound <= 0:
        raise ValueError(f"action bound must be positive, got {bound}")
    return ((action / bound + 1.0) * 0.5).clamp(0.0, 1.0)


def check_actions(action: Tensor, num_joints: int, name: str = "actions") -> None:
    """Raise a ValueError naming ``name`` when the last dim is not J or a value is not finite.

    The finiteness test reads one bool back from the device: a NaN from a diverged student
    would otherwise pass silently through the sigmoid-bounded VAE.
    """
    if action.ndim < 1 or action.shape[-1] != num_joints:
        raise ValueError(f"{name}: expected (..., {num_joints}) joints, got {tuple(action.shape)}")
    if not bool(torch.isfinite(action).all()):
        raise ValueError(f"{name}: contains NaN or inf")


class ActionEncoder(nn.Module):
    """(B, J) actions in [0, 1] and an optional (B, J) mask -> mu, logvar (B, latent).

    A separate module so the HLM loss can run it with detached weights (frozen encoder,
    gradients still reaching the action) through ``torch.func.functional_call``.
    """

    def __init__(self, num_joints: int, cfg: ActionVAEConfig) -> None:
        super().__init__()
        self.num_joints = num_joints
        # Fixed, not learned: in a flattened MLP a per-slot constant input acts like a bias,
        # but it makes each joint's feature self-describing (the paper's positional encoding).
        self.register_buffer("pos", joint_position_codes(num_joints, cfg.pos_dim))
        self.inp = nn.Sequential(nn.Linear(num_joints * (2 + cfg.pos_dim), cfg.hidden), nn.ReLU())
        self.blocks = nn.Sequential(*(ResidualFC(cfg.hidden) for _ in range(cfg.blocks)))
        self.mu = nn.Linear(cfg.hidden, cfg.latent)
        self.logvar = nn.Linear(cfg.hidden, cfg.latent)

    def forward(self, actions01: Tensor, mask: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """(B..., J) in [0, 1], mask (B..., J) bool or None -> mu, logvar (B..., latent)."""
        check_actions(actions01, self.num_joints)
        batch = actions01.shape[:-1]
        x = actions01.reshape(-1, self.num_joints)
        if mask is None:
            flag = torch.zeros_like(x)
        else:
            if mask.shape != actions01.shape:
                raise ValueError(f"mask shape {tuple(mask.shape)} != actions "
                                 f"{tuple(actions01.shape)}")
            flag = mask.reshape(-1, self.num_joints).to(x.dtype)
        # A hidden joint reads 0 (a valid action value) with its flag set, so the flag, not
        # the value, tells the network that the joint is missing.
        value = x * (1.0 - flag)
        pos = self.pos.to(x.dtype).expand(x.shape[0], -1, -1)
        feats = torch.cat([value[..., None], flag[..., None], pos], dim=-1)  # (b, J, 2 + P)
        h = self.blocks(self.inp(feats.flatten(1)))
        logvar = self.logvar(h).clamp(*LOGVAR_RANGE)
        return self.mu(h).reshape(*batch, -1), logvar.reshape(*batch, -1)


class ActionVAE(nn.Module):
    """VAE over one step's joint actions in [0, 1] (see the module docstring).

    Args:
        num_joints: J, the action size of the robot (19 for H1, 23 for G1 in our configs).
        cfg: sizes and mode; ``cfg.masked`` only changes how :func:`legoh.objectives.hlm.
            vae_loss` trains it, the network is the same.
    """

    def __init__(self, num_joints: int, cfg: ActionVAEConfig | None = None) -> None:
        super().__init__()
        cfg = cfg if cfg is not None else ActionVAEConfig()
        self.cfg = cfg
        self.num_joints = num_joints
        self.encoder = ActionEncoder(num_joints, cfg)
        self.decoder = nn.Sequential(
            nn.Linear(cfg.latent, cfg.hidden), nn.ReLU(),
            *(ResidualFC(cfg.hidden) for _ in range(cfg.blocks)),
            nn.Linear(cfg.hidden, num_joints),
        )
        # per-joint centre and spread of the raw actions (to_unit); none until fit_action_range
        self.register_buffer("center", torch.zeros(num_joints))
        self.register_buffer("spread", torch.ones(num_joints))

    def to_unit(self, actions: Tensor, bound: float) -> Tensor:
        """Raw actions (B..., J) -> [0, 1]: ``normalize_actions((a - center) / spread,
        bound)``; with no fitted range, ``normalize_actions(a, bound)``."""
        return normalize_actions((actions - self.center) / self.spread, bound)

    def from_unit(self, actions01: Tensor, bound: float) -> Tensor:
        """The inverse of :meth:`to_unit` (inside the range): [0, 1] -> raw actions."""
        return self.center + self.spread * bound * (2.0 * actions01 - 1.0)

    @torch.no_grad()
    def fit_action_range(self, actions: Tensor, bound: float, sigmas: float = 3.0) -> None:
        """Centre each joint on its mean over ``actions`` (B, J) and scale it so that
        ``sigmas`` standard deviations either side fill [0, 1]. A walking policy's actions
        span a few % of the env's clip range (H1 walker: std 0.25-2.1 against a clip of
        20): normalised by the clip alone, the VAE learned no more than each joint's mean
        (docs/hlm.md)."""
        check_actions(actions, self.num_joints)
        flat = actions.reshape(-1, self.num_joints).to(self.center)
        self.center.copy_(flat.mean(0))
        std = flat.std(0) if flat.shape[0] > 1 else torch.ones_like(self.spread)
        self.spread.copy_((sigmas * std / bound).clamp_min(1e-6))

    def _load_from_state_dict(self, state_dict, prefix, *args, **kwargs) -> None:
        """Checkpoints from before the fitted range: no centre, unit spread."""
        state_dict.setdefault(prefix + "center", torch.zeros_like(self.center))
        state_dict.setdefault(prefix + "spread", torch.ones_like(self.spread))
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)

    def encode(self, actions01: Tensor, mask: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """(B..., J) in [0, 1], mask (B..., J) bool (True = hidden) -> mu, logvar (B..., latent)."""
        return self.encoder(actions01, mask)

    def decode_logits(self, z: Tensor) -> Tensor:
        """(B..., latent) -> (B..., J) pre-sigmoid outputs (for a numerically stable BCE)."""
        return self.decoder(z)

    def decode(self, z: Tensor) -> Tensor:
        """(B..., latent) -> (B..., J) reconstructed actions in [0, 1]."""
        return torch.sigmoid(self.decoder(z))

    def forward(self, actions01: Tensor, mask: Tensor | None = None) -> dict[str, Tensor]:
        """Encode, sample z by reparameterisation (mu in eval mode), decode.

        Returns ``recon`` (B..., J) in [0, 1], ``logits`` (its pre-sigmoid), ``mu``,
        ``logvar`` and ``z`` (B..., latent).
        """
        mu, logvar = self.encode(actions01, mask)
        if self.training:
            z = mu + torch.randn_like(mu) * (0.5 * logvar).exp()
        else:
            z = mu
        logits = self.decode_logits(z)
        return {"recon": torch.sigmoid(logits), "logits": logits, "mu": mu, "logvar": logvar,
                "z": z}

