"""Checkpoints: round trip, atomic writes, refusals of another robot or layout."""

import random

import numpy as np
import pytest
import torch
from torch import nn

from legoh import checkpoint as ckpt
from legoh.checkpoint import (
    CheckpointError,
    load_checkpoint,
    make_payload,
    restore_rng,
    save_checkpoint,
)

LAYOUT = {("obs", "proprio"): (63,), ("obs", "proprio_history"): (10, 63)}


def payload(**over) -> dict:
    torch.manual_seed(0)
    model = nn.Linear(4, 2)
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    model(torch.randn(3, 4)).sum().backward()
    opt.step()
    args = dict(models={"actor": model}, optimizers={"actor": opt}, iteration=12, robot="h1",
                layout=LAYOUT, curriculum={"levels": torch.arange(4)},
                config={"algo": {"lr": 2e-4}, "robot": "h1"})
    return make_payload(**{**args, **over})


def test_round_trip(tmp_path):
    p = payload()
    save_checkpoint(tmp_path / "c.pt", p)
    got = load_checkpoint(tmp_path / "c.pt", expect_robot="h1", expect_layout=LAYOUT)
    assert got["iteration"] == 12 and got["config"] == {"algo": {"lr": 2e-4}, "robot": "h1"}
    assert got["layout"] == {"obs/proprio": (63,), "obs/proprio_history": (10, 63)}
    for k, v in p["models"]["actor"].items():
        assert torch.equal(got["models"]["actor"][k], v)
    assert got["optimizers"]["actor"]["state"][0]["step"] == 1
    assert torch.equal(got["curriculum"]["levels"], torch.arange(4))
    model = nn.Linear(4, 2)
    model.load_state_dict(got["models"]["actor"])


def test_rng_states_restore(tmp_path):
    save_checkpoint(tmp_path / "c.pt", payload())
    expected = (torch.rand(3), np.random.rand(3), random.random())
    restore_rng(load_checkpoint(tmp_path / "c.pt")["rng"])
    got = (torch.rand(3), np.random.rand(3), random.random())
    assert torch.equal(got[0], expected[0]) and np.array_equal(got[1], expected[1])
    assert got[2] == expected[2]


def test_failed_write_leaves_old_file_and_no_temp(tmp_path):
    path = tmp_path / "c.pt"
    save_checkpoint(path, payload(iteration=1))
    bad = payload(iteration=2)
    bad["extra"] = {"fn": lambda: None}  # unpicklable: torch.save fails midway
    with pytest.raises(Exception, match="lambda|pickle|Can't"):
        save_checkpoint(path, bad)
    assert [f.name for f in tmp_path.iterdir()] == ["c.pt"]
    assert load_checkpoint(path)["iteration"] == 1


def test_crash_before_rename_leaves_no_partial_file(tmp_path, monkeypatch):
    def boom(*_):
        raise OSError("disk gone")

    monkeypatch.setattr(ckpt.os, "replace", boom)
    with pytest.raises(OSError, match="disk gone"):
        save_checkpoint(tmp_path / "c.pt", payload())
    assert list(tmp_path.iterdir()) == []


def test_wrong_robot_refused(tmp_path):
    save_checkpoint(tmp_path / "c.pt", payload())
    with pytest.raises(CheckpointError, match="robot 'h1'.*robot 'g1'"):
        load_checkpoint(tmp_path / "c.pt", expect_robot="g1")


def test_wrong_layout_refused(tmp_path):
    save_checkpoint(tmp_path / "c.pt", payload())
    other = {**LAYOUT, ("obs", "proprio"): (70,)}
    with pytest.raises(CheckpointError, match=r"\(63,\).*\(70,\).*differing keys: \['obs/pro"):
        load_checkpoint(tmp_path / "c.pt", expect_layout=other)


def test_missing_and_corrupt_files(tmp_path):
    with pytest.raises(FileNotFoundError, match="no checkpoint at"):
        load_checkpoint(tmp_path / "nope.pt")
    save_checkpoint(tmp_path / "c.pt", payload())
    data = (tmp_path / "c.pt").read_bytes()
    (tmp_path / "c.pt").write_bytes(data[: len(data) // 2])
    with pytest.raises(CheckpointError, match="corrupt or truncated"):
        load_checkpoint(tmp_path / "c.pt")
    torch.save({"hello": 1}, tmp_path / "x.pt")
    with pytest.raises(CheckpointError, match="not a legoh checkpoint"):
        load_checkpoint(tmp_path / "x.pt")


def test_incomplete_payload_refused(tmp_path):
    with pytest.raises(ValueError, match="lacks"):
        save_checkpoint(tmp_path / "c.pt", {"models": {}})


def test_damaged_bytes_are_refused(tmp_path):
    """100 random bytes in the middle of a checkpoint: refused, naming the damaged entry.

    Failed before with: DID NOT RAISE (torch.load skips the zip CRCs; values up to 1e36
    loaded into the model)."""
    torch.manual_seed(0)
    big = nn.Linear(200, 100)
    save_checkpoint(tmp_path / "c.pt", payload(models={"actor": big}, optimizers=None))
    data = bytearray((tmp_path / "c.pt").read_bytes())
    mid = len(data) // 2
    data[mid:mid + 100] = np.random.default_rng(0).bytes(100)
    (tmp_path / "c.pt").write_bytes(bytes(data))
    with pytest.raises(CheckpointError, match=r"c\.pt is damaged: zip entry '.*data/\d+' fails"):
        load_checkpoint(tmp_path / "c.pt")


@pytest.mark.parametrize("bad", [float("nan"), 5e34])
def test_non_finite_or_absurd_tensors_are_refused(tmp_path, bad):
    """A checkpoint holding NaN or 5e34 (a diverged run, damage behind a valid CRC) is refused,
    naming the file and the tensor.

    Failed before with: DID NOT RAISE (the values reached the model and Adam)."""
    model = nn.Linear(4, 2)
    with torch.no_grad():
        model.weight[0, 1] = bad
    save_checkpoint(tmp_path / "c.pt", payload(models={"actor": model}, optimizers=None))
    with pytest.raises(CheckpointError, match=r"c\.pt: tensor models/actor/weight holds"):
        load_checkpoint(tmp_path / "c.pt")
