"""Egocentric depth by ray casting from a MuJoCo camera (``mj_multiRay``): no GL context needed."""

from __future__ import annotations

import mujoco
import numpy as np

from legoh.envs.robots import ROBOT_GEOM_GROUP

# Ray casts see every geom group but the robot's own colliders.
WORLD_GROUPS = np.array([g not in (2, ROBOT_GEOM_GROUP) for g in range(6)], dtype=np.uint8)


def camera_ray_directions(fovy_deg: float, width: int, height: int) -> np.ndarray:
    """Unit ray directions through each pixel centre, in the camera frame.

    MuJoCo cameras look along their -z axis with +y up and +x right. Returns (height, width, 3),
    row 0 at the top of the image. Depth is measured along -z (planar depth, like a depth camera).
    """
    half_h = np.tan(np.deg2rad(fovy_deg) / 2.0)
    half_w = half_h * width / height
    u = (np.arange(width) + 0.5) / width * 2.0 - 1.0  # -1 left .. 1 right
    v = 1.0 - (np.arange(height) + 0.5) / height * 2.0  # 1 top .. -1 bottom
    x = np.broadcast_to(u[None, :] * half_w, (height, width))
    y = np.broadcast_to(v[:, None] * half_h, (height, width))
    dirs = np.stack([x, y, -np.ones_like(x)], axis=-1)
    return dirs / np.linalg.norm(dirs, axis=-1, keepdims=True)


class RayDepthCamera:
    """Planar depth image from a named camera by ``mj_multiRay``.

    The robot's own colliders (geom group ``ROBOT_GEOM_GROUP``) and visual meshes (group 2,
    present only in render builds) are skipped: the camera sees the world, not its own head.
    """

    def __init__(self, model: mujoco.MjModel, camera: str, width: int, height: int,
                 far: float) -> None:
        cam = model.camera(camera)
        self.cam_id = cam.id
        self.width, self.height, self.far = width, height, far
        self._dirs_cam = camera_ray_directions(float(model.cam_fovy[cam.id]), width, height)
        self._cos = -self._dirs_cam[..., 2]  # ray length -> planar depth
        n = width * height
        self._geomid = np.zeros(n, dtype=np.int32)
        self._dist = np.zeros(n, dtype=np.float64)

    def render(self, model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
        """Depth image (height, width) in metres, clipped to ``far``; misses read ``far``."""
        rot = data.cam_xmat[self.cam_id].reshape(3, 3)
        vec = (self._dirs_cam.reshape(-1, 3) @ rot.T).ravel()
        mujoco.mj_multiRay(model, data, data.cam_xpos[self.cam_id], vec, WORLD_GROUPS, True,
                           -1, self._geomid, self._dist, None,
                           self.width * self.height, self.far * 2.0)
        dist = np.where(self._dist < 0, np.inf, self._dist).reshape(self.height, self.width)
        return np.minimum(dist * self._cos, self.far)
