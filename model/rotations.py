"""Rotation helpers on numpy arrays: logarithm, quaternions, swing-twist angle.

Orientations are stored as rotation matrices and updated by ``R <- expm(psi) R`` with the spatial rotation
vector ``psi`` (the compiled Rodrigues kernel, :func:`model.elements.rotation_update_spec`); no angle set is
stored, so nothing is singular at any stroke.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["log_so3", "quaternion", "twist_angle", "twist_gradient", "skew"]


def skew(v: np.ndarray) -> np.ndarray:
    """Skew-symmetric matrices of vectors ``v`` (..., 3) -> (..., 3, 3)."""
    v = np.asarray(v, dtype=float)
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def log_so3(R: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) of rotation matrices (..., 3, 3), the inverse of the exponential map
    (Rodrigues' formula, compiled in :func:`model.elements.rotation_update_spec`) for angles below pi.

    Through the unit quaternion (Shepperd's method, vectorised: the largest of ``w, x, y, z`` is found
    first, so no division by a small number) and ``psi = 2 atan2(|v|, w) v/|v|`` with the series
    ``2 (1 + |v|^2 / 6) v`` (``|v| -> 0``, ``w -> 1``) below ``|v| = 1e-6``.
    """
    R = np.asarray(R, dtype=float)
    A = R.reshape(-1, 3, 3)
    d0, d1, d2 = A[:, 0, 0], A[:, 1, 1], A[:, 2, 2]
    tr = d0 + d1 + d2
    k = np.argmax(np.stack([tr, d0, d1, d2], axis=1), axis=1)
    q = np.empty((len(A), 4))
    s21, s02, s10 = A[:, 2, 1] - A[:, 1, 2], A[:, 0, 2] - A[:, 2, 0], A[:, 1, 0] - A[:, 0, 1]
    p10, p20, p21 = A[:, 1, 0] + A[:, 0, 1], A[:, 2, 0] + A[:, 0, 2], A[:, 2, 1] + A[:, 1, 2]
    diag = np.stack([1.0 + tr, 1.0 + 2 * d0 - tr, 1.0 + 2 * d1 - tr, 1.0 + 2 * d2 - tr], axis=1)
    big = 0.5 * np.sqrt(np.maximum(diag[np.arange(len(A)), k], 1e-300))
    f = 0.25 / big
    rows = (
        np.stack([big, s21 * f, s02 * f, s10 * f], 1),
        np.stack([s21 * f, big, p10 * f, p20 * f], 1),
        np.stack([s02 * f, p10 * f, big, p21 * f], 1),
        np.stack([s10 * f, p20 * f, p21 * f, big], 1),
    )
    for j in range(4):
        sel = k == j
        q[sel] = rows[j][sel]
    q[q[:, 0] < 0] *= -1.0
    w, v = q[:, 0], q[:, 1:]
    nv = np.sqrt(np.einsum("ij,ij->i", v, v))
    small = nv < 1e-6
    fac = np.where(small, 2.0 * (1.0 + nv * nv / 6.0), 2.0 * np.arctan2(nv, w) / np.where(small, 1.0, nv))
    return (fac[:, None] * v).reshape(R.shape[:-2] + (3,))


def quaternion(R: np.ndarray) -> tuple[float, float, float, float]:
    """Unit quaternion ``(w, x, y, z)`` of a rotation matrix (Shepperd's method, stable at any angle)."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = R.tolist()
    t = r00 + r11 + r22
    k = max(range(4), key=(t, r00, r11, r22).__getitem__)
    if k == 0:
        w = 0.5 * math.sqrt(1.0 + t)
        f = 0.25 / w
        q = (w, (r21 - r12) * f, (r02 - r20) * f, (r10 - r01) * f)
    elif k == 1:
        x = 0.5 * math.sqrt(1.0 + 2 * r00 - t)
        f = 0.25 / x
        q = ((r21 - r12) * f, x, (r10 + r01) * f, (r20 + r02) * f)
    elif k == 2:
        y = 0.5 * math.sqrt(1.0 + 2 * r11 - t)
        f = 0.25 / y
        q = ((r02 - r20) * f, (r10 + r01) * f, y, (r21 + r12) * f)
    else:
        z = 0.5 * math.sqrt(1.0 + 2 * r22 - t)
        f = 0.25 / z
        q = ((r10 - r01) * f, (r20 + r02) * f, (r21 + r12) * f, z)
    return q if q[0] >= 0 else (-q[0], -q[1], -q[2], -q[3])


def twist_angle(R: np.ndarray, axis: np.ndarray, near: float = 0.0) -> float:
    """Twist of ``R`` about ``axis`` (swing-twist decomposition), the branch closest to ``near``.

    With the quaternion ``(w, v)`` of ``R`` the twist is ``2 atan2(v . a, w)``: the rotation angle about
    ``a`` left after removing the swing about an axis perpendicular to ``a``.
    """
    w, x, y, z = quaternion(R)
    a0, a1, a2 = axis.tolist()
    th = 2.0 * math.atan2(x * a0 + y * a1 + z * a2, w)
    return th + 2 * math.pi * round((near - th) / (2 * math.pi))


def twist_gradient(R: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Gradient of :func:`twist_angle` with respect to a spatial rotation increment ``psi`` (R <- exp(psi) R).

    From ``q <- (1, psi/2) (x) q``: ``dw = -psi.v/2``, ``dv = (w psi + psi x v)/2``, hence
    ``d twist = [w (w a + v x a) + (v.a) v] . psi / (w^2 + (v.a)^2)``; equal to ``a`` when there is no swing.
    """
    w, x, y, z = quaternion(R)
    a0, a1, a2 = axis.tolist()
    va = x * a0 + y * a1 + z * a2
    d = w * w + va * va
    return (
        np.array(
            [
                w * (w * a0 + y * a2 - z * a1) + va * x,
                w * (w * a1 + z * a0 - x * a2) + va * y,
                w * (w * a2 + x * a1 - y * a0) + va * z,
            ]
        )
        / d
    )
