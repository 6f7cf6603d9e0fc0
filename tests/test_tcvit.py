"""TC-ViTs and its recurrent cores (legoh/modules/tcvit.py, legoh/modules/temporal.py)."""

import dataclasses

import pytest
import torch

from legoh.modules.tcvit import PRESETS, TCViTs, squash_point, tcvit_config
from legoh.modules.temporal import CausalTransformerCore, GRUCore, make_core

PROPRIO = 39  # H1's proprioception in this env
PAPER_PARAMS = {"gru": 31.25e6, "transformer": 55.92e6}  # appendix 3.1
CORES = ("gru", "transformer")


def inputs(cfg, batch=3, seed=0):
    """Random depth (B, T, H, W) in [-0.5, 0.5], goal (B, 4) m, proprio (B, P)."""
    g = torch.Generator().manual_seed(seed)
    depth = torch.rand(batch, cfg.frames, cfg.height, cfg.width, generator=g) - 0.5
    goal = torch.randn(batch, 4, generator=g) * 5.0
    return depth, goal, torch.randn(batch, PROPRIO, generator=g)


def small(core, **overrides):
    torch.manual_seed(0)
    cfg = tcvit_config("small", core, **overrides)
    return cfg, TCViTs(cfg, PROPRIO)


class TestConfig:
    def test_presets_differ_only_in_core(self):
        gru, ct = tcvit_config("paper", "gru"), tcvit_config("paper", "transformer")
        assert (gru.core, ct.core) == ("gru", "transformer")
        assert dataclasses.replace(ct, core="gru") == gru

    def test_overrides_and_frozen(self):
        cfg = tcvit_config("small", dim=32)
        assert cfg.dim == 32 and PRESETS["small"].dim != 32
        with pytest.raises(AttributeError):
            cfg.dim = 8  # frozen: derived configs are new objects

    def test_unknown_preset(self):
        with pytest.raises(ValueError, match="options: small, paper"):
            tcvit_config("huge")

    def test_unknown_core(self):
        with pytest.raises(ValueError, match="options: gru, transformer"):
            make_core("lstm", 8, hidden=8)
        with pytest.raises(ValueError, match="options: gru, transformer"):
            TCViTs(tcvit_config("small", "lstm"), PROPRIO)

    def test_patch_must_divide_image(self):
        with pytest.raises(ValueError, match="patch"):
            tcvit_config("small", patch=7)


class TestTCViTs:
    @pytest.mark.parametrize("core", CORES)
    def test_output_shapes(self, core):
        cfg, net = small(core)
        depth, goal, proprio = inputs(cfg, batch=5)
        out = net(depth, goal, proprio, net.initial_state(5))
        assert out["latent"].shape == (5, cfg.latent_dim)
        assert out["goal_correction"].shape == (5, 2)
        assert out["near_goals"].shape == (5, cfg.num_goals, 2)
        assert out["state"].shape == (5, *net.state_shape)
        assert all(v.dtype == torch.float32 and v.isfinite().all() for v in out.values())
        assert out["latent"].abs().max() <= 1.0  # Tanh, like the oracle's z_tea

    def test_state_shapes(self):
        assert small("gru")[1].state_shape == (1, 128)
        assert small("transformer")[1].state_shape == (3, 128 + 1)

    @pytest.mark.parametrize("core", CORES)
    def test_gradients_reach_every_parameter(self, core):
        cfg, net = small(core)
        depth, goal, proprio = inputs(cfg)
        state, total = net.initial_state(3), 0.0
        for _ in range(2):  # the second step reads the first through the state (past tokens)
            out = net(depth, goal, proprio, state)
            state = out["state"]
            total = total + sum(v.sum() for k, v in out.items() if k != "state")
        total.backward()
        for name, p in net.named_parameters():
            assert p.grad is not None, name
            assert p.grad.isfinite().all(), name
            assert p.grad.abs().sum() > 0, name

    @pytest.mark.parametrize("core", CORES)
    def test_zero_state_is_a_fresh_episode(self, core):
        cfg, net = small(core)
        depth, goal, proprio = inputs(cfg)
        fresh = net(depth, goal, proprio, net.initial_state(3))
        state = net.initial_state(3)
        for seed in (1, 2):  # some history, then reset to zeros
            state = net(*inputs(cfg, seed=seed), state)["state"]
        assert state.abs().sum() > 0
        again = net(depth, goal, proprio, torch.zeros_like(state))
        for key in fresh:
            torch.testing.assert_close(again[key], fresh[key])

    @pytest.mark.parametrize("core", CORES)
    def test_rows_are_independent(self, core):
        cfg, net = small(core)
        depth, goal, proprio = inputs(cfg, batch=4)
        state = net(depth, goal, proprio, net.initial_state(4))["state"]
        both = net(depth, goal, proprio, state)["latent"]
        one = net(depth[:1], goal[:1], proprio[:1], state[:1])["latent"]
        torch.testing.assert_close(both[:1], one)

    def test_terminus_reaches_the_encoder(self):
        cfg, net = small("gru")
        depth, goal, _ = inputs(cfg)
        moved = goal.clone()
        moved[:, 0] += 1.0
        assert not torch.allclose(net.encoder(depth, goal[:, :2]), net.encoder(depth, moved[:, :2]))

    @pytest.mark.parametrize("core", CORES)
    def test_paper_parameter_count(self, core):
        net = TCViTs(tcvit_config("paper", core), PROPRIO)
        count = sum(p.numel() for p in net.parameters())
        assert count == pytest.approx(PAPER_PARAMS[core], rel=0.05)


def test_squash_point_bounded_and_smooth():
    xy = torch.tensor([[0.0, 0.0], [1e-3, 0.0], [3.0, 4.0], [1e4, 0.0]])
    out = squash_point(xy)
    assert out.norm(dim=-1).max() <= 1.0
    torch.testing.assert_close(out[0], torch.zeros(2))
    torch.testing.assert_close(out[3], torch.tensor([1.0, 0.0]))
    assert out[2, 1] / out[2, 0] == pytest.approx(4 / 3)  # direction kept


class TestCores:
    def ct(self, context=3):
        torch.manual_seed(0)
        return CausalTransformerCore(6, dim=16, layers=2, heads=4, context=context)

    def test_gru_matches_nn_gru_unrolled(self):
        torch.manual_seed(0)
        core = GRUCore(6, hidden=8, layers=2)
        xs = torch.randn(4, 5, 6)  # (B, steps, in)
        ref, _ = core.gru(xs)
        state, ys = core.initial_state(4), []
        for t in range(5):
            y, state = core(xs[:, t], state)
            ys.append(y)
        torch.testing.assert_close(torch.stack(ys, 1), ref)

    def test_transformer_state_layout(self):
        core = self.ct()
        x = torch.randn(2, 6)
        _, state = core(x, core.initial_state(2))
        assert state.shape == (2, 3, 17)
        assert state[:, :, -1].tolist() == [[0, 0, 1], [0, 0, 1]]  # newest token enters right
        torch.testing.assert_close(state[:, -1, :-1], core.embed(x))

    def test_transformer_ignores_invalid_past(self):
        """Flag-0 slots hold no past, whatever their content."""
        core = self.ct()
        x = torch.randn(2, 6)
        garbage = torch.randn(2, 3, 17)
        garbage[..., -1] = 0.0
        torch.testing.assert_close(core(x, garbage)[0], core(x, core.initial_state(2))[0])

    def test_transformer_is_causal(self):
        """Outputs up to step t never change when later inputs do."""
        core = self.ct()
        xs, other = torch.randn(2, 6, 6), torch.randn(2, 6, 6)
        other[:, :3] = xs[:, :3]

        def run(seq):
            state, ys = core.initial_state(2), []
            for t in range(seq.shape[1]):
                y, state = core(seq[:, t], state)
                ys.append(y)
            return torch.stack(ys, 1)

        a, b = run(xs), run(other)
        torch.testing.assert_close(a[:, :3], b[:, :3])
        assert not torch.allclose(a[:, 3:], b[:, 3:])

    def test_transformer_forgets_beyond_context(self):
        core = self.ct(context=2)
        xs, other = torch.randn(2, 5, 6), torch.randn(2, 5, 6)
        other[:, 2:] = xs[:, 2:]  # same last 3 steps: the window of context 2 + now
        outs = []
        for seq in (xs, other):
            state = core.initial_state(2)
            for t in range(5):
                y, state = core(seq[:, t], state)
            outs.append(y)
        torch.testing.assert_close(outs[0], outs[1])


@pytest.mark.parametrize("length", [4, 12])  # the temporal and spatial sequences
def test_attention_block_matches_pytorchs_encoder_layer(length):
    """AttentionBlock (softmax over dim 1, for speed) is nn.TransformerEncoderLayer with the
    same state dict: same outputs and gradients in float32, in training mode."""
    from torch import nn

    from legoh.modules.tcvit import AttentionBlock

    def make(cls):
        torch.manual_seed(0)
        return cls(64, 4, 128, dropout=0.0, activation="gelu", batch_first=True,
                   norm_first=True)

    ref, ours = make(nn.TransformerEncoderLayer), make(AttentionBlock)
    ours.load_state_dict(ref.state_dict())  # the same keys: old checkpoints load
    x = torch.randn(50, length, 64)
    xs = [x.clone().requires_grad_() for _ in range(2)]
    ys = [m(xi) for m, xi in zip((ref, ours), xs, strict=True)]
    for y in ys:
        y.square().mean().backward()
    torch.testing.assert_close(ys[1], ys[0], atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(xs[1].grad, xs[0].grad, atol=1e-7, rtol=1e-4)
    for (name, p), q in zip(ref.named_parameters(), ours.parameters(), strict=True):
        torch.testing.assert_close(q.grad, p.grad, atol=1e-6, rtol=1e-4, msg=name)
    with pytest.raises(ValueError, match="mask"):
        ours(x, src_mask=torch.zeros(length, length, dtype=torch.bool))
