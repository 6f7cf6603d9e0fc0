"""TC-ViTs: the navigation network of the unified policy (main paper 3.4, appendix 3.1).

One call per depth frame (10 Hz)::

    depth (B, T, H, W) + terminus map --ViViT encoder--> alpha (B, dim)
    depth[:, -1] (current frame)      --shallow CNN----> beta  (B, cnn_out)
    cat(alpha, beta)                  --MLP------------> gamma (B, gamma_dim)
    cat(gamma, goal, proprio), state  --GRU / CT core--> h, new state
    h --heads--> z_uni (B, 32) Tanh, delta_g0 (B, 2), g1..g3 (B, 3, 2)

The encoder is ViViT's factorised self-attention (Arnab et al. 2021, model 3): every layer is a
spatial attention block over the patches of one frame followed by a temporal attention block
over the same patch across frames. The terminus P_B is tiled into two image-shaped channels
beside the depth, so every token carries the final goal. Sizes: :data:`PRESETS`, and
docs/tcvit.md for where each comes from and the resulting parameter and FLOP counts.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from legoh.modules.encoders import mlp
from legoh.modules.temporal import TemporalCore, make_core

GOAL_SCALE = 8.0  # m: distance squashing scale (trails ~16 m: goal_speed 0.8 m/s x 20 s episodes)
GOAL_CHANNELS = 2  # terminus map channels: its direction scaled by the squashed distance
DEPTH_RANGE = 0.5  # depth arrives in [-0.5, 0.5]; the terminus map uses the same range


@dataclass(frozen=True)
class TCViTConfig:
    """Sizes of TC-ViTs. Defaults are the "small" preset (CPU training); see :data:`PRESETS`."""

    # depth input: the env default (legoh/config/env.py DepthConfig): 4 frames of 32 x 24
    frames: int = 4  # frames in the history (paper: 16 frames sub-sampled to 4)
    height: int = 24  # pixels
    width: int = 32  # pixels
    # ViViT encoder
    patch: int = 8  # tubelet 1 frame x patch x patch: a 4 x 3 patch grid at 32 x 24
    dim: int = 64  # token width
    layers: int = 2  # each: one spatial + one temporal attention block
    heads: int = 4  # attention heads (divides dim)
    mlp_ratio: float = 2.0  # feed-forward width / dim
    # shallow CNN on the current frame (Extreme Parkour's depth backbone: conv5, pool, conv3)
    cnn_channels: tuple[int, int] = (8, 16)
    cnn_out: int = 64  # beta's size
    # alpha + beta mixing
    mix_hidden: int = 128
    gamma_dim: int = 64
    # recurrent goal adaptation core
    core: str = "gru"  # gru | transformer (legoh/modules/temporal.py)
    core_hidden: int = 128  # GRU hidden size; the transformer core's token width
    core_layers: int = 1  # GRU layers
    core_ct_layers: int = 2  # causal transformer layers (core="transformer")
    core_context: int = 3  # past steps the causal transformer sees (3 + now = 4 frames)
    core_heads: int = 4  # causal transformer heads
    # outputs
    latent_dim: int = 32  # z_uni: the size of the oracle's z_tea (scandot encoder's last layer)
    num_goals: int = 3  # near-future goals g1..g3 (env: NUM_EXPERT_GOALS)

    def __post_init__(self) -> None:
        if self.height % self.patch or self.width % self.patch:
            raise ValueError(f"patch {self.patch} must divide the depth image "
                             f"{self.width} x {self.height} (the paper preset is sized for "
                             "64 x 48 frames: env.depth.width=64 env.depth.height=48)")
        if self.dim % self.heads or self.core_hidden % self.core_heads:
            raise ValueError("heads must divide dim, and core_heads core_hidden")

    @property
    def patches(self) -> int:
        """Tokens per frame."""
        return (self.height // self.patch) * (self.width // self.patch)

    def core_sizes(self) -> dict[str, int | float]:
        """Keyword sizes for :func:`legoh.modules.temporal.make_core` of ``self.core``."""
        if self.core == "gru":
            return {"hidden": self.core_hidden, "layers": self.core_layers}
        return {"dim": self.core_hidden, "layers": self.core_ct_layers, "heads": self.core_heads,
                "context": self.core_context, "mlp_ratio": self.mlp_ratio}


PRESETS: dict[str, TCViTConfig] = {
    # ~0.4 M parameters: trains at 64 envs on a 2-core CPU (experiments/bench.py model-size)
    "small": TCViTConfig(),
    # 31.25 M (GRU) / 55.92 M (causal transformer) in the paper; sizes chosen to land within a
    # few percent of both (docs/tcvit.md). The image is the camera's native 64 x 48
    # (legoh/config/robot.py CameraConfig), patch 16 as in ViT-B/16, width 512 with 8 heads.
    "paper": TCViTConfig(height=48, width=64, patch=16, dim=512, layers=4, heads=8,
                         mlp_ratio=4.0, cnn_channels=(32, 48), cnn_out=128, mix_hidden=512,
                         gamma_dim=512, core_hidden=512, core_layers=1, core_ct_layers=8,
                         core_context=3, core_heads=8),
}


def tcvit_config(preset: str, core: str = "gru", **overrides) -> TCViTConfig:
    """The named preset with ``core`` and any field overrides applied (a new frozen config)."""
    if preset not in PRESETS:
        raise ValueError(f"unknown TC-ViTs preset {preset!r}; options: {', '.join(PRESETS)}")
    return dataclasses.replace(PRESETS[preset], core=core, **overrides)


def squash_point(xy: Tensor) -> Tensor:
    """(..., 2) point in metres -> (..., 2): its direction times tanh(distance / GOAL_SCALE).

    Bounded by 1 however far the goal is, smooth through zero (~ xy / GOAL_SCALE near it).
    """
    dist = xy.norm(dim=-1, keepdim=True).clamp_min(1e-6)
    return xy * (torch.tanh(dist / GOAL_SCALE) / dist)


class ShallowCNN(nn.Module):
    """Current frame (B, H, W) -> beta (B, out): conv5, max-pool 2, conv3, linear.

    The layout of Extreme Parkour's per-frame depth backbone; the linear layer over the whole
    feature map keeps where things are in the image (near-field detail the coarse ViT patches
    blur).
    """

    def __init__(self, height: int, width: int, channels: tuple[int, int], out: int) -> None:
        super().__init__()
        c1, c2 = channels
        self.conv = nn.Sequential(
            nn.Conv2d(1, c1, kernel_size=5), nn.MaxPool2d(2), nn.ELU(),
            nn.Conv2d(c1, c2, kernel_size=3), nn.ELU(), nn.Flatten(),
        )
        flat = c2 * ((height - 4) // 2 - 2) * ((width - 4) // 2 - 2)
        self.head = nn.Sequential(nn.Linear(flat, out), nn.ELU())

    def forward(self, frame: Tensor) -> Tensor:
        """(B, H, W) -> (B, out)."""
        return self.head(self.conv(frame.unsqueeze(1)))


class AttentionBlock(nn.TransformerEncoderLayer):
    """A pre-norm ``nn.TransformerEncoderLayer`` (same parameters and state dict) whose
    self-attention lays the scores out keys-first, so the softmax runs over dim 1.

    Why: the sequences here are 4 (frames) and 12 (patches) long, and PyTorch's CPU softmax
    over a last dimension that short ran 2-4x slower than over dim 1 (19,664 score
    matrices of 12 x 12: 44 vs 11 ms forward, float32, 1 thread). TC-ViTs forward and
    backward on 1,229 frames: 1,576 -> 1,043 ms under bfloat16 autocast, 1,998 -> 1,531 ms
    in float32 (``docs/unified.md``, Speed). Masks are not supported (none is used here).
    """

    def _sa_block(self, x: Tensor, attn_mask, key_padding_mask, is_causal: bool = False
                  ) -> Tensor:
        if attn_mask is not None or key_padding_mask is not None or is_causal:
            raise ValueError("AttentionBlock takes no attention mask")
        attn = self.self_attn
        b, n, d = x.shape
        h = attn.num_heads
        qkv = F.linear(x, attn.in_proj_weight, attn.in_proj_bias).view(b, n, 3, h, d // h)
        q, k, v = qkv.permute(2, 0, 3, 1, 4).reshape(3, b * h, n, d // h)
        weights = torch.softmax(torch.bmm(k, q.transpose(1, 2) * (d // h) ** -0.5), dim=1)
        out = torch.bmm(weights.transpose(1, 2), v)  # (b * h, queries, d / h)
        out = out.view(b, h, n, d // h).transpose(1, 2).reshape(b, n, d)
        return self.dropout1(F.linear(out, attn.out_proj.weight, attn.out_proj.bias))


class FactorisedViViT(nn.Module):
    """Depth history + terminus map -> alpha (B, dim), ViViT-style factorised attention.

    Tokens: each frame, with the terminus map as extra channels, is cut into patch x patch
    tiles, linearly embedded (a strided convolution), and given a learned spatial (which
    tile) plus temporal (which frame) position embedding. Each layer: spatial attention among
    one frame's tiles, then temporal attention of one tile across frames. Output: the final
    layer-normed tokens, mean-pooled.
    """

    def __init__(self, cfg: TCViTConfig) -> None:
        super().__init__()
        self.cfg = cfg
        d = cfg.dim
        self.embed = nn.Conv2d(1 + GOAL_CHANNELS, d, kernel_size=cfg.patch, stride=cfg.patch)
        self.pos_space = nn.Parameter(torch.randn(cfg.patches, d) * 0.02)
        self.pos_time = nn.Parameter(torch.randn(cfg.frames, 1, d) * 0.02)

        def block() -> AttentionBlock:
            return AttentionBlock(d, cfg.heads, int(cfg.mlp_ratio * d), dropout=0.0,
                                              activation="gelu", batch_first=True,
                                              norm_first=True)

        self.spatial = nn.ModuleList(block() for _ in range(cfg.layers))
        self.temporal = nn.ModuleList(block() for _ in range(cfg.layers))
        self.norm = nn.LayerNorm(d)

    def forward(self, depth: Tensor, terminus: Tensor) -> Tensor:
        """depth (B, T, H, W) in [-0.5, 0.5]; terminus (B, 2) m, yaw frame -> alpha (B, dim)."""
        b, t, h, w = depth.shape
        n, d = self.cfg.patches, self.cfg.dim
        # tile the terminus into an image: every pixel, hence every token, carries the goal
        goal_map = (DEPTH_RANGE * squash_point(terminus))[:, None, :, None, None]
        goal_map = goal_map.expand(b, t, GOAL_CHANNELS, h, w)
        image = torch.cat([depth.unsqueeze(2), goal_map], dim=2)  # (B, T, 1 + 2, H, W)
        x = self.embed(image.reshape(b * t, 1 + GOAL_CHANNELS, h, w))  # (B*T, d, H/p, W/p)
        x = x.flatten(2).transpose(1, 2).reshape(b, t, n, d) + self.pos_space + self.pos_time
        for spatial, temporal in zip(self.spatial, self.temporal, strict=True):
            x = spatial(x.reshape(b * t, n, d)).reshape(b, t, n, d)
            x = x.transpose(1, 2).reshape(b * n, t, d)  # one sequence per tile, across frames
            x = temporal(x).reshape(b, n, t, d).transpose(1, 2)
        return self.norm(x).mean(dim=(1, 2))


class TCViTs(nn.Module):
    """Temporal-contextual ViTs: depth history, goals and proprioception -> navigation outputs.

    Args:
        cfg: sizes (:func:`tcvit_config`).
        proprio_dim: P (39 for H1, 45 for G1 in this env).
        goal_dim: size of the goal input (terminus xy, middle waypoint xy).

    Attributes:
        state_shape: the recurrent core's per-env state shape; zeros = fresh episode.
    """

    def __init__(self, cfg: TCViTConfig, proprio_dim: int, goal_dim: int = 4) -> None:
        super().__init__()
        if goal_dim % 2:
            raise ValueError(f"goal_dim holds xy points, so it must be even, got {goal_dim}")
        self.cfg = cfg
        self.encoder = FactorisedViViT(cfg)
        self.cnn = ShallowCNN(cfg.height, cfg.width, cfg.cnn_channels, cfg.cnn_out)
        self.mix = mlp(cfg.dim + cfg.cnn_out, [cfg.mix_hidden, cfg.gamma_dim], nn.ELU)
        self.core: TemporalCore = make_core(cfg.core, cfg.gamma_dim + goal_dim + proprio_dim,
                                            **cfg.core_sizes())
        h = self.core.out_dim
        self.latent_head = nn.Sequential(nn.Linear(h, cfg.latent_dim), nn.Tanh())
        self.correction_head = nn.Linear(h, 2)
        self.goals_head = nn.Linear(h, 2 * cfg.num_goals)

    @property
    def state_shape(self) -> tuple[int, ...]:
        """Per-env recurrent state shape (the core's)."""
        return self.core.state_shape

    def initial_state(self, batch: int, device: torch.device | str | None = None) -> Tensor:
        """Zeros (batch, *state_shape): the state at the start of an episode."""
        return self.core.initial_state(batch, device)

    def forward(self, depth: Tensor, goal: Tensor, proprio: Tensor,
                state: Tensor) -> dict[str, Tensor]:
        """One depth frame's step.

        Args:
            depth: (B, T, H, W) normalised depth in [-0.5, 0.5], oldest first.
            goal: (B, 4) terminus xy and middle waypoint xy in the robot yaw frame, m.
            proprio: (B, P) proprioception.
            state: (B, *state_shape) recurrent state; zeros at the start of an episode.

        Returns:
            dict with ``latent`` (B, latent_dim) z_uni in [-1, 1]; ``goal_correction`` (B, 2)
            delta_g0, m; ``near_goals`` (B, num_goals, 2) g1..g3, robot yaw frame, m;
            ``state`` (B, *state_shape) the next state.
        """
        return self.recur(self.encode(depth, goal[:, :2]), goal, proprio, state)

    def encode(self, depth: Tensor, terminus: Tensor) -> Tensor:
        """The state-free part of a step: depth (B, T, H, W) and terminus (B, 2) -> gamma
        (B, gamma_dim). Kept apart so that a training update can encode every fresh frame
        of a batch in one call (per frame 1.7x cheaper at 320 frames than at 64)."""
        alpha = self.encoder(depth, terminus)
        beta = self.cnn(depth[:, -1])
        return self.mix(torch.cat([alpha, beta], dim=-1))

    def recur(self, gamma: Tensor, goal: Tensor, proprio: Tensor, state: Tensor
              ) -> dict[str, Tensor]:
        """The recurrent part of a step: gamma (:meth:`encode`), the goals, proprioception
        and the state -> the outputs of :meth:`forward`."""
        points = squash_point(goal.reshape(goal.shape[0], -1, 2)).flatten(1)  # bounded goals
        h, new_state = self.core(torch.cat([gamma, points, proprio], dim=-1), state)
        return {
            "latent": self.latent_head(h),
            "goal_correction": self.correction_head(h),
            "near_goals": self.goals_head(h).reshape(-1, self.cfg.num_goals, 2),
            "state": new_state,
        }
