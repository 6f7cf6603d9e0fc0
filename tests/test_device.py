"""GPU placement: ``device`` picks the learner's device, the envs stay on the CPU.

This machine has no GPU: the parsing, the refusal of CUDA without one, and a training
iteration through the switch run here; the CUDA run itself runs where torch sees a GPU.
"""

from pathlib import Path

import pytest
import torch

from legoh.envs.physics import physics_device
from legoh.train.collect import policy_device, worker_policy_device
from legoh.train.oracle import train_oracle
from tests.conftest import compose_config
from tests.test_train_oracle import TINY

HAS_CUDA = torch.cuda.is_available()


@pytest.mark.parametrize(("name", "expected"), [("cpu", "cpu"), ("cuda", "cuda"),
                                                ("cuda:1", "cuda:1")])
def test_device_names_parse(name: str, expected: str, monkeypatch) -> None:
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    assert policy_device(compose_config(f"device={name}")) == torch.device(expected)


def test_auto_follows_the_machine(monkeypatch) -> None:
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert policy_device(compose_config("device=auto")) == torch.device("cpu")
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    assert policy_device(compose_config("device=auto")) == torch.device("cuda")


def test_cuda_without_a_gpu_is_a_clear_error(monkeypatch) -> None:
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    with pytest.raises(RuntimeError, match="no CUDA GPU"):
        policy_device(compose_config("device=cuda"))


def test_cuda_without_a_gpu_stops_training_before_any_work(tmp_path: Path,
                                                           monkeypatch) -> None:
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    with pytest.raises(RuntimeError, match="device=cuda"):
        train_oracle(compose_config(*TINY, "device=cuda", "algo.total_frames=32"), tmp_path)
    assert not (tmp_path / "train.csv").exists()


@pytest.mark.parametrize("name", ["tpu", "banana", "mps"])
def test_other_devices_are_refused(name: str) -> None:
    with pytest.raises(ValueError, match=name):
        policy_device(compose_config(f"device={name}"))


def test_workers_follow_the_learner_unless_told(monkeypatch) -> None:
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    cfg = compose_config("device=cuda")
    assert worker_policy_device(cfg) == torch.device("cuda")
    assert worker_policy_device(compose_config("device=cuda", "collector.policy_device=cpu")
                                ) == torch.device("cpu")
    ray_cfg = compose_config("device=cuda", "collector=ray")
    assert worker_policy_device(ray_cfg) == torch.device("cpu")  # Ray workers: CPU default
    assert physics_device(cfg.sim) == "cpu"  # MuJoCo steps on the CPU, whatever the learner
    assert physics_device(compose_config("sim=warp").sim) == "cuda"  # the GPU torch sees


def test_training_runs_through_the_device_switch(tmp_path: Path) -> None:
    """device=cpu explicitly: the learner, the batch and the checkpoint all on the CPU."""
    cfg = compose_config(*TINY, "device=cpu", "algo.total_frames=32")
    run = train_oracle(cfg, tmp_path)
    assert run.iterations == 1
    assert all(p.device == torch.device("cpu") for p in run.policy.parameters())


@pytest.mark.skipif(not HAS_CUDA, reason="no CUDA GPU on this machine")
def test_training_on_the_gpu(tmp_path: Path) -> None:
    """device=cuda: the learner's weights on the GPU, the envs stepping on the CPU."""
    cfg = compose_config(*TINY, "device=cuda", "algo.total_frames=64")
    run = train_oracle(cfg, tmp_path)
    assert run.iterations == 2
    assert all(p.is_cuda for p in run.policy.parameters())
