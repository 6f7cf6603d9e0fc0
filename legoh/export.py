"""Deployment: a trained student as one TorchScript file (no legoh, torchrl or tensordict
needed to run it; ``torch.jit.load`` is enough).

The file holds one module with three methods, all on plain tensors (batch B first):

* ``encode(depth, goal, proprio, proprio_history, state) -> (held, state)``: the
  navigation half, once per depth frame (10 Hz).
* ``act(goal, proprio, proprio_history, held) -> action``: the locomotion half, every
  policy step (50 Hz), on the outputs held since the last frame (latent tiling).
* ``forward(depth, goal, proprio, proprio_history, state, held, fresh)
  -> (action, state, held)``: one policy step that refreshes the held outputs where
  ``fresh`` (B, 1) is true; both halves run, so ``encode`` + ``act`` is the cheaper loop.

Inputs: depth (B, T, H, W) normalised to [-0.5, 0.5] (``d / far - 0.5``, oldest first),
goal (B, 4) terminus and middle waypoint xy in the robot's yaw frame (m), proprio (B, P) and
proprio_history (B, 10, P) as ``docs/env.md`` defines them; ``state`` and ``held`` start at
zeros (shapes in the file's ``state_shape`` / ``held_dim`` attributes). Output: the joint
action (B, A), deterministic (the policy's mean), before the env's clip and scale.

Tracing (not scripting): the students' control flow does not depend on data inside
``encode`` and ``act``, and tracing keeps torch's own layers (attention, GRU) as they are.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import torch
from torch import Tensor, nn

from legoh import keys
from legoh.modules.students import Student

META_FILE = "legoh.json"


class DeployedStudent(nn.Module):
    """A student on plain tensors (see the module docstring for the methods)."""

    def __init__(self, student: Student) -> None:
        super().__init__()
        self.navigator = student.navigation.navigator
        self.head = student.locomotion.module[0].module  # GaussianPolicyHead: (loc, scale)
        self.state_shape = list(self.navigator.state_shape)
        self.held_dim = int(self.navigator.held_dim)

    def _obs(self, depth, goal, proprio, proprio_history) -> dict:
        return {keys.DEPTH: depth, keys.GOAL: goal, keys.PROPRIO: proprio,
                keys.PROPRIO_HISTORY: proprio_history}

    def encode(self, depth: Tensor, goal: Tensor, proprio: Tensor, proprio_history: Tensor,
               state: Tensor) -> tuple[Tensor, Tensor]:
        return self.navigator.frame(self._obs(depth, goal, proprio, proprio_history), state)

    def act(self, goal: Tensor, proprio: Tensor, proprio_history: Tensor, held: Tensor
            ) -> Tensor:
        out = self.navigator.act(self._obs(None, goal, proprio, proprio_history), held)
        extra = [out["history_latent"]] if "history_latent" in out else []
        loc, _ = self.head(proprio, out["latent"], out["nav_goal"], *extra)
        return loc

    def forward(self, depth: Tensor, goal: Tensor, proprio: Tensor, proprio_history: Tensor,
                state: Tensor, held: Tensor, fresh: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        new_held, new_state = self.encode(depth, goal, proprio, proprio_history, state)
        held = torch.where(fresh, new_held, held)
        state = torch.where(fresh.view(-1, *[1] * (state.dim() - 1)), new_state, state)
        return self.act(goal, proprio, proprio_history, held), state, held


def example_inputs(student: Student, batch: int = 1) -> dict[str, Tensor]:
    """Zeros of the right shapes for every input (a depth of 0: mid-range)."""
    dims = student.dims
    frames, height, width = dims.depth or (1, 1, 1)
    nav = student.navigation.navigator
    return {"depth": torch.zeros(batch, frames, height, width),
            "goal": torch.tensor([[4.0, 0.0, 2.0, 0.0]]).expand(batch, 4).clone(),
            "proprio": torch.zeros(batch, dims.proprio),
            "proprio_history": torch.zeros(batch, dims.history, dims.proprio),
            "state": torch.zeros(batch, *nav.state_shape),
            "held": torch.zeros(batch, nav.held_dim),
            "fresh": torch.ones(batch, 1, dtype=torch.bool)}


def export_student(student: Student, path: str | Path, meta: dict | None = None) -> Path:
    """Trace ``student`` (eval mode, no gradients) into one TorchScript file at ``path``.

    The file also carries ``legoh.json`` (read it with :func:`load_exported`): the input
    shapes, the state sizes and ``meta`` (robot, action scale, depth range...)."""
    deployed = DeployedStudent(student).eval()
    x = example_inputs(student)
    enc = (x["depth"], x["goal"], x["proprio"], x["proprio_history"], x["state"])
    with torch.no_grad(), warnings.catch_warnings():
        # the libraries' shape checks (tensordict's distribution, torch's GRU input) on
        # shapes the traced file fixes anyway: the tracer's warnings about them are noise
        warnings.filterwarnings("ignore", category=torch.jit.TracerWarning,
                                module=r"(tensordict\.nn\.distributions|torch\.nn\.modules\.rnn)")
        held, _ = deployed.encode(*enc)
        traced = torch.jit.trace_module(deployed, {
            "encode": enc,
            "act": (x["goal"], x["proprio"], x["proprio_history"], held),
            "forward": (*enc, held, x["fresh"]),
        }, check_trace=False)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    info = {"student": student.name, "state_shape": list(deployed.state_shape),
            "held_dim": deployed.held_dim, "proprio": student.dims.proprio,
            "history": student.dims.history, "depth": list(student.dims.depth or []),
            "depth_far": student.dims.depth_far, **(meta or {})}
    torch.jit.save(traced, str(tmp), _extra_files={META_FILE: json.dumps(info)})
    tmp.replace(path)  # atomic: a killed export leaves no half-written file
    return path


def load_exported(path: str | Path) -> tuple[torch.jit.ScriptModule, dict]:
    """The exported module and its ``legoh.json`` metadata."""
    extra = {META_FILE: ""}
    module = torch.jit.load(str(path), _extra_files=extra)
    return module.eval(), json.loads(extra[META_FILE])
