"""Every committed oracle checkpoint still loads and computes what it computed when it was
recorded: the actor's mean action, the critic's value and the adaptation module's latent on
fixed observations (tests/data/checkpoint_outputs.json, recorded before the renovation of
issue 19 with the code of 8118900).

A checkpoint whose bytes changed since (a campaign committed a newer one) must still load
and give finite outputs; its numbers are re-recorded with ``python
tests/test_committed_checkpoints.py``.
"""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
import warnings
from pathlib import Path

import pytest
import torch
from omegaconf import OmegaConf
from tensordict import TensorDict

from legoh.config.compose import compose_config
from legoh.envs.robots import build_robot_spec
from legoh.modules.actor_critic import (
    LOC,
    STATE_VALUE,
    OracleInputDims,
    OracleNetConfig,
    make_oracle_actor_critic,
)
from legoh.modules.encoders import PRIV_LATENT_EST, make_adaptation_module
from legoh.train.oracle import load_oracle_checkpoint, oracle_net_config

ROOT = Path(__file__).resolve().parents[1]
RECORDED = ROOT / "tests" / "data" / "checkpoint_outputs.json"
BATCH = 3  # fixed observations per checkpoint


def committed_checkpoints() -> list[str]:
    """Oracle checkpoints tracked by git under experiments/results, and pretrained/*.pt."""
    out = subprocess.run(["git", "ls-files", "experiments/results", "pretrained"], cwd=ROOT,
                         capture_output=True, text=True, check=True).stdout.split()
    return [p for p in out if p.endswith("/oracle.pt") or p.startswith("pretrained/")
            and p.endswith("_oracle.pt")]


def outputs(path: str) -> dict:
    """Actor mean, critic value and adaptation latent on seeded observations of the
    checkpoint's own layout, its robot's action count."""
    robot = torch.load(ROOT / path, map_location="cpu", weights_only=True)["robot"]
    cfg = compose_config(f"robot={robot}")
    state = load_oracle_checkpoint(ROOT / path, cfg)
    net_cfg = oracle_net_config(cfg, state)
    dims = OracleInputDims.from_layout(state["layout"])
    actions = len(build_robot_spec(OmegaConf.to_object(cfg.robot))[1].action_scale)
    net = OracleNetConfig(init_std=net_cfg.algo.init_noise_std,
                          critic=tuple(int(s) for s in net_cfg.algo.critic_hidden))
    actor, critic = make_oracle_actor_critic(dims, actions, net_cfg.algo.tanh_bound, net)
    adaptation = make_adaptation_module(dims.proprio, dims.history)
    for name, module in (("actor", actor), ("critic", critic), ("adaptation", adaptation)):
        module.load_state_dict(state["models"][name])
    gen = torch.Generator().manual_seed(0)
    td = TensorDict({tuple(k.split("/")): torch.randn(BATCH, *shape, generator=gen)
                     for k, shape in sorted(state["layout"].items())}, batch_size=[BATCH])
    with torch.no_grad():
        return {"action": actor(td.clone())[LOC], "value": critic(td.clone())[STATE_VALUE],
                "adaptation": adaptation(td.clone())[PRIV_LATENT_EST]}


def sha256(path: str) -> str:
    return hashlib.sha256((ROOT / path).read_bytes()).hexdigest()


@pytest.mark.parametrize("path", committed_checkpoints())
def test_committed_checkpoint_computes_what_it_did(path: str) -> None:
    got = outputs(path)
    want = json.loads(RECORDED.read_text()).get(path)
    if want is None or want["sha256"] != sha256(path):
        assert all(torch.isfinite(v).all() for v in got.values())
        warnings.warn(f"{path}: no recorded outputs for these bytes; record them with "
                      f"python tests/test_committed_checkpoints.py", stacklevel=1)
        return
    for name, value in got.items():
        torch.testing.assert_close(value, torch.tensor(want[name]), rtol=1e-5, atol=1e-5,
                                   msg=lambda m, name=name: f"{path} {name}: {m}")


def record() -> None:
    """Write the outputs of every committed checkpoint to tests/data."""
    table = {p: {"sha256": sha256(p), **{k: v.tolist() for k, v in outputs(p).items()}}
             for p in committed_checkpoints()}
    RECORDED.write_text(json.dumps(table, indent=1) + "\n")
    print(f"recorded {len(table)} checkpoints in {RECORDED}")


if __name__ == "__main__":
    sys.exit(record())
