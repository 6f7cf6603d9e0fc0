"""Oracle-stage networks: keys, shapes, sizes from the paper, sampling."""

import pytest
import torch
from tensordict import TensorDict
from torch import nn
from torchrl.data import Bounded
from torchrl.envs.utils import ExplorationType, set_exploration_type

from legoh.keys import ACTION, PRIVILEGED, PROPRIO_HISTORY, SCANDOTS, TEACHER_LATENT
from legoh.modules import (
    PRIV_LATENT,
    PRIV_LATENT_EST,
    OracleInputDims,
    OracleNetConfig,
    make_adaptation_module,
    make_oracle_actor_critic,
    make_privileged_encoder,
    make_scandot_encoder,
)
from legoh.modules.actor_critic import LOG_PROB, STATE_VALUE

N, P, K, A, BOUND = 6, 63, 16, 19, 4.8
DIMS = OracleInputDims(proprio=P, privileged=K)


def batch(*shape: int) -> TensorDict:
    g = torch.Generator().manual_seed(0)
    return TensorDict({
        "obs": {"proprio": torch.randn(*shape, P, generator=g),
                "proprio_history": torch.randn(*shape, 10, P, generator=g),
                "scandots": torch.randn(*shape, 132, generator=g),
                "privileged": torch.randn(*shape, K, generator=g),
                "command": torch.randn(*shape, 2, generator=g)},
        "expert": {"goals": torch.randn(*shape, 3, 2, generator=g)},
    }, batch_size=list(shape))


def mlp_params(sizes: list[int]) -> int:
    """Weights and biases of Linear layers sizes[0] -> sizes[1] -> ..."""
    return sum(a * b + b for a, b in zip(sizes[:-1], sizes[1:], strict=True))


def linear_sizes(module: nn.Module) -> list[int]:
    lin = [m for m in module.modules() if isinstance(m, nn.Linear)]
    return [lin[0].in_features] + [m.out_features for m in lin]


def n_params(module: nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())


class TestEncoders:
    def test_scandot_encoder_keys_sizes_and_tanh_range(self):
        enc = make_scandot_encoder()
        assert enc.in_keys == [SCANDOTS] and enc.out_keys == [TEACHER_LATENT]
        assert linear_sizes(enc) == [132, 128, 64, 32]
        assert n_params(enc) == mlp_params([132, 128, 64, 32])
        z = enc(batch(N))[TEACHER_LATENT]
        assert z.shape == (N, 32) and z.abs().max() <= 1.0
        assert isinstance(enc.module[-1], nn.Tanh)

    def test_privileged_encoder(self):
        enc = make_privileged_encoder(K)
        assert enc.in_keys == [PRIVILEGED] and enc.out_keys == [PRIV_LATENT]
        assert n_params(enc) == mlp_params([K, 64, 20])
        assert enc(batch(N))[PRIV_LATENT].shape == (N, 20)

    def test_adaptation_module_over_any_batch_shape(self):
        ada = make_adaptation_module(P)
        assert ada.in_keys == [PROPRIO_HISTORY] and ada.out_keys == [PRIV_LATENT_EST]
        assert ada(batch(N))[PRIV_LATENT_EST].shape == (N, 20)
        assert ada(batch(4, N))[PRIV_LATENT_EST].shape == (4, N, 20)
        assert any(isinstance(m, nn.Conv1d) for m in ada.modules())

    def test_adaptation_module_refuses_wrong_history(self):
        ada = make_adaptation_module(P, history=10)
        td = batch(N)
        td["obs", "proprio_history"] = td["obs", "proprio_history"][:, :8]
        with pytest.raises(ValueError, match="10 history steps"):
            ada(td)


class TestActorCritic:
    def test_keys_and_shapes(self):
        actor, critic = make_oracle_actor_critic(DIMS, A, BOUND)
        assert set(actor.in_keys) == {("obs", "proprio"), SCANDOTS, PRIVILEGED,
                                      ("expert", "goals"), ("obs", "command")}
        with set_exploration_type(ExplorationType.RANDOM):
            out = actor(batch(N))
        assert out[ACTION].shape == (N, A) and out[LOG_PROB].shape == (N,)
        assert out[TEACHER_LATENT].shape == (N, 32)
        assert torch.isfinite(out[LOG_PROB]).all()
        assert critic(batch(N))[STATE_VALUE].shape == (N, 1)

    def test_mlp_sizes_match_the_paper(self):
        actor, critic = make_oracle_actor_critic(DIMS, A, BOUND)
        in_dim = P + 32 + K + 20 + 6 + 2  # + the velocity command
        head = actor.module[0].module[2].module  # scan encoder, latent, head
        assert linear_sizes(head) == [in_dim, 512, 256, 128, A]
        assert n_params(head.body) == mlp_params([in_dim, 512, 256, 128, A])
        value = critic.module[2].module
        assert n_params(value) == mlp_params([in_dim, 512, 256, 128, 1])

    def test_samples_within_spec_and_mean_bounded(self):
        spec = Bounded(-BOUND, BOUND, shape=(N, A))
        actor, _ = make_oracle_actor_critic(DIMS, A, BOUND, action_spec=spec)
        torch.manual_seed(0)
        with set_exploration_type(ExplorationType.RANDOM):
            out = actor(batch(N))
        assert spec.is_in(out[ACTION])
        with set_exploration_type(ExplorationType.DETERMINISTIC):
            mode = actor(batch(N))[ACTION]
        assert mode.abs().max() <= BOUND and spec.is_in(mode)

    def test_log_prob_matches_the_distribution(self):
        actor, _ = make_oracle_actor_critic(DIMS, A, BOUND, OracleNetConfig(init_std=0.5))
        td = batch(N)
        with set_exploration_type(ExplorationType.RANDOM):
            out = actor(td)
        dist = actor.get_dist(td)
        assert torch.allclose(dist.log_prob(out[ACTION]), out[LOG_PROB])
        assert torch.allclose(out["hidden", "action_scale"], torch.full((N, A), 0.5))

    def test_adaptation_variant_shares_the_rest(self):
        actor, _ = make_oracle_actor_critic(DIMS, A, BOUND)
        deployed, _ = make_oracle_actor_critic(
            DIMS, A, BOUND, OracleNetConfig(raw_privileged=False), use_adaptation=True)
        assert PRIVILEGED not in deployed.in_keys and PROPRIO_HISTORY in deployed.in_keys
        td = batch(N).exclude(PRIVILEGED)
        assert deployed(td)[PRIV_LATENT_EST].shape == (N, 20)
        same, _ = make_oracle_actor_critic(DIMS, A, BOUND, use_adaptation=True)
        missing, unexpected = same.load_state_dict(actor.state_dict(), strict=False)
        assert all(".module.1." in k for k in missing + unexpected)  # only the latent source

    def test_dims_from_spec(self):
        from torchrl.data import Composite, Unbounded
        spec = Composite(
            obs=Composite(proprio=Unbounded((N, P)), proprio_history=Unbounded((N, 10, P)),
                          scandots=Unbounded((N, 132)), privileged=Unbounded((N, K)),
                          command=Unbounded((N, 2)), shape=(N,)),
            expert=Composite(goals=Unbounded((N, 3, 2)), shape=(N,)), shape=(N,))
        assert OracleInputDims.from_spec(spec) == DIMS
        assert DIMS.as_layout()["obs/proprio_history"] == (10, P)
