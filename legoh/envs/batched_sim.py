"""N robots stepped in parallel by MuJoCo's own thread pool (``mujoco.rollout``).

Each env owns a physics state row; one call advances all N by ``substeps`` with the PD loop
inside MuJoCo's actuators, releasing the GIL, and returns every substep's sensordata. Envs
may use different MjModels of the same size signature (the domain-randomisation pool).
"""

from __future__ import annotations

import os

import mujoco
import numpy as np
from mujoco import rollout

STATE_SPEC = mujoco.mjtState.mjSTATE_FULLPHYSICS


class BatchedSim:
    """Physics state of N envs as arrays, stepped together.

    Attributes:
        state: (N, nstate) float64, MuJoCo's full physics state per env.
        sensordata: (N, substeps, nsensordata) float64, from the last step.
        model_of_env: (N,) int, which pool model each env steps with.
    """

    def __init__(self, models: list[mujoco.MjModel], num_envs: int, substeps: int,
                 threads: int = 0) -> None:
        self.models = models
        self.num_envs, self.substeps = num_envs, substeps
        model = models[0]
        self.nq, self.nv = model.nq, model.nv
        self.threads = threads or os.cpu_count() or 1
        self._pool = rollout.Rollout(nthread=self.threads)
        self._datas = [mujoco.MjData(model) for _ in range(self.threads)]
        self._scratch = mujoco.MjData(model)  # resets only
        nstate = mujoco.mj_stateSize(model, STATE_SPEC)
        # Full physics state layout: time, qpos, qvel, act, ... (MuJoCo's mjtState order).
        self._qpos = slice(1, 1 + self.nq)
        self._qvel = slice(1 + self.nq, 1 + self.nq + self.nv)
        self.state = np.zeros((num_envs, nstate))
        self.sensordata = np.zeros((num_envs, substeps, model.nsensordata))
        self._state_out = np.zeros((num_envs, substeps, nstate))
        self._control = np.zeros((num_envs, substeps, model.nu))
        self.model_of_env = np.zeros(num_envs, dtype=np.int64)
        self._model_list = [models[0]] * num_envs

    @property
    def qpos(self) -> np.ndarray:
        """(N, nq) view into the state."""
        return self.state[:, self._qpos]

    @property
    def qvel(self) -> np.ndarray:
        """(N, nv) view into the state."""
        return self.state[:, self._qvel]

    def set_models(self, env_ids: np.ndarray, model_ids: np.ndarray) -> None:
        """Assign pool models to envs (takes effect from the next step)."""
        self.model_of_env[env_ids] = model_ids
        self._model_list = [self.models[k] for k in self.model_of_env]

    def step(self, ctrl: np.ndarray) -> None:
        """Advance every env by ``substeps`` physics steps holding ``ctrl`` (N, nu)."""
        self._control[:] = ctrl[:, None, :]
        self._pool.rollout(self._model_list, self._datas, self.state, self._control,
                           nstep=self.substeps, state=self._state_out,
                           sensordata=self.sensordata, skip_checks=True)
        self.state[:] = self._state_out[:, -1]

    def reset_envs(self, env_ids: np.ndarray, qpos: np.ndarray, qvel: np.ndarray,
                   ctrl: np.ndarray) -> None:
        """Put envs in a new state and fill their sensordata by a forward pass.

        A per-env loop, on reset envs only: a forward pass is the only way to get the
        sensors of a state that was never stepped.
        """
        d = self._scratch
        for k, env in enumerate(env_ids):
            model = self.models[self.model_of_env[env]]
            mujoco.mj_resetData(model, d)
            d.qpos[:], d.qvel[:], d.ctrl[:] = qpos[k], qvel[k], ctrl[k]
            mujoco.mj_forward(model, d)
            mujoco.mj_getState(model, d, self.state[env], STATE_SPEC)
            self.sensordata[env, :] = d.sensordata

    def close(self) -> None:
        """Stop the thread pool."""
        self._pool.close()
