"""Networks as TensorDict modules: each reads named keys and writes named keys.

Modules know nothing of the environment: they meet it through the keys in
:mod:`legoh.keys` and the sizes in :class:`legoh.modules.actor_critic.OracleInputDims`.
"""

from legoh.modules.actor_critic import (
    OracleInputDims,
    OracleNetConfig,
    make_oracle_actor_critic,
)
from legoh.modules.encoders import (
    PRIV_LATENT,
    PRIV_LATENT_EST,
    make_adaptation_module,
    make_privileged_encoder,
    make_scandot_encoder,
)

__all__ = [
    "PRIV_LATENT",
    "PRIV_LATENT_EST",
    "OracleInputDims",
    "OracleNetConfig",
    "make_adaptation_module",
    "make_oracle_actor_critic",
    "make_privileged_encoder",
    "make_scandot_encoder",
]
