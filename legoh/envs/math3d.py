"""Batched rotations for (N, ...) torch tensors of MuJoCo quaternions (w, x, y, z)."""

import math

import torch


def quat_to_mat(q: torch.Tensor) -> torch.Tensor:
    """(..., 4) unit quaternions -> (..., 3, 3) rotation matrices (body to world)."""
    w, x, y, z = q.unbind(-1)
    xx, yy, zz, xy, xz, yz = x * x, y * y, z * z, x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    return torch.stack([
        1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy),
        2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx),
        2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy),
    ], -1).reshape(*q.shape[:-1], 3, 3)


def world_to_body(rot: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Express world vectors (N, 3) in the body frame given body-to-world rotations (N, 3, 3)."""
    return (rot * v[:, :, None]).sum(1)


def roll_pitch_yaw(rot: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """ZYX Euler angles (rad) of rotation matrices (N, 3, 3)."""
    roll = torch.atan2(rot[:, 2, 1], rot[:, 2, 2])
    pitch = torch.asin(torch.clamp(-rot[:, 2, 0], -1.0, 1.0))
    yaw = torch.atan2(rot[:, 1, 0], rot[:, 0, 0])
    return roll, pitch, yaw


def to_yaw_frame(xy: torch.Tensor, origin: torch.Tensor, yaw: torch.Tensor) -> torch.Tensor:
    """World points (N, ..., 2) relative to ``origin`` (N, 2), rotated by -yaw (N,)."""
    extra = [1] * (xy.dim() - 2)
    d = xy - origin.reshape(origin.shape[0], *extra, 2)
    c, s = torch.cos(yaw).reshape(-1, *extra), torch.sin(yaw).reshape(-1, *extra)
    dx, dy = d[..., 0], d[..., 1]
    return torch.stack([c * dx + s * dy, c * dy - s * dx], -1)


def wrap_angle(a: torch.Tensor) -> torch.Tensor:
    """Angles wrapped to [-pi, pi)."""
    return torch.remainder(a + math.pi, 2 * math.pi) - math.pi
