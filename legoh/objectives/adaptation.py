"""The RMA-style adaptation module's loss: regress the privileged latent from history.

Extreme Parkour trains the estimator beside PPO on the same batches, with the oracle's
privileged encoder as the (detached) target; later stages swap it in for the encoder.
"""

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModule

from legoh.modules.encoders import PRIV_LATENT, PRIV_LATENT_EST

MAX_ROWS = 2048  # a random subset of the batch: the estimator never feeds PPO, so a
# smaller batch costs the policy nothing, and the full 6k-row batch cost ~10 % of an update


def adaptation_loss(adaptation: TensorDictModule, actor, data: TensorDictBase,
                    generator: torch.Generator | None = None) -> torch.Tensor:
    """MSE between the estimate from ``("obs","proprio_history")`` and the actor's latent
    (its privileged encoder, run alone), on at most ``MAX_ROWS`` random rows of ``data``."""
    if data.shape[0] > MAX_ROWS:
        data = data[torch.randperm(data.shape[0], generator=generator)[:MAX_ROWS]]
    encoder = actor.module[0].module[1]  # (scandot encoder, privileged encoder, head)
    with torch.no_grad():
        target = encoder(data.select(*encoder.in_keys).clone()).get(PRIV_LATENT)
    estimate = adaptation(data.select(*adaptation.in_keys).clone()).get(PRIV_LATENT_EST)
    return torch.nn.functional.mse_loss(estimate, target)
