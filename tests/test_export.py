"""Export: the TorchScript file acts like the student it came from, step by step on a real
rollout (frames arriving, held outputs between them)."""

import warnings

import pytest
import torch
from torchrl.envs.utils import ExplorationType, set_exploration_type

from legoh import keys
from legoh.export import export_student, load_exported
from tests.test_students import build


@pytest.mark.parametrize("name", ["lego_h", "lego_h+history", "rma_b"])
def test_export_gives_the_module_actions(tmp_path, name):
    cfg, student, env = build(None, name)
    student.locomotion.eval()
    try:
        torch.manual_seed(0)
        with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
            td = env.rollout(12, student.policy, break_when_any_done=False)
    finally:
        env.close()
    with warnings.catch_warnings(record=True) as caught:  # the console stays quiet
        warnings.simplefilter("always")
        module, meta = load_exported(export_student(student, tmp_path / "policy.pt",
                                                    meta={"robot": cfg.robot.name}))
    assert not [w for w in caught if issubclass(w.category, torch.jit.TracerWarning)]
    assert meta["student"] == name.partition("+")[0] and meta["robot"] == "h1"
    n = td.shape[0]
    state = torch.zeros(n, *meta["state_shape"])
    held = torch.zeros(n, meta["held_dim"])
    depth_shape = meta["depth"] or [1, 1, 1]
    with torch.no_grad():
        for t in range(td.shape[1]):
            step = td[:, t]
            fresh = step[keys.IS_INIT].reshape(n, 1)
            if keys.DEPTH_FRESH in step.keys(True):
                fresh = fresh | step[keys.DEPTH_FRESH].reshape(n, 1)
            depth = step.get(keys.DEPTH, torch.zeros(n, *depth_shape))
            if name == "rma_b":  # blind: the navigation half runs every step
                fresh = torch.ones_like(fresh)
            action, state, held = module(depth, step[keys.GOAL], step[keys.PROPRIO],
                                         step[keys.PROPRIO_HISTORY], state, held, fresh)
            torch.testing.assert_close(action, step["action"], rtol=1e-4, atol=1e-5)
