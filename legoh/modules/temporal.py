"""Recurrent cores for TC-ViTs' recurrent goal adaptation (one step = one depth frame, 10 Hz).

A core maps one input vector per env and a per-env state to one output vector and the next
state. States are plain float32 tensors (no tuples, no caches held in the module), so a
collector can store them in a TensorDict next to the observations, and an all-zeros state is
always "start of episode": resetting an env means zeroing its row.

=========================  ======================================  ==========================
core                       state per env                           out_dim
=========================  ======================================  ==========================
:class:`GRUCore`           (layers, hidden): nn.GRU's hidden state  hidden
:class:`CausalTransformer  (context, dim + 1): the last ``context``  dim
Core`                      input tokens, last channel 1 = valid
=========================  ======================================  ==========================

The paper grafts a GRU at the end of TC-ViTs and compares it with a causal transformer
(appendix 3.1, Table 1); :func:`make_core` builds either by name.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn


class TemporalCore(nn.Module):
    """Protocol of a recurrent core: ``(x, state) -> (y, new_state)``, one step at a time.

    Attributes:
        state_shape: per-env state shape (float32); zeros mean "no past" (fresh episode).
        out_dim: size of ``y``.
    """

    state_shape: tuple[int, ...]
    out_dim: int

    def initial_state(self, batch: int, device: torch.device | str | None = None) -> Tensor:
        """Zeros of shape (batch, *state_shape): the state at the start of an episode."""
        return torch.zeros(batch, *self.state_shape, device=device)

    def forward(self, x: Tensor, state: Tensor) -> tuple[Tensor, Tensor]:
        """x (B, in_dim), state (B, *state_shape) -> y (B, out_dim), new_state (B, *state_shape)."""
        raise NotImplementedError


class GRUCore(TemporalCore):
    """A stack of GRU layers (torch's nn.GRU), stepped once per call.

    Args:
        in_dim: input size. hidden: hidden size (= out_dim). layers: stacked GRU layers.
    """

    def __init__(self, in_dim: int, hidden: int, layers: int = 1) -> None:
        super().__init__()
        self.gru = nn.GRU(in_dim, hidden, num_layers=layers, batch_first=True)
        self.state_shape = (layers, hidden)
        self.out_dim = hidden

    def forward(self, x: Tensor, state: Tensor) -> tuple[Tensor, Tensor]:
        """x (B, in_dim), state (B, layers, hidden) -> y (B, hidden), new_state (same shape)."""
        # nn.GRU wants the layer axis first; the state keeps the env axis first for TensorDicts
        y, h = self.gru(x.unsqueeze(1), state.transpose(0, 1).contiguous())
        return y[:, 0], h.transpose(0, 1)


class CausalTransformerCore(TemporalCore):
    """A causal transformer over the last ``context`` steps plus the current one.

    The state holds the last ``context`` input tokens (after the input projection), oldest
    first, each with a validity flag in its last channel; a zero state therefore holds no
    past. Every call re-encodes the window ``[past..., new]`` with a causal mask (a token sees
    itself and the valid tokens before it) and returns the new token's output. Only input
    tokens are stored, not per-layer keys and values, so the state stays one plain tensor;
    the price is re-running the ``context`` past tokens through every layer each step
    (counted in experiments/bench.py model-size).

    Args:
        in_dim: input size. dim: token width (= out_dim). layers: transformer layers.
        heads: attention heads (divides dim). context: past steps kept in the state.
        mlp_ratio: feed-forward width / dim.
    """

    def __init__(self, in_dim: int, dim: int, layers: int, heads: int, context: int,
                 mlp_ratio: float = 4.0) -> None:
        super().__init__()
        if context < 1:
            raise ValueError(f"context must be at least 1 past step, got {context}")
        self.dim, self.heads, self.context = dim, heads, context
        self.state_shape = (context, dim + 1)
        self.out_dim = dim
        self.embed = nn.Linear(in_dim, dim)
        # position by age within the window: new tokens always enter at the right end
        self.pos = nn.Parameter(torch.randn(context + 1, dim) * 0.02)
        layer = nn.TransformerEncoderLayer(dim, heads, dim_feedforward=int(mlp_ratio * dim),
                                           dropout=0.0, activation="gelu", batch_first=True,
                                           norm_first=True)
        self.blocks = nn.TransformerEncoder(layer, layers, enable_nested_tensor=False)
        self.norm = nn.LayerNorm(dim)  # pre-norm blocks leave the residual stream unnormalised

    def forward(self, x: Tensor, state: Tensor) -> tuple[Tensor, Tensor]:
        """x (B, in_dim), state (B, context, dim + 1) -> y (B, dim), new_state (same shape)."""
        b, n = x.shape[0], self.context + 1
        token = self.embed(x)  # (B, dim)
        past, valid = state[..., :-1], state[..., -1] > 0.5  # (B, C, dim), (B, C)
        seq = torch.cat([past, token.unsqueeze(1)], dim=1) + self.pos  # (B, C + 1, dim)
        keep = torch.cat([valid, valid.new_ones(b, 1)], dim=1)  # (B, C + 1)
        # blocked[b, i, j]: query i may not read key j. Future keys are blocked, and so are
        # invalid past keys, except that every token always reads itself: a row with every key
        # blocked gives NaN, which would leak into valid tokens through the next layer's values.
        idx = torch.arange(n, device=x.device)
        future = idx[None, :] > idx[:, None]  # (C + 1, C + 1)
        blocked = future | (~keep[:, None, :] & (idx[None, :] != idx[:, None]))  # (B, C+1, C+1)
        mask = blocked.repeat_interleave(self.heads, dim=0)  # (B * heads, C + 1, C + 1)
        y = self.norm(self.blocks(seq, mask=mask)[:, -1])
        new_token = torch.cat([token, token.new_ones(b, 1)], dim=1).unsqueeze(1)
        return y, torch.cat([state[:, 1:], new_token], dim=1)


CORES: dict[str, type[TemporalCore]] = {"gru": GRUCore, "transformer": CausalTransformerCore}


def make_core(kind: str, in_dim: int, **sizes) -> TemporalCore:
    """Build a core by name: ``"gru"`` -> :class:`GRUCore` (sizes: hidden, layers);
    ``"transformer"`` -> :class:`CausalTransformerCore` (sizes: dim, layers, heads, context,
    mlp_ratio)."""
    if kind not in CORES:
        raise ValueError(f"unknown temporal core {kind!r}; options: {', '.join(CORES)}")
    return CORES[kind](in_dim, **sizes)
