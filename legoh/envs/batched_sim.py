"""N robots stepped in parallel by MuJoCo's own thread pool (``mujoco.rollout``): the CPU
backend of ``legoh.envs.physics``.

Each env owns a physics state row; one call advances all N by ``substeps`` with the PD loop
inside MuJoCo's actuators, releasing the GIL, and returns every substep's sensordata. Envs
may use different MjModels of the same size signature (the domain-randomisation pool). The
state lives in numpy arrays that MuJoCo writes; the torch tensors are zero-copy views.
"""

from __future__ import annotations

import os

import mujoco
import numpy as np
import torch
from mujoco import rollout

from legoh.config.env import DepthBackend, depth_backend
from legoh.envs.heightmap_depth import HeightmapDepthCamera
from legoh.envs.sensors import DepthRaycaster

STATE_SPEC = mujoco.mjtState.mjSTATE_FULLPHYSICS


class BatchedSim:
    """Physics state of N envs, stepped together (the contract: ``legoh.envs.physics``).

    Attributes:
        state: (N, nstate) float64 numpy, MuJoCo's full physics state per env.
        sensordata: (N, substeps, nsensordata) float64 tensor, from the last step.
        model_of_env: (N,) int64 tensor, which pool model each env steps with.
    """

    device = torch.device("cpu")
    dtype = torch.float64

    def __init__(self, models: list[mujoco.MjModel], num_envs: int, substeps: int,
                 threads: int = 0) -> None:
        self.models = models
        self.num_draws = len(models)
        self.num_envs, self.substeps = num_envs, substeps
        model = models[0]
        self.nq, self.nv = model.nq, model.nv
        self.threads = threads or os.cpu_count() or 1
        self._pool = rollout.Rollout(nthread=self.threads)
        self._datas = [mujoco.MjData(model) for _ in range(self.threads)]
        self._scratch = mujoco.MjData(model)  # resets only
        nstate = mujoco.mj_stateSize(model, STATE_SPEC)
        # Full physics state layout: time, qpos, qvel, act, ... (MuJoCo's mjtState order).
        self.state = np.zeros((num_envs, nstate))
        self._sensordata = np.zeros((num_envs, substeps, model.nsensordata))
        self._state_out = np.zeros((num_envs, substeps, nstate))
        self._control = np.zeros((num_envs, substeps, model.nu))
        state = torch.from_numpy(self.state)
        self.time = state[:, 0]
        self.qpos = state[:, 1:1 + self.nq]
        self.qvel = state[:, 1 + self.nq:1 + self.nq + self.nv]
        self.sensordata = torch.from_numpy(self._sensordata)
        self._control_t = torch.from_numpy(self._control)
        self._model_of_env = np.zeros(num_envs, dtype=np.int64)
        self.model_of_env = torch.from_numpy(self._model_of_env)
        self._model_list = [models[0]] * num_envs

    def set_models(self, env_ids: torch.Tensor, model_ids: torch.Tensor) -> None:
        """Assign pool models to envs (takes effect from the next step)."""
        self.model_of_env[env_ids] = model_ids
        self._model_list = [self.models[k] for k in self._model_of_env]

    def step(self, ctrl: torch.Tensor) -> None:
        """Advance every env by ``substeps`` physics steps holding ``ctrl`` (N, nu)."""
        self._control_t.copy_(ctrl[:, None, :])
        self._pool.rollout(self._model_list, self._datas, self.state, self._control,
                           nstep=self.substeps, state=self._state_out,
                           sensordata=self._sensordata, skip_checks=True)
        self.state[:] = self._state_out[:, -1]

    def reset_envs(self, env_ids: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor,
                   ctrl: torch.Tensor) -> None:
        """Put envs in a new state and fill their sensordata by a forward pass.

        A per-env loop, on reset envs only: a forward pass is the only way to get the
        sensors of a state that was never stepped.
        """
        d = self._scratch
        qpos, qvel, ctrl = qpos.numpy(), qvel.numpy(), ctrl.numpy()
        for k, env in enumerate(env_ids.tolist()):
            model = self.models[self._model_of_env[env]]
            mujoco.mj_resetData(model, d)
            d.qpos[:], d.qvel[:], d.ctrl[:] = qpos[k], qvel[k], ctrl[k]
            mujoco.mj_forward(model, d)
            mujoco.mj_getState(model, d, self.state[env], STATE_SPEC)
            self._sensordata[env, :] = d.sensordata

    def make_depth_camera(self, fovy_deg: float, width: int, height: int, far: float,
                          backend: DepthBackend | str = DepthBackend.multiray
                          ) -> RaycastCamera | HeightmapDepthCamera:
        """A depth camera against the nominal world (static geoms): ``multiray`` casts with
        ``mj_multiRay`` in this backend's threads, ``raymarch`` marches the map in torch."""
        if depth_backend(backend) == DepthBackend.raymarch:
            return HeightmapDepthCamera(self.models[0], fovy_deg, width, height, far,
                                        self.device, self.threads)
        return RaycastCamera(self.models[0], fovy_deg, width, height, far, self.threads)

    def close(self) -> None:
        """Stop the thread pool."""
        self._pool.close()


class RaycastCamera:
    """``DepthRaycaster`` behind the backend contract: torch poses in, torch depth out."""

    def __init__(self, model: mujoco.MjModel, fovy_deg: float, width: int, height: int,
                 far: float, threads: int) -> None:
        self._world = mujoco.MjData(model)  # the world's static geoms, posed once
        mujoco.mj_forward(model, self._world)
        self._caster = DepthRaycaster(model, fovy_deg, width, height, far, threads)

    def render(self, cam_pos: torch.Tensor, cam_mat: torch.Tensor) -> torch.Tensor:
        """Planar depth (k, H, W) in metres for camera positions (k, 3), rotations (k, 3, 3)."""
        depth = self._caster.render(self._world, np.ascontiguousarray(cam_pos.numpy()),
                                    np.ascontiguousarray(cam_mat.numpy()))
        return torch.from_numpy(depth)
