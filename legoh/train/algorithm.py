"""What :class:`legoh.train.runner.OnPolicyRunner` drives: a stage's networks, optimisers
and update behind one interface (rsl_rl's algorithms are the shape).

An algorithm is built whole (networks on the learner's device, optimisers, losses) before
the runner sees it. Its ``models`` and ``optimizers`` names are the keys of its checkpoints
(the oracle's: actor, critic, adaptation; ppo, adaptation): renaming one breaks the loading
of every checkpoint written before.
"""

from __future__ import annotations

from pathlib import Path

import torch


class Algorithm:
    """A training stage's learner.

    Attributes set by subclasses:
        name: the checkpoint's stem (``<name>.pt``). label: the progress bar's.
        policy: the module the collector acts with (reads observations, writes ``action``).
        models / optimizers: name -> module / optimiser, what checkpoints hold.
        layout: the observation layout checkpoints carry (key -> per-env shape).
        extra: more checkpoint fields (the oracle's critic size, the student's type).
        device: the learner's device; batches arrive there.
    """

    name: str
    label: str
    policy: torch.nn.Module
    models: dict[str, torch.nn.Module]
    optimizers: dict[str, torch.optim.Optimizer]
    layout: dict
    extra: dict
    device: torch.device

    def update(self, batch) -> dict[str, float]:
        """Learn from one (envs, time) batch; returns its scalars (``loss_*``, ``time/*``)."""
        raise NotImplementedError

    def read_checkpoint(self, path: str | Path) -> dict:
        """Read a checkpoint of this algorithm, refusing one that does not fit it."""
        raise NotImplementedError

    def progress(self, stats: dict) -> dict[str, str]:
        """Extra progress-bar fields from an iteration's ``stats``."""
        return {}

    def state_dict(self) -> dict:
        """``{"models": {name: state dict}, "optimizers": {name: state dict}}``: the
        algorithm's part of a checkpoint."""
        return {"models": {k: m.state_dict() for k, m in self.models.items()},
                "optimizers": {k: o.state_dict() for k, o in self.optimizers.items()}}

    def load_state_dict(self, state: dict) -> None:
        """Load :meth:`state_dict`'s part of a checkpoint (models and optimisers)."""
        for name, module in self.models.items():
            module.load_state_dict(state["models"][name])
        for name, optim in self.optimizers.items():
            optim.load_state_dict(state["optimizers"][name])


def start_at_checkpoint_lr(optimizer: torch.optim.Optimizer, state: dict) -> None:
    """A warm start's PPO optimiser at the learning rate checkpoint ``state``'s adaptive
    schedule had reached (unchanged when it stores no PPO optimiser): a fresh Adam at the
    configured 1e-3 undid a walker within 5 iterations."""
    lr = state.get("optimizers", {}).get("ppo", {}).get("param_groups", [{}])[0].get("lr")
    for group in optimizer.param_groups:
        group["lr"] = lr or group["lr"]
