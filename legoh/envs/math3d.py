"""Batched rotations for (N, ...) arrays of MuJoCo quaternions (w, x, y, z)."""

import numpy as np


def quat_to_mat(q: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions -> (..., 3, 3) rotation matrices (body to world)."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def world_to_body(rot: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Express world vectors (N, 3) in the body frame given body-to-world rotations (N, 3, 3)."""
    return np.einsum("nji,nj->ni", rot, v)


def roll_pitch_yaw(rot: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ZYX Euler angles (rad) of rotation matrices (N, 3, 3)."""
    roll = np.arctan2(rot[:, 2, 1], rot[:, 2, 2])
    pitch = np.arcsin(np.clip(-rot[:, 2, 0], -1.0, 1.0))
    yaw = np.arctan2(rot[:, 1, 0], rot[:, 0, 0])
    return roll, pitch, yaw


def to_yaw_frame(xy: np.ndarray, origin: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """World points (N, ..., 2) relative to ``origin`` (N, 2), rotated by -yaw (N,)."""
    d = xy - origin.reshape(origin.shape[0], *([1] * (xy.ndim - 2)), 2)
    c = np.cos(yaw).reshape(-1, *([1] * (xy.ndim - 2)))
    s = np.sin(yaw).reshape(-1, *([1] * (xy.ndim - 2)))
    return np.stack([c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1]], -1)


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Angles wrapped to [-pi, pi)."""
    return (a + np.pi) % (2 * np.pi) - np.pi
