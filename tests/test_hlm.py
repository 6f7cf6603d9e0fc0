"""HLM: the action VAE (masked and vanilla), its training loss, the HLM losses, the plug-in."""

import pytest
import torch
from tensordict import TensorDict

from legoh.keys import TEACHER_ACTION
from legoh.modules.vae import (
    ActionVAE,
    ActionVAEConfig,
    ResidualFC,
    normalize_actions,
    random_joint_mask,
)
from legoh.objectives.hlm import HLMLoss, hlm_loss, vae_loss

J, BOUND = 19, 4.8
SMALL = ActionVAEConfig(hidden=64, blocks=2, latent=16)  # a fast stand-in for the 256-wide VAE


def structured_actions(n: int, g: torch.Generator) -> torch.Tensor:
    """(n, J) raw actions: fixed linear maps of 2 latent factors plus small noise, so any
    joint can be predicted from the others (the structure the masked VAE must learn)."""
    w = torch.randn(J, 2, generator=torch.Generator().manual_seed(7))
    factors = torch.randn(n, 2, generator=g)
    return factors @ w.T * 0.7 + 0.05 * torch.randn(n, J, generator=g)


@pytest.fixture(scope="module")
def trained() -> tuple[ActionVAE, list[tuple[float, float]]]:
    """A small masked VAE trained 300 steps on structured actions, and per step its
    reconstruction loss and mean absolute error."""
    torch.manual_seed(0)  # the reparameterisation noise uses the global generator
    threads = torch.get_num_threads()
    # Tiny matrices: one thread is ~4 ms a step; two threads on a busy 2-core box spin-wait
    # for each other and can be 20x slower.
    torch.set_num_threads(1)
    try:
        g = torch.Generator().manual_seed(0)
        vae = ActionVAE(J, SMALL)
        opt = torch.optim.Adam(vae.parameters(), lr=1e-3)
        losses = []
        for _ in range(300):
            out = vae_loss(vae, structured_actions(128, g), BOUND, generator=g)
            opt.zero_grad()
            (out["loss_recon"] + out["loss_kl"]).backward()
            opt.step()
            losses.append((float(out["loss_recon"].detach()), float(out["recon_mae"])))
        opt.zero_grad(set_to_none=True)  # the HLM tests check that no gradient reaches the VAE
    finally:
        torch.set_num_threads(threads)
    return vae.eval(), losses


class TestVAE:
    def test_shapes_and_ranges(self):
        vae = ActionVAE(J, SMALL)
        x = torch.rand(5, 3, J)  # leading batch dims, as in a (T, N) rollout
        mask = random_joint_mask(15, J, 0.3).reshape(5, 3, J)
        mu, logvar = vae.encode(x, mask)
        assert mu.shape == logvar.shape == (5, 3, SMALL.latent)
        recon = vae.decode(mu)
        assert recon.shape == (5, 3, J) and recon.min() >= 0 and recon.max() <= 1
        out = vae(x[0])
        assert {k: tuple(v.shape) for k, v in out.items()} == {
            "recon": (3, J), "logits": (3, J), "mu": (3, 16), "logvar": (3, 16), "z": (3, 16)}

    def test_default_sizes(self):
        vae = ActionVAE(J)
        assert vae.encoder.mu.out_features == 32 and len(vae.encoder.blocks) == 3
        assert vae.encoder.inp[0].in_features == J * (2 + 8)  # value, mask flag, 8-d code

    def test_residual_block_is_identity_plus_branch(self):
        block = ResidualFC(4)
        torch.nn.init.zeros_(block.net[2].weight)
        torch.nn.init.zeros_(block.net[2].bias)
        x = torch.tensor([[-1.0, 0.5, 2.0, -0.1]])
        assert torch.equal(block(x), torch.relu(x))

    def test_masked_value_is_hidden(self):
        """A hidden joint's value cannot reach the encoder: changing it changes nothing."""
        vae = ActionVAE(J, SMALL)
        x = torch.rand(4, J)
        mask = torch.zeros(4, J, dtype=torch.bool)
        mask[:, 3] = True
        y = x.clone()
        y[:, 3] = 1.0 - y[:, 3]
        assert torch.equal(vae.encode(x, mask)[0], vae.encode(y, mask)[0])
        assert not torch.equal(vae.encode(x)[0], vae.encode(y)[0])

    def test_training_reduces_loss_and_fills_in_masked_joints(self, trained):
        vae, losses = trained
        (loss0, mae0), (loss1, mae1) = (torch.tensor(losses[:20]).mean(0).tolist(),
                                        torch.tensor(losses[-20:]).mean(0).tolist())
        # BCE on soft targets has a floor (the targets' entropy, ~12.8 nats here), so the loss
        # itself falls by little; the error it stands for falls by more than half.
        assert loss1 < loss0 - 0.2
        assert mae1 < 0.5 * mae0
        g = torch.Generator().manual_seed(1)
        target = normalize_actions(structured_actions(1000, g), BOUND)
        mask = random_joint_mask(1000, J, 0.3, generator=g)
        with torch.no_grad():
            recon = vae(target, mask)["recon"]
        constant = target.mean(0, keepdim=True).expand_as(target)  # the best blind guess
        err_vae = (recon - target).abs()[mask].mean()
        err_const = (constant - target).abs()[mask].mean()
        assert err_vae < 0.7 * err_const

    def test_vanilla_and_masked_both_train(self):
        g = torch.Generator().manual_seed(0)
        actions = structured_actions(32, g)
        for masked in (True, False):
            vae = ActionVAE(J, ActionVAEConfig(hidden=32, blocks=1, masked=masked))
            out = vae_loss(vae, actions, BOUND, generator=g)
            (out["loss_recon"] + out["loss_kl"]).backward()
            assert all(p.grad is not None for p in vae.parameters())
            assert torch.isnan(out["recon_mae_masked"]) != masked  # vanilla hides nothing
            assert not out["kl"].requires_grad and not out["recon_mae"].requires_grad
            hlm = hlm_loss(vae, actions, actions, BOUND, generator=g)
            assert torch.isfinite(hlm["loss_hlm_triplet"])


class TestMaskAndNormalisation:
    def test_mask_count_and_uniformity(self):
        g = torch.Generator().manual_seed(0)
        mask = random_joint_mask(4000, J, 0.3, generator=g)
        assert mask.dtype == torch.bool and mask.shape == (4000, J)
        assert (mask.sum(-1) == round(0.3 * J)).all()  # 6 of 19 in every row
        per_joint = mask.float().mean(0)
        assert torch.allclose(per_joint, torch.full((J,), 6 / J), atol=0.03)

    def test_at_least_one_joint_per_row(self):
        mask = random_joint_mask(100, J, 0.01)
        assert (mask.sum(-1) == 1).all()

    @pytest.mark.parametrize("ratio", [0.0, -0.1, 1.5])
    def test_bad_ratio(self, ratio):
        with pytest.raises(ValueError, match="ratio"):
            random_joint_mask(4, J, ratio)

    def test_normalize_actions(self):
        a = torch.tensor([-BOUND, 0.0, BOUND, 2 * BOUND, -9.9, 2.4])
        assert torch.allclose(normalize_actions(a, BOUND),
                              torch.tensor([0.0, 0.5, 1.0, 1.0, 0.0, 0.75]))
        with pytest.raises(ValueError, match="bound"):
            normalize_actions(a, 0.0)


class TestHLMLoss:
    def test_identical_actions(self, trained):
        vae, _ = trained
        g = torch.Generator().manual_seed(2)
        a = structured_actions(256, g)
        out = hlm_loss(vae, a, a.clone(), BOUND, generator=g)
        assert out["loss_hlm_similarity"] == pytest.approx(0.0, abs=1e-5)
        assert out["hlm_cos"] == pytest.approx(1.0, abs=1e-5)
        assert out["hlm_d_neg"] > out["hlm_d_pos"] + 0.01  # the masked negative lies farther

    def test_similarity_grows_with_difference(self, trained):
        vae, _ = trained
        g = torch.Generator().manual_seed(3)
        a = structured_actions(256, g)
        near = hlm_loss(vae, a, a + 0.1 * torch.randn(a.shape, generator=g), BOUND)
        far = hlm_loss(vae, a, structured_actions(256, g), BOUND)
        assert 0 < near["loss_hlm_similarity"] < far["loss_hlm_similarity"]

    def test_weights(self, trained):
        vae, _ = trained
        a, b = torch.randn(2, 64, J)
        g = torch.Generator().manual_seed(0)
        out = hlm_loss(vae, a, b, BOUND, c_mt=0.0, c_ms=0.15, generator=g)
        assert out["loss_hlm_triplet"] == 0
        assert out["loss_hlm_similarity"] == pytest.approx(0.15 * float(out["hlm_d_pos"]))

    def test_gradients_reach_student_not_vae(self, trained):
        vae, _ = trained
        g = torch.Generator().manual_seed(4)
        oracle = structured_actions(64, g).requires_grad_(True)
        student = (oracle.detach() + 0.3 * torch.randn(64, J, generator=g)).requires_grad_(True)
        out = hlm_loss(vae, oracle, student, BOUND, generator=g)
        (out["loss_hlm_similarity"] + out["loss_hlm_triplet"]).backward()
        assert student.grad is not None and student.grad.abs().sum() > 0
        assert oracle.grad is None  # the oracle is a label
        assert all(p.grad is None for p in vae.parameters())
        assert all(p.requires_grad for p in vae.parameters())  # frozen without being touched

    def test_bad_inputs(self):
        vae = ActionVAE(J, SMALL)
        good = torch.zeros(8, J)
        nan = good.clone()
        nan[2, 5] = float("nan")
        with pytest.raises(ValueError, match="joints"):
            vae.encode(torch.zeros(8, J + 1))
        with pytest.raises(ValueError, match="oracle_action.*joints"):
            vae_loss(vae, torch.zeros(8, J - 1), BOUND)
        with pytest.raises(ValueError, match="oracle_action.*NaN"):
            vae_loss(vae, nan, BOUND)
        with pytest.raises(ValueError, match="student_action.*NaN"):
            hlm_loss(vae, good, nan, BOUND)
        with pytest.raises(ValueError, match="student_action.*joints"):
            hlm_loss(vae, good, torch.zeros(8, 12), BOUND)
        with pytest.raises(ValueError, match="differ in shape"):
            hlm_loss(vae, good, torch.zeros(4, J), BOUND)
        with pytest.raises(ValueError, match="pos_dim"):
            ActionVAEConfig(pos_dim=7)


class TestPlugIn:
    def test_any_student_through_tensordict_keys(self, trained):
        vae, _ = trained
        student = torch.nn.Linear(5, J)  # stands for any policy: HLM needs only its action
        td = TensorDict({"obs": torch.randn(4, 6, 5), TEACHER_ACTION: torch.randn(4, 6, J)},
                        batch_size=[4, 6])
        td["loc"] = student(td["obs"])
        loss = HLMLoss(vae, BOUND, student_key="loc", generator=torch.Generator())
        assert loss.in_keys == ["loc", TEACHER_ACTION]
        out = loss(td)
        assert sorted(k for k in out.keys() if k.startswith("loss_")) == [
            "loss_hlm_similarity", "loss_hlm_triplet"]
        sum(v for k, v in out.items() if k.startswith("loss_")).backward()
        assert student.weight.grad.abs().sum() > 0
        assert all(p.grad is None for p in vae.parameters())

    def test_warns_when_student_action_has_no_graph(self, trained):
        vae, _ = trained
        td = TensorDict({"action": torch.randn(8, J), TEACHER_ACTION: torch.randn(8, J)}, [8])
        loss = HLMLoss(vae, BOUND)
        with pytest.warns(UserWarning, match="no graph"):
            loss(td)
        loss.set_keys(student="other")
        assert loss.in_keys[0] == "other"


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a GPU")
def test_cuda_actions_with_a_cpu_generator():
    """Training loops seed one cpu generator; the masks must still land on the actions' device."""
    vae = ActionVAE(J, SMALL).cuda()
    g = torch.Generator().manual_seed(0)
    a = torch.randn(16, J, device="cuda")
    assert vae_loss(vae, a, BOUND, generator=g)["loss_recon"].is_cuda
    assert hlm_loss(vae, a, a, BOUND, generator=g)["loss_hlm_triplet"].is_cuda
