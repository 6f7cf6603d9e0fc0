"""Physics backends behind one contract: N envs' state as torch tensors on the backend's
device, stepped together.

``make_physics`` returns an object with (all tensors torch, on ``backend.device``):

* ``device``, ``num_envs``, ``substeps``, ``nq``, ``nv``, ``dtype`` (float64 for mujoco,
  float32 for warp), ``num_draws`` (physics draws: 0 is the nominal one);
* ``qpos`` (N, nq) and ``qvel`` (N, nv): views, in-place writes go into the physics state;
  ``time`` (N,); ``sensordata`` (N, substeps, nsensordata): every substep of the last step;
  ``model_of_env`` (N,) int64: which draw each env steps with;
* ``set_models(ids, draw_ids)`` (from the next step), ``step(ctrl (N, nu))``,
  ``reset_envs(ids, qpos (k, nq), qvel (k, nv), ctrl (k, nu))`` (sets the state and fills
  those envs' sensordata by a forward pass), ``make_depth_camera(fovy_deg, width, height,
  far, backend)`` -> an object whose ``render(cam_pos (k, 3), cam_mat (k, 3, 3))`` gives
  (k, H, W) planar depth in metres (``backend``: a ``DepthBackend``, ``multiray`` by
  default: the backend's own ray cast; ``raymarch``: ``legoh.envs.heightmap_depth``), and
  ``close()``.

Backends: ``mujoco`` (``BatchedSim``: CPU, ``mujoco.rollout``), ``warp`` (``WarpSim``:
MuJoCo Warp on a GPU, the ``gpu`` extra).
"""

from __future__ import annotations

import warnings

import mujoco
import torch

from legoh.envs.randomization import PhysicsDraw, build_model_pool

BACKENDS = ("mujoco", "warp")


def physics_device(sim) -> str:
    """Where ``sim`` (a SimConfig) keeps its state: the CPU for mujoco; for warp
    ``sim.warp_device``, ``auto`` being the GPU when torch sees one, else Warp's CPU device."""
    if sim.backend != "warp":
        return "cpu"
    if sim.warp_device == "auto":
        if torch.cuda.is_available():
            return "cuda"
        warnings.warn("sim.backend=warp: torch sees no CUDA GPU, so MuJoCo Warp runs on its CPU "
                      "device (about 20x slower than sim.backend=mujoco; docs/scaling.md)",
                      stacklevel=2)
        return "cpu"
    return str(sim.warp_device)


def sim_options(sim) -> dict:
    """The backend's own settings from ``sim`` (a SimConfig): MuJoCo Warp's buffer sizes,
    graph capture and overflow checks; none for mujoco."""
    if sim.backend != "warp":
        return {}
    return {"nconmax": sim.nconmax, "njmax": sim.njmax, "graph": sim.graph,
            "overflow_check_every": sim.overflow_check_every}


def make_physics(backend: str, model: mujoco.MjModel, base_body: str, draws: PhysicsDraw,
                 num_envs: int, substeps: int, threads: int, device: str, **options):
    """The physics of ``num_envs`` envs on ``backend`` (see the module docstring);
    ``options``: the backend's own settings (:func:`sim_options`)."""
    if backend == "mujoco":
        from legoh.envs.batched_sim import BatchedSim

        return BatchedSim(build_model_pool(model, base_body, draws), num_envs, substeps,
                          threads)
    if backend == "warp":
        try:
            from legoh.envs.warp_sim import WarpSim
        except ImportError as err:
            raise ImportError(
                f"sim.backend=warp needs MuJoCo Warp ({err}); install the `gpu` extra: "
                "pip install -e '.[gpu]'") from err
        return WarpSim(model, base_body, draws, num_envs, substeps, threads, device, **options)
    raise ValueError(f"sim.backend={backend!r}: known backends {list(BACKENDS)}")
