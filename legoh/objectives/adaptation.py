"""The RMA-style adaptation module's loss: regress the privileged latent from history.

Extreme Parkour trains the estimator beside PPO on the same batches, with the oracle's
privileged encoder as the (detached) target; later stages swap it in for the encoder.
"""

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModule

from legoh.modules.encoders import PRIV_LATENT, PRIV_LATENT_EST


def adaptation_loss(adaptation: TensorDictModule, actor, data: TensorDictBase) -> torch.Tensor:
    """MSE between the estimate from ``("obs","proprio_history")`` and the actor's latent."""
    with torch.no_grad():
        target = actor(data.select(*actor.in_keys).clone()).get(PRIV_LATENT)
    estimate = adaptation(data.select(*adaptation.in_keys).clone()).get(PRIV_LATENT_EST)
    return torch.nn.functional.mse_loss(estimate, target)
