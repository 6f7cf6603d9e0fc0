"""The student update's sizes: the prior's rows per step and the imitation's share of the
batch (the knobs that make a 256-env student iteration cheaper; docs/unified.md, Speed)."""

import pytest
import torch
from tensordict import TensorDict

import legoh.objectives.hlm as hlm
import legoh.train.unified as unified
from legoh.config import validate
from legoh.train.prior import make_prior, train_prior
from tests.conftest import compose_config


@pytest.mark.parametrize("batch,rows", [(6144, 256), (768, 192), (64, 16)])
def test_prior_steps_take_vae_batch_rows_at_most_a_minibatch(monkeypatch, batch, rows):
    """At 256 envs a prior step took the batch's 1,536 rows (0.27 s an iteration); now
    algo.vae_batch (256) at most, and never more than the batch over algo.minibatches (the
    default 32 envs' 192 rows are unchanged)."""
    cfg = compose_config("algo=unified", "algo.minibatches=4")
    vae, optim, _ = make_prior(cfg, 19)
    seen = []
    loss = hlm.vae_loss

    def spy(vae, actions, *args, **kwargs):
        seen.append(actions.shape[0])
        return loss(vae, actions, *args, **kwargs)

    monkeypatch.setattr(hlm, "vae_loss", spy)
    train_prior(vae, optim, torch.rand(batch, 19) * 2 - 1, cfg, torch.Generator().manual_seed(0))
    assert seen == [rows] * cfg.algo.vae_steps


def _batch(n: int) -> TensorDict:
    return TensorDict({"row": torch.arange(n)[:, None].expand(n, 3)}, batch_size=[n, 3],
                      device="cpu")


@pytest.mark.parametrize("share,steps,rows", [(1.0, 4, 16), (0.5, 4, 8), (0.01, 4, 1)])
def test_distill_share_runs_that_share_of_the_sequences(monkeypatch, share, steps, rows):
    """algo.distill_share: each imitation pass takes a random share of the batch's env
    sequences (whole sequences, never split), in algo.minibatches steps; 1 covers them all."""
    cfg = compose_config("algo=unified", "algo.minibatches=4", "algo.distill_epochs=2",
                         f"algo.distill_share={share}")
    passes = []

    def step(student, batch, cfg, optim, prior_loss, context):
        passes.append(batch.get("row")[:, 0].tolist())
        assert batch.shape[1] == 3
        return {"distill/loss_action": 1.0}

    monkeypatch.setattr(unified, "distill_step", step)
    out = unified.distill(None, _batch(64), cfg, None, None, torch.Generator().manual_seed(0))
    assert len(passes) == 2 * steps and all(len(p) == rows for p in passes)
    first, second = (sum(passes[i:i + steps], []) for i in (0, steps))
    assert len(set(first)) == len(first) == steps * rows  # a pass takes a row once
    if share == 1.0:
        assert sorted(first) == sorted(second) == list(range(64))
    else:
        assert set(first) != set(second)  # a fresh draw each pass
    assert out["distill/loss_action"] == pytest.approx(1.0)


@pytest.mark.parametrize("value", [0.0, 1.5, -0.2])
def test_distill_share_out_of_range_is_refused(value):
    with pytest.raises(ValueError, match=r"algo\.distill_share"):
        validate(compose_config("algo=unified", f"algo.distill_share={value}"))
