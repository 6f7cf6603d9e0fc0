"""Encoders of the oracle stage (appendix 6.1; Extreme Parkour's RMA-style adaptation).

Every factory returns a :class:`tensordict.nn.TensorDictModule` with explicit keys:

=========================  =================================  ================================
factory                    reads                              writes
=========================  =================================  ================================
make_scandot_encoder       ``("obs","scandots")`` (B, 132)    ``("teacher","latent")`` (B, 32)
make_privileged_encoder    ``("obs","privileged")`` (B, K)    ``("hidden","priv_latent")`` (B, 20)
make_adaptation_module     ``("obs","proprio_history")``      ``("hidden","priv_latent_est")``
                           (B, 10, P)                         (B, 20)
=========================  =================================  ================================

B is any batch shape (for example (N,) or (T, N)).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.modules import MLP

from legoh.keys import PRIVILEGED, PROPRIO_HISTORY, SCANDOTS, TEACHER_LATENT

PRIV_LATENT = ("hidden", "priv_latent")  # (20,) privileged latent, from the privileged encoder
PRIV_LATENT_EST = ("hidden", "priv_latent_est")  # (20,) its estimate from proprio history


def mlp(in_dim: int, sizes: Sequence[int], out_act: type[nn.Module] | None) -> nn.Sequential:
    """Linear layers ``in_dim -> sizes[0] -> ... -> sizes[-1]``, ELU between them.

    ``out_act`` (a module class, or None for a linear output) follows the last layer.
    """
    net = MLP(in_features=in_dim, out_features=sizes[-1], num_cells=list(sizes[:-1]),
              activation_class=nn.ELU)
    return nn.Sequential(*net, out_act()) if out_act is not None else nn.Sequential(*net)


def make_scandot_encoder(num_scandots: int = 132, sizes: Sequence[int] = (128, 64, 32),
                         out_key=TEACHER_LATENT) -> TensorDictModule:
    """Scandot encoder: MLP 128-64-32, ELU hidden, Tanh out (appendix 6.1).

    Reads ``("obs","scandots")`` (B, num_scandots); writes z_tea (B, sizes[-1]) to
    ``out_key`` (default ``("teacher","latent")``, the target the unified policy regresses).
    """
    return TensorDictModule(mlp(num_scandots, sizes, nn.Tanh), [SCANDOTS], [out_key])


def make_privileged_encoder(num_privileged: int, sizes: Sequence[int] = (64, 20),
                            out_key=PRIV_LATENT) -> TensorDictModule:
    """Privileged encoder: MLP 64-20 with ELU after every layer (Extreme Parkour's
    ``priv_encoder`` also activates its last layer).

    Reads ``("obs","privileged")`` (B, K); writes (B, sizes[-1]) to ``out_key``.
    """
    return TensorDictModule(mlp(num_privileged, sizes, nn.ELU), [PRIVILEGED], [out_key])


class HistoryConvEncoder(nn.Module):
    """1-D convolutions over time: (B, T, P) proprioception history -> (B, out_dim).

    Each step is first embedded (Linear P -> 3c, ELU), then the time axis is reduced by
    Conv1d(3c -> 2c, kernel 4, stride 2), ELU, Conv1d(2c -> c, kernel 2, stride 1), ELU, and
    the flattened result mapped by Linear -> out_dim, ELU (the shape of Extreme Parkour's
    ``StateHistoryEncoder`` for 10 steps: 10 -> 4 -> 3 time samples).

    Args:
        proprio_dim: P. history: T (at least 5, so both convolutions have an input).
        out_dim: size of the estimate (the privileged latent's size).
        channels: c, the base channel count.
    """

    def __init__(self, proprio_dim: int, history: int = 10, out_dim: int = 20,
                 channels: int = 10) -> None:
        super().__init__()
        c = channels
        self.history = history
        self.embed = nn.Sequential(nn.Linear(proprio_dim, 3 * c), nn.ELU())
        self.conv = nn.Sequential(
            nn.Conv1d(3 * c, 2 * c, kernel_size=4, stride=2), nn.ELU(),
            nn.Conv1d(2 * c, c, kernel_size=2, stride=1), nn.ELU(),
            nn.Flatten(),
        )
        steps = (history - 4) // 2 + 1 - 1  # after the two convolutions
        if steps < 1:
            raise ValueError(f"history must be at least 5 steps, got {history}")
        self.head = nn.Sequential(nn.Linear(c * steps, out_dim), nn.ELU())

    def forward(self, history: torch.Tensor) -> torch.Tensor:
        """(B..., T, P) -> (B..., out_dim)."""
        # a shape check, not data: skipped while tracing (the export fixes the shapes)
        if not torch.jit.is_tracing() and history.shape[-2] != self.history:
            raise ValueError(f"expected {self.history} history steps, got {history.shape[-2]}")
        batch = history.shape[:-2]
        x = self.embed(history.reshape(-1, *history.shape[-2:]))  # (b, T, 3c)
        x = self.conv(x.transpose(1, 2))  # channels first: (b, 3c, T) -> (b, c * steps)
        return self.head(x).reshape(*batch, -1)


def make_adaptation_module(proprio_dim: int, history: int = 10, latent_dim: int = 20,
                           channels: int = 10, out_key=PRIV_LATENT_EST) -> TensorDictModule:
    """RMA-style adaptation module: estimates the privileged latent from proprioception.

    Reads ``("obs","proprio_history")`` (B, history, proprio_dim), oldest first; writes
    (B, latent_dim) to ``out_key`` (default ``("hidden","priv_latent_est")``). Trained by
    regressing the (detached) output of :func:`make_privileged_encoder`.
    """
    net = HistoryConvEncoder(proprio_dim, history, latent_dim, channels)
    return TensorDictModule(net, [PROPRIO_HISTORY], [out_key])
