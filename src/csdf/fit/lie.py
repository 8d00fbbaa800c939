"""SO(3) helpers: the exponential map, its left Jacobian, and rotation sets."""

from __future__ import annotations

import numpy as np

__all__ = ["hat", "exp_so3", "left_jacobian", "log_so3", "cube_rotations", "sphere_rotations",
           "rotation_angle"]


def hat(w: np.ndarray) -> np.ndarray:
    """Skew matrix ``[w]x`` (3, 3) with ``[w]x v = w x v``."""
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def exp_so3(w: np.ndarray) -> np.ndarray:
    """Rotation matrix ``exp([w]x)`` (Rodrigues) of a rotation vector ``w`` (3,), radians."""
    th = float(np.linalg.norm(w))
    K = hat(w)
    if th < 1e-8:
        return np.eye(3) + K + 0.5 * K @ K
    return np.eye(3) + np.sin(th) / th * K + (1 - np.cos(th)) / th**2 * K @ K


def left_jacobian(w: np.ndarray) -> np.ndarray:
    """Left Jacobian ``J_l(w)`` of SO(3): ``exp(w + dw) = exp(J_l(w) dw) exp(w)`` to first
    order."""
    th = float(np.linalg.norm(w))
    K = hat(w)
    if th < 1e-6:
        return np.eye(3) + 0.5 * K + K @ K / 6.0
    return (np.eye(3) + (1 - np.cos(th)) / th**2 * K
            + (th - np.sin(th)) / th**3 * K @ K)


def log_so3(R: np.ndarray) -> np.ndarray:
    """Rotation vector (3,) of a rotation matrix (inverse of :func:`exp_so3`)."""
    c = np.clip((np.trace(R) - 1) / 2, -1.0, 1.0)
    th = float(np.arccos(c))
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if th < 1e-8:
        return 0.5 * v
    if np.pi - th < 1e-6:  # near a half turn: axis from the symmetric part
        M = (R + np.eye(3)) / 2
        axis = M[np.argmax(np.diag(M))]
        axis = axis / np.linalg.norm(axis)
        return th * axis
    return th / (2 * np.sin(th)) * v


def rotation_angle(R1: np.ndarray, R2: np.ndarray) -> float:
    """Angle (radians) of ``R1^T R2``."""
    c = (np.trace(R1.T @ R2) - 1) / 2
    return float(np.arccos(np.clip(c, -1.0, 1.0)))


def cube_rotations() -> np.ndarray:
    """The 24 rotations of the cube group, ``(24, 3, 3)``."""
    out = []
    for perm in ((0, 1, 2), (1, 2, 0), (2, 0, 1), (0, 2, 1), (2, 1, 0), (1, 0, 2)):
        for signs in np.ndindex(2, 2, 2):
            R = np.zeros((3, 3))
            for i, j in enumerate(perm):
                R[i, j] = 1.0 if signs[i] == 0 else -1.0
            if np.linalg.det(R) > 0:
                out.append(R)
    return np.array(out)


def sphere_rotations(n: int) -> np.ndarray:
    """``n`` rotations spread evenly over SO(3), deterministic, ``(n, 3, 3)``.

    Unit quaternions from a Fibonacci-like low-discrepancy sequence on S^3 (the angles
    use irrational steps), mapped to matrices.
    """
    i = np.arange(n) + 0.5
    s = i / n
    phi1 = 2 * np.pi * i * 0.7548776662466927  # plastic-number based steps
    phi2 = 2 * np.pi * i * 0.5698402909980532
    r1, r2 = np.sqrt(1 - s), np.sqrt(s)
    q = np.stack([r1 * np.sin(phi1), r1 * np.cos(phi1), r2 * np.sin(phi2), r2 * np.cos(phi2)],
                 axis=1)
    x, y, z, w = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=1),
    ], axis=1)
