"""``csdf.Pose``: where an object is: a similarity transform ``p = s R q + t``.

``q`` is a point in the object's own frame (the frame its model is written in), ``p``
the same point in the world (scene, camera) frame; ``R`` is a rotation (orthonormal,
determinant +1), ``t`` the object's origin in the world and ``s > 0`` a uniform scale.
Distances scale with ``s``: an object whose model gives ``f(q)`` has world distance
``s f(q)``, gradient ``R grad f(q)`` and the same Lipschitz bound.

Poses compose like the maps they are: ``(a @ b).apply(q) == a.apply(b.apply(q))``, and
``a.inverse() @ a`` is the identity. Every consumer that places objects (scan, fit, the
fit overlay, scenes) takes and returns this type; ``Pose.from_matrix`` reads the 4x4
matrices users already have.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .errors import CsdfError

__all__ = ["Pose", "as_pose", "check_rotation"]

_ORTHO_TOL = 1e-6   # |R^T R - I| allowed in a given rotation
_ROW_TOL = 1e-9     # |last row - (0, 0, 0, 1)| allowed in a 4x4 matrix
_EYE3 = np.eye(3)  # compared with, never written
_EYE3.setflags(write=False)


def _vec3(v: Any, what: str) -> np.ndarray:
    try:
        a = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError):
        raise CsdfError(f"{what} must be 3 numbers") from None
    if a.shape != (3,):
        raise CsdfError(f"{what} must have shape (3,), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise CsdfError(f"{what} must be finite")
    return a


def check_rotation(R: Any, what: str) -> np.ndarray:
    """``R`` as a ``(3, 3)`` float64 rotation (orthonormal to 1e-6, determinant +1).

    Raises:
        CsdfError: naming ``what``: not an array of numbers, another shape, non-finite
            entries, or not a rotation.
    """
    try:
        a = np.asarray(R, dtype=np.float64)
    except (TypeError, ValueError):
        raise CsdfError(f"{what} must be a (3, 3) rotation matrix") from None
    if a.shape != (3, 3):
        raise CsdfError(f"{what} must have shape (3, 3), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise CsdfError(f"{what} must be finite")
    if np.max(np.abs(a.T @ a - np.eye(3))) > _ORTHO_TOL or np.linalg.det(a) < 0:
        raise CsdfError(f"{what} must be a rotation (orthonormal, determinant +1)")
    return a


class Pose:
    """A similarity transform ``p = s R q + t`` (object frame to world frame).

    Args:
        rotation: ``(3, 3)`` rotation ``R`` (default identity); checked orthonormal
            with determinant +1 to 1e-6.
        translation: ``(3,)`` ``t`` in world units (default 0).
        scale: ``s > 0`` (default 1).

    Attributes:
        rotation: ``(3, 3)`` float64 (read-only); translation: ``(3,)`` float64
            (read-only); scale: float.

    Raises:
        CsdfError: a matrix that is not a rotation, a bad shape, a non-finite value or
            a scale that is not positive.
    """

    __slots__ = ("rotation", "translation", "scale", "_identity")

    def __init__(self, rotation: Any = None, translation: Any = None, scale: float = 1.0):
        R = np.eye(3) if rotation is None else check_rotation(rotation, "rotation")
        t = np.zeros(3) if translation is None else _vec3(translation, "translation")
        try:
            s = float(scale)
        except (TypeError, ValueError):
            raise CsdfError(f"scale must be a positive number, got {scale!r}") from None
        if not (math.isfinite(s) and s > 0):
            raise CsdfError(f"scale must be a positive finite number, got {s}")
        R = np.array(R, dtype=np.float64)
        t = np.array(t, dtype=np.float64)
        R.setflags(write=False)
        t.setflags(write=False)
        object.__setattr__(self, "rotation", R)
        object.__setattr__(self, "translation", t)
        object.__setattr__(self, "scale", s)
        # the exact identity test, asked on every evaluation of a field (the arrays
        # are read-only, so it cannot change)
        object.__setattr__(self, "_identity", bool(
            s == 1.0 and (R == _EYE3).all() and not (t != 0.0).any()))

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError("a Pose is immutable; make a new one")

    # ------------------------------------------------------------------ construction
    @classmethod
    def identity(cls) -> Pose:
        """The identity pose."""
        return cls()

    @classmethod
    def from_matrix(cls, T: Any, what: str = "pose", *, rigid: bool = False) -> Pose:
        """A pose from a ``(4, 4)`` matrix ``[[s R, t], [0, 0, 0, 1]]``.

        Args:
            T: the matrix (any array-like of numbers).
            what: the argument's name, for error messages.
            rigid: require ``s = 1`` (a rigid transform).

        Raises:
            CsdfError: a bad shape, non-finite entries, a last row that is not
                ``(0, 0, 0, 1)``, or a 3x3 block that is not a (scaled) rotation.
        """
        kind = "rigid" if rigid else "similarity"
        try:
            M = np.asarray(T, dtype=np.float64)
        except (TypeError, ValueError):
            raise CsdfError(f"{what} must be a (4, 4) {kind} transform") from None
        if M.shape != (4, 4):
            raise CsdfError(f"{what} must have shape (4, 4), got {M.shape}")
        if not np.all(np.isfinite(M)):
            raise CsdfError(f"{what} must be finite")
        if np.max(np.abs(M[3] - [0.0, 0.0, 0.0, 1.0])) > _ROW_TOL:
            raise CsdfError(f"{what}'s last row must be (0, 0, 0, 1)")
        A = M[:3, :3]
        s = 1.0 if rigid else float(np.cbrt(np.linalg.det(A)))
        if not s > 0:
            raise CsdfError(f"{what} must have a positive determinant (a similarity "
                            "transform: a scaled rotation)")
        R = A / s
        if np.max(np.abs(R.T @ R - np.eye(3))) > _ORTHO_TOL or np.linalg.det(R) < 0:
            if rigid:
                raise CsdfError(f"{what} must be rigid: its 3x3 block must be a rotation "
                                "(orthonormal, determinant +1)")
            raise CsdfError(f"{what} must be a similarity: its 3x3 block must be a "
                            "uniformly scaled rotation")
        return cls(R, M[:3, 3], s)

    @classmethod
    def nearest(cls, T: Any, what: str = "pose") -> Pose:
        """The similarity nearest to a ``(4, 4)`` matrix whose 3x3 block has a positive
        determinant: ``s = det(A)^(1/3)`` and ``R`` the rotation nearest to ``A / s``
        (by SVD); the last row is ignored. For initial guesses that need not be exact.

        Raises:
            CsdfError: not a finite ``(4, 4)`` array, or ``det(A) <= 0``.
        """
        try:
            M = np.asarray(T, dtype=np.float64)
        except (TypeError, ValueError):
            raise CsdfError(f"{what} must be a (4, 4) transform") from None
        if M.shape != (4, 4) or not np.all(np.isfinite(M)):
            raise CsdfError(f"{what} must be a finite (4, 4) transform")
        A = M[:3, :3]
        s = float(np.cbrt(np.linalg.det(A)))
        if not s > 0:
            raise CsdfError(f"{what} must have a positive determinant")
        U, _, Vt = np.linalg.svd(A / s)
        return cls(U @ Vt, M[:3, 3], s)

    @classmethod
    def from_rotvec(cls, rotvec: Any, translation: Any = None, scale: float = 1.0) -> Pose:
        """A pose from a rotation vector (axis times angle in radians, Rodrigues)."""
        w = _vec3(rotvec, "rotvec")
        th = float(np.linalg.norm(w))
        K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
        if th < 1e-12:
            R = np.eye(3) + K
            U, _, Vt = np.linalg.svd(R)
            R = U @ Vt
        else:
            K = K / th
            R = np.eye(3) + math.sin(th) * K + (1.0 - math.cos(th)) * (K @ K)
        return cls(R, translation, scale)

    # ------------------------------------------------------------------ views
    @property
    def matrix(self) -> np.ndarray:
        """``(4, 4)`` float64 ``[[s R, t], [0, 0, 0, 1]]`` (a new array)."""
        T = np.eye(4)
        T[:3, :3] = self.scale * self.rotation
        T[:3, 3] = self.translation
        return T

    def is_identity(self, tol: float = 0.0) -> bool:
        """True when this is the identity to ``tol`` (exactly, by default)."""
        if tol == 0.0:
            return self._identity  # (made when the pose was: fields ask on every call)
        return bool(np.max(np.abs(self.rotation - np.eye(3))) <= tol
                    and np.max(np.abs(self.translation)) <= tol
                    and abs(self.scale - 1.0) <= tol)

    # ------------------------------------------------------------------ algebra
    def compose(self, other: Pose) -> Pose:
        """``self ∘ other``: first ``other``, then ``self`` (``self @ other``)."""
        if not isinstance(other, Pose):
            raise CsdfError(f"can only compose a Pose with a Pose, got {type(other).__name__}")
        return Pose(self.rotation @ other.rotation,
                    self.scale * (self.rotation @ other.translation) + self.translation,
                    self.scale * other.scale)

    def __matmul__(self, other: Pose) -> Pose:
        return self.compose(other)

    def inverse(self) -> Pose:
        """The world-to-object map ``q = R^T (p - t) / s``."""
        Rt = self.rotation.T
        return Pose(Rt, -(Rt @ self.translation) / self.scale, 1.0 / self.scale)

    # ------------------------------------------------------------------ application
    def apply(self, points: Any) -> np.ndarray:
        """Object-frame points ``(..., 3)`` to world points ``s R q + t`` (float64)."""
        q = np.asarray(points, dtype=np.float64)
        return self.scale * (q @ self.rotation.T) + self.translation

    def apply_inverse(self, points: Any) -> np.ndarray:
        """World points ``(..., 3)`` to object-frame points ``R^T (p - t) / s``."""
        p = np.asarray(points, dtype=np.float64)
        return ((p - self.translation) @ self.rotation) / self.scale

    def apply_dirs(self, dirs: Any) -> np.ndarray:
        """Object-frame directions ``(..., 3)`` to world directions ``R d`` (unit
        vectors stay unit: the scale does not apply to directions)."""
        return np.asarray(dirs, dtype=np.float64) @ self.rotation.T

    def apply_inverse_dirs(self, dirs: Any) -> np.ndarray:
        """World directions ``(..., 3)`` to object-frame directions ``R^T d``."""
        return np.asarray(dirs, dtype=np.float64) @ self.rotation

    def apply_box(self, box: Any) -> np.ndarray:
        """The world-frame axis-aligned box ``(2, 3)`` that holds the image of an
        object-frame box ``(2, 3)`` (its 8 corners mapped; conservative)."""
        b = np.asarray(box, dtype=np.float64).reshape(2, 3)
        corners = np.array([[b[i, 0], b[j, 1], b[k, 2]]
                            for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        w = self.apply(corners)
        return np.array([w.min(0), w.max(0)])

    # ------------------------------------------------------------------ comparison
    def allclose(self, other: Pose, atol: float = 1e-9) -> bool:
        """Equal to ``other`` within ``atol`` in every entry of the 4x4 matrix."""
        return bool(np.allclose(self.matrix, other.matrix, rtol=0.0, atol=atol))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Pose):
            return NotImplemented
        return bool(np.array_equal(self.rotation, other.rotation)
                    and np.array_equal(self.translation, other.translation)
                    and self.scale == other.scale)

    def __hash__(self) -> int:
        return hash((self.rotation.tobytes(), self.translation.tobytes(), self.scale))

    def __repr__(self) -> str:
        t = ", ".join(f"{v:.6g}" for v in self.translation)
        ang = math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(self.rotation) - 1) / 2))))
        return f"Pose(translation=({t}), rotation={ang:.4g} deg, scale={self.scale:.6g})"

    def __reduce__(self):
        return (Pose, (np.array(self.rotation), np.array(self.translation), self.scale))


def as_pose(pose: Any, what: str = "pose", *, rigid: bool = False) -> Pose:
    """A :class:`Pose` from ``None`` (identity), a Pose, or a ``(4, 4)`` matrix.

    Raises:
        CsdfError: anything else, or a matrix that is not a (rigid, with ``rigid``)
            similarity transform; a Pose with ``s != 1`` when ``rigid``.
    """
    if pose is None:
        return Pose()
    if isinstance(pose, Pose):
        if rigid and pose.scale != 1.0:
            raise CsdfError(f"{what} must be rigid (scale 1), got scale {pose.scale:g}")
        return pose
    return Pose.from_matrix(pose, what, rigid=rigid)
