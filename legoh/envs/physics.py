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
  far)`` -> an object whose ``render(cam_pos (k, 3), cam_mat (k, 3, 3))`` gives (k, H, W)
  planar depth in metres, and ``close()``.

Backends: ``mujoco`` (``BatchedSim``: CPU, ``mujoco.rollout``), ``warp`` (``WarpSim``:
MuJoCo Warp on a GPU, the ``gpu`` extra).
"""

from __future__ import annotations

import mujoco

from legoh.envs.randomization import PhysicsDraw, build_model_pool

BACKENDS = ("mujoco", "warp")
DEFAULT_DEVICE = {"mujoco": "cpu", "warp": "cuda"}  # where each backend keeps its state


def make_physics(backend: str, model: mujoco.MjModel, base_body: str, draws: PhysicsDraw,
                 num_envs: int, substeps: int, threads: int, device: str):
    """The physics of ``num_envs`` envs on ``backend`` (see the module docstring)."""
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
        return WarpSim(model, base_body, draws, num_envs, substeps, threads, device)
    raise ValueError(f"sim.backend={backend!r}: known backends {list(BACKENDS)}")
