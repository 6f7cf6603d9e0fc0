"""DAgger's mixing schedule (Ross et al., 2011): early in stage 2 the teacher's action is
executed on a share beta of the steps, so a student that falls at once still collects
states along the teacher's path; beta decays from 1 to 0 over ``algo.dagger_mix_iterations``
iterations (0, the default: off, the student always acts). Every step is labelled by the
oracle either way; PPO learns only from the steps the student acted (its log-probabilities
describe its own actions, not the teacher's).

How to measure it against the plain version (docs/unified.md, "DAgger's mixture").
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase

from legoh import keys
from legoh.modules.actor_critic import LOC


def teacher_share(iteration: int, iterations: int) -> float:
    """beta at ``iteration`` (0-based): 1 - iteration / iterations, floored at 0, so the
    teacher acts on every step of the first batch and on none from ``iterations`` on;
    0 throughout when ``iterations`` is 0 (off)."""
    if iterations <= 0:
        return 0.0
    return max(0.0, 1.0 - iteration / iterations)


class TeacherMix(TensorDictModuleBase):
    """The acting policy under DAgger's mixture.

    The student runs on every step (its recurrent state advances, its sampled action and
    log-probability are recorded); then on each env, with probability ``beta`` (a buffer,
    set each iteration from :func:`teacher_share`), the oracle's mean action replaces
    ``"action"``. Writes ``TEACHER_ACTED`` (B, 1) bool.
    """

    def __init__(self, student_policy, oracle) -> None:
        super().__init__()
        self.student, self.oracle = student_policy, oracle
        self.register_buffer("beta", torch.zeros(()))
        self.in_keys = list(dict.fromkeys([*student_policy.in_keys, *oracle.in_keys]))
        self.out_keys = [*student_policy.out_keys, keys.TEACHER_ACTED]

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        td = self.student(td)
        action = td.get(keys.ACTION)
        acted = torch.zeros(*action.shape[:-1], 1, dtype=torch.bool, device=action.device)
        beta = float(self.beta)
        if beta > 0.0:
            acted = torch.rand(acted.shape, device=action.device) < beta
            with torch.no_grad():
                teacher = self.oracle(td.select(*self.oracle.in_keys).clone(recurse=False))
            td.set(keys.ACTION, torch.where(acted, teacher.get(LOC), action))
        td.set(keys.TEACHER_ACTED, acted)
        return td


def student_rows(batch: TensorDictBase) -> TensorDictBase:
    """The flat batch (B,) of the steps the student acted (all of them without a mixture)."""
    flat = batch.reshape(-1)
    if keys.TEACHER_ACTED not in flat.keys(include_nested=True):
        return flat
    return flat[~flat.get(keys.TEACHER_ACTED).reshape(-1)]
