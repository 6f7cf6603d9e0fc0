"""Egocentric depth by ray casting (``mj_multiRay``): no GL context, batched over envs.

The renderer alternative (MuJoCo's EGL ``Renderer``) is measured against this one in
``experiments/bench.py env``. This ray caster is the exact reference
(``env.depth.backend=multiray``) of the default ray-march, ``legoh.envs.heightmap_depth``
(docs/env.md gives the figures).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import mujoco
import numpy as np

from legoh.envs.robots import CAMERA_NAME, ROBOT_GEOM_GROUP

# Ray casts see every geom group but visual meshes (2) and the robot's own colliders.
WORLD_GROUPS = np.array([g not in (2, ROBOT_GEOM_GROUP) for g in range(6)], dtype=np.uint8)


def camera_ray_directions(fovy_deg: float, width: int, height: int) -> np.ndarray:
    """Unit ray directions through each pixel centre, in the camera frame.

    MuJoCo cameras look along their -z axis with +y up and +x right. Returns (height, width, 3),
    row 0 at the top of the image.
    """
    half_h = np.tan(np.deg2rad(fovy_deg) / 2.0)
    half_w = half_h * width / height
    u = (np.arange(width) + 0.5) / width * 2.0 - 1.0  # -1 left .. 1 right
    v = 1.0 - (np.arange(height) + 0.5) / height * 2.0  # 1 top .. -1 bottom
    x = np.broadcast_to(u[None, :] * half_w, (height, width))
    y = np.broadcast_to(v[:, None] * half_h, (height, width))
    dirs = np.stack([x, y, -np.ones_like(x)], axis=-1)
    return dirs / np.linalg.norm(dirs, axis=-1, keepdims=True)


def camera_poses(model: mujoco.MjModel, qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World position (k, 3) and rotation (k, 3, 3) of the depth camera at each of the k
    poses ``qpos`` (k, nq): kinematics only, for tests and benchmarks of the ray casters."""
    data, cam = mujoco.MjData(model), model.camera(CAMERA_NAME).id
    pos, mat = [], []
    for q in qpos:
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        mujoco.mj_camlight(model, data)
        pos.append(data.cam_xpos[cam].copy())
        mat.append(data.cam_xmat[cam].reshape(3, 3).copy())
    return np.array(pos), np.array(mat)


class DepthRaycaster:
    """Planar depth images (along the optical axis, metres, clipped to ``far``) for many
    camera poses against one world, cast in parallel threads (MuJoCo releases the GIL).

    The world is read from ``data``: static geoms only need one forward pass. The robot's own
    colliders (group ``ROBOT_GEOM_GROUP``) and visual meshes are never hit.
    """

    def __init__(self, model: mujoco.MjModel, fovy_deg: float, width: int, height: int,
                 far: float, threads: int = 0) -> None:
        self.model, self.width, self.height, self.far = model, width, height, far
        dirs = camera_ray_directions(fovy_deg, width, height).reshape(-1, 3)
        self._dirs = dirs
        self._cos = -dirs[:, 2]  # ray length -> planar depth
        # Geoms beyond the longest ray (the image corner at the far plane) are never tested.
        self._cutoff_scale = 1.0 / float(self._cos.min())
        self.threads = threads or os.cpu_count() or 1
        self._pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None
        # mj_multiRay allocates its scratch on the MjData's stack: threads sharing one MjData
        # corrupt each other's rays (measured: identical runs gave depths 0.49 apart). Each
        # thread casts against its own MjData, kept at the caller's pose (positions).
        self._scratch = [mujoco.MjData(model) for _ in range(self.threads)]
        for world in self._scratch:
            mujoco.mj_forward(model, world)

    def render(self, data: mujoco.MjData, cam_pos: np.ndarray, cam_mat: np.ndarray
               ) -> np.ndarray:
        """Depth (N, height, width) for camera positions (N, 3) and rotations (N, 3, 3)."""
        n, nray = len(cam_pos), len(self._dirs)
        vec = np.einsum("rj,nij->nri", self._dirs, cam_mat).reshape(n, -1)
        dist = np.empty((n, nray))

        def cast(k: int) -> None:
            world = self._scratch[k]
            if not np.array_equal(world.qpos, data.qpos):  # the world moved: follow it
                world.qpos[:] = data.qpos
                mujoco.mj_forward(self.model, world)
            geomid = np.empty(nray, dtype=np.int32)
            for i in range(k, n, self.threads):
                mujoco.mj_multiRay(self.model, world, cam_pos[i], vec[i], WORLD_GROUPS, True,
                                   -1, geomid, dist[i], None, nray, self.far * self._cutoff_scale)

        if self._pool is None:
            cast(0)
        else:
            list(self._pool.map(cast, range(self.threads)))
        dist[dist < 0] = np.inf  # a miss
        return np.minimum(dist * self._cos, self.far).reshape(n, self.height, self.width)

    def render_camera(self, data: mujoco.MjData, camera: str) -> np.ndarray:
        """Depth (height, width) from a named camera of a forwarded ``data``."""
        cam = self.model.camera(camera).id
        return self.render(data, data.cam_xpos[cam][None],
                           data.cam_xmat[cam].reshape(1, 3, 3))[0]
