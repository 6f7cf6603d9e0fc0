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

from legoh.envs.hiking_env import make_env
from legoh.envs.robots import build_robot_spec
from legoh.modules.actor_critic import LOC, STATE_VALUE
from legoh.modules.encoders import PRIV_LATENT_EST
from legoh.policies.oracle import load_oracle, load_oracle_checkpoint
from legoh.train.oracle import OraclePPO
from tests.conftest import compose_config

ROOT = Path(__file__).resolve().parents[1]
RECORDED = ROOT / "tests" / "data" / "checkpoint_outputs.json"
BATCH = 3  # fixed observations per checkpoint


def committed_checkpoints() -> list[str]:
    """Oracle checkpoints tracked by git under experiments/results, and pretrained/*.pt."""
    out = subprocess.run(["git", "ls-files", "experiments/results", "pretrained"], cwd=ROOT,
                         capture_output=True, text=True, check=True).stdout.split()
    return [p for p in out if p.endswith("/oracle.pt") or p.startswith("pretrained/")
            and p.endswith("_oracle.pt")]


def robot_config(path: str):
    """The current config of the checkpoint's robot (older checkpoints' own configs no longer
    fit the schema; the checkpoint's network settings are read from it by the loaders)."""
    robot = torch.load(ROOT / path, map_location="cpu", weights_only=True)["robot"]
    return compose_config(f"robot={robot}", "trail=flat", "trail.variants=1", "trail.levels=1")


def fixed_observations(layout: dict) -> TensorDict:
    """BATCH seeded normal draws of every input of ``layout``."""
    gen = torch.Generator().manual_seed(0)
    return TensorDict({tuple(k.split("/")): torch.randn(BATCH, *shape, generator=gen)
                       for k, shape in sorted(layout.items())}, batch_size=[BATCH])


def outputs_of(actor, critic, adaptation, layout: dict) -> dict:
    """Actor mean, critic value and adaptation latent on :func:`fixed_observations`."""
    td = fixed_observations(layout)
    with torch.no_grad():
        return {"action": actor(td.clone())[LOC], "value": critic(td.clone())[STATE_VALUE],
                "adaptation": adaptation(td.clone())[PRIV_LATENT_EST]}


def outputs(path: str) -> dict:
    """The outputs of checkpoint ``path`` loaded as eval, play and stage 2 load it."""
    cfg = robot_config(path)
    layout = load_oracle_checkpoint(ROOT / path, cfg)["layout"]  # after any conversion
    actions = len(build_robot_spec(OmegaConf.to_object(cfg.robot))[1].action_scale)
    return outputs_of(*load_oracle(cfg, ROOT / path, actions), layout)


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


@pytest.mark.parametrize("path", committed_checkpoints())
def test_committed_checkpoint_resumes_into_the_oracle_algorithm(path: str) -> None:
    """The runner's resume path: the algorithm reads the checkpoint and loads models and
    optimisers under the names the campaign's checkpoints carry."""
    state = torch.load(ROOT / path, map_location="cpu", weights_only=True)
    critic = state["extra"].get("critic_hidden", [512, 256, 128])
    cfg = OmegaConf.merge(robot_config(path), {"algo": {"critic_hidden": critic}})
    env = make_env(cfg, num_envs=1)
    try:
        algorithm = OraclePPO(cfg, env, device=torch.device("cpu"))
        algorithm.load_state_dict(algorithm.read_checkpoint(ROOT / path))
    finally:
        env.close()
    assert set(algorithm.models) == set(state["models"])
    assert set(algorithm.optimizers) == set(state["optimizers"])
    want = json.loads(RECORDED.read_text()).get(path)
    if want is not None and want["sha256"] == sha256(path):
        got = outputs_of(*algorithm.models.values(), algorithm.layout)
        torch.testing.assert_close(got["action"], torch.tensor(want["action"]), rtol=1e-5,
                                   atol=1e-5)


def record() -> None:
    """Write the outputs of every committed checkpoint to tests/data."""
    table = {p: {"sha256": sha256(p), **{k: v.tolist() for k, v in outputs(p).items()}}
             for p in committed_checkpoints()}
    RECORDED.write_text(json.dumps(table, indent=1) + "\n")
    print(f"recorded {len(table)} checkpoints in {RECORDED}")


if __name__ == "__main__":
    sys.exit(record())
