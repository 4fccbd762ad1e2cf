"""Attitude representations and frame conversions.

Conventions (docs/conventions.md):

- navigation frame l = ENU, body frame b = right-forward-up (RFU);
- ``C`` (or ``C_b^l``) rotates body vectors into ENU: ``v^l = C v^b``;
- Euler angles ``roll r, pitch p, heading A`` (heading clockwise from north) with
  ``C_b^l = Rz(-A) Rx(p) Ry(r)`` (Noureldin et al. 2013, ch. 2), where ``Rx, Ry, Rz`` are the active
  (right-handed, counter-clockwise) elementary rotations;
- quaternions are scalar-last ``(x, y, z, w)`` as in scipy;
- rotation vectors: ``C = exp([phi x])`` (Rodrigues).

All public functions are vectorised over leading axes: Euler angles may be arrays of shape
``(N,)`` and DCMs then have shape ``(N, 3, 3)``.

The NED / FRD convention of KF-GINS and pyins (yaw-pitch-roll, ``C_b^n = R3(-y) R2(-p) R1(-r)``
as an active rotation) relates to ours by the same permutation matrix ``P`` for both frames
(ENU <-> NED and RFU <-> FRD): ``C_frd^ned = P C_rfu^enu P``; the Euler angles coincide:
roll = roll, pitch = pitch, yaw = heading.
"""

from __future__ import annotations

import numpy as np

from .jit import njit

#: ENU <-> NED and RFU <-> FRD axis permutation (symmetric, its own inverse)
P_SWAP = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def _arr(x) -> np.ndarray:
    return np.asarray(x, dtype=float)


def Rx(theta) -> np.ndarray:
    """Active rotation about x by ``theta`` [rad] (vectorised)."""
    t = _arr(theta)
    c, s = np.cos(t), np.sin(t)
    o, z = np.ones_like(t), np.zeros_like(t)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2)


def Ry(theta) -> np.ndarray:
    """Active rotation about y by ``theta`` [rad] (vectorised)."""
    t = _arr(theta)
    c, s = np.cos(t), np.sin(t)
    o, z = np.ones_like(t), np.zeros_like(t)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2)


def Rz(theta) -> np.ndarray:
    """Active rotation about z by ``theta`` [rad] (vectorised)."""
    t = _arr(theta)
    c, s = np.cos(t), np.sin(t)
    o, z = np.ones_like(t), np.zeros_like(t)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def skew(v) -> np.ndarray:
    """Skew-symmetric cross-product matrix ``[v x]`` (vectorised over leading axes)."""
    v = _arr(v)
    z = np.zeros_like(v[..., 0])
    return np.stack(
        [
            np.stack([z, -v[..., 2], v[..., 1]], -1),
            np.stack([v[..., 2], z, -v[..., 0]], -1),
            np.stack([-v[..., 1], v[..., 0], z], -1),
        ],
        -2,
    )


def euler_to_dcm(roll, pitch, heading) -> np.ndarray:
    """``C_b^l = Rz(-A) Rx(p) Ry(r)`` from roll, pitch, heading [rad]."""
    sr, cr = np.sin(_arr(roll)), np.cos(_arr(roll))
    sp, cp = np.sin(_arr(pitch)), np.cos(_arr(pitch))
    sa, ca = np.sin(_arr(heading)), np.cos(_arr(heading))
    sr, cr, sp, cp, sa, ca = np.broadcast_arrays(sr, cr, sp, cp, sa, ca)
    C = np.empty(sr.shape + (3, 3))
    C[..., 0, 0] = ca * cr + sa * sp * sr
    C[..., 0, 1] = sa * cp
    C[..., 0, 2] = ca * sr - sa * sp * cr
    C[..., 1, 0] = -sa * cr + ca * sp * sr
    C[..., 1, 1] = ca * cp
    C[..., 1, 2] = -sa * sr - ca * sp * cr
    C[..., 2, 0] = -cp * sr
    C[..., 2, 1] = sp
    C[..., 2, 2] = cp * cr
    return C


@njit(cache=True)
def euler_to_dcm_nb(roll, pitch, heading, C):
    """Compiled :func:`euler_to_dcm` for one attitude, written into ``C`` (3x3)."""
    sr, cr = np.sin(roll), np.cos(roll)
    sp, cp = np.sin(pitch), np.cos(pitch)
    sa, ca = np.sin(heading), np.cos(heading)
    C[0, 0] = ca * cr + sa * sp * sr
    C[0, 1] = sa * cp
    C[0, 2] = ca * sr - sa * sp * cr
    C[1, 0] = -sa * cr + ca * sp * sr
    C[1, 1] = ca * cp
    C[1, 2] = -sa * sr - ca * sp * cr
    C[2, 0] = -cp * sr
    C[2, 1] = sp
    C[2, 2] = cp * cr


def dcm_to_euler(C) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Roll, pitch, heading [rad] from ``C_b^l`` (the inverse of :func:`euler_to_dcm`).

    Heading is wrapped to [0, 2 pi); roll to (-pi, pi]; pitch to [-pi/2, pi/2].
    """
    C = _arr(C)
    roll = np.arctan2(-C[..., 2, 0], C[..., 2, 2])
    pitch = np.arctan2(C[..., 2, 1], np.hypot(C[..., 0, 1], C[..., 1, 1]))
    heading = np.mod(np.arctan2(C[..., 0, 1], C[..., 1, 1]), 2.0 * np.pi)
    return roll, pitch, heading


@njit(cache=True)
def dcm_to_euler_nb(C):
    """Compiled single-matrix version of :func:`dcm_to_euler`."""
    roll = np.arctan2(-C[2, 0], C[2, 2])
    pitch = np.arctan2(C[2, 1], np.sqrt(C[0, 1] ** 2 + C[1, 1] ** 2))
    heading = np.arctan2(C[0, 1], C[1, 1])
    if heading < 0.0:
        heading += 2.0 * np.pi
    return roll, pitch, heading


def dcm_to_quat(C) -> np.ndarray:
    """Unit quaternion (x, y, z, w) from a DCM (Shepperd's method, robust for any angle)."""
    C = _arr(C)
    shape = C.shape[:-2]
    C = C.reshape(-1, 3, 3)
    tr = np.trace(C, axis1=1, axis2=2)
    cand = np.stack([C[:, 0, 0], C[:, 1, 1], C[:, 2, 2], tr], -1)
    k = np.argmax(cand, axis=1)
    q = np.empty((C.shape[0], 4))
    for i in range(4):  # four branches, vectorised over the samples of each branch
        m = k == i
        if not np.any(m):
            continue
        c = C[m]
        if i == 3:
            w = 0.5 * np.sqrt(1.0 + tr[m])
            q[m] = np.stack(
                [(c[:, 2, 1] - c[:, 1, 2]) / (4 * w), (c[:, 0, 2] - c[:, 2, 0]) / (4 * w),
                 (c[:, 1, 0] - c[:, 0, 1]) / (4 * w), w], -1)
        else:
            j, l = (i + 1) % 3, (i + 2) % 3
            qi = 0.5 * np.sqrt(1.0 + 2.0 * c[:, i, i] - tr[m])
            out = np.empty((c.shape[0], 4))
            out[:, i] = qi
            out[:, j] = (c[:, j, i] + c[:, i, j]) / (4 * qi)
            out[:, l] = (c[:, l, i] + c[:, i, l]) / (4 * qi)
            out[:, 3] = (c[:, l, j] - c[:, j, l]) / (4 * qi)
            q[m] = out
    q *= np.where(q[:, 3:4] < 0, -1.0, 1.0)
    return q.reshape(shape + (4,))


def quat_to_dcm(q) -> np.ndarray:
    """DCM from a quaternion (x, y, z, w); the quaternion is normalised first."""
    q = _arr(q)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    C = np.empty(q.shape[:-1] + (3, 3))
    C[..., 0, 0] = x * x - y * y - z * z + w * w
    C[..., 0, 1] = 2 * (x * y - z * w)
    C[..., 0, 2] = 2 * (x * z + y * w)
    C[..., 1, 0] = 2 * (x * y + z * w)
    C[..., 1, 1] = -x * x + y * y - z * z + w * w
    C[..., 1, 2] = 2 * (y * z - x * w)
    C[..., 2, 0] = 2 * (x * z - y * w)
    C[..., 2, 1] = 2 * (y * z + x * w)
    C[..., 2, 2] = -x * x - y * y + z * z + w * w
    return C


def rotvec_to_dcm(phi) -> np.ndarray:
    """Rodrigues: ``exp([phi x]) = I + sin|phi|/|phi| [phi x] + (1-cos|phi|)/|phi|^2 [phi x]^2``."""
    phi = _arr(phi)
    a = np.linalg.norm(phi, axis=-1)[..., None, None]
    small = a < 1e-8
    a_safe = np.where(small, 1.0, a)
    s = np.where(small, 1.0 - a * a / 6.0, np.sin(a_safe) / a_safe)
    # (1 - cos a) / a^2 written as 2 sin^2(a/2) / a^2: no cancellation for small angles
    c = np.where(small, 0.5 - a * a / 24.0, 2.0 * (np.sin(0.5 * a_safe) / a_safe) ** 2)
    K = skew(phi)
    return np.eye(3) + s * K + c * (K @ K)


@njit(cache=True, inline="always")
def rotvec_xyz_to_dcm_nb(x, y, z, out):
    """Compiled Rodrigues formula for the rotation vector ``(x, y, z)``, written into ``out``."""
    a2 = x * x + y * y + z * z
    if a2 < 1e-16:
        s = 1.0 - a2 / 6.0
        c = 0.5 - a2 / 24.0
    else:
        a = np.sqrt(a2)
        s = np.sin(a) / a
        sh = np.sin(0.5 * a)
        c = 2.0 * sh * sh / a2  # = (1 - cos a) / a^2 without cancellation
    out[0, 0] = 1.0 - c * (y * y + z * z)
    out[0, 1] = -s * z + c * x * y
    out[0, 2] = s * y + c * x * z
    out[1, 0] = s * z + c * x * y
    out[1, 1] = 1.0 - c * (x * x + z * z)
    out[1, 2] = -s * x + c * y * z
    out[2, 0] = -s * y + c * x * z
    out[2, 1] = s * x + c * y * z
    out[2, 2] = 1.0 - c * (x * x + y * y)


@njit(cache=True)
def rotvec_to_dcm_nb(phi, out):
    """Compiled Rodrigues formula for one rotation vector, written into ``out`` (3x3)."""
    rotvec_xyz_to_dcm_nb(phi[0], phi[1], phi[2], out)


def dcm_to_rotvec(C) -> np.ndarray:
    """Rotation vector (log map) of a DCM, via the quaternion (stable for all angles < pi)."""
    q = dcm_to_quat(C)
    v = q[..., :3]
    sn = np.linalg.norm(v, axis=-1)
    ang = 2.0 * np.arctan2(sn, q[..., 3])
    small = sn < 1e-12
    k = np.where(small, 2.0 / np.where(small, q[..., 3], 1.0), ang / np.where(small, 1.0, sn))
    return v * k[..., None]


def orthonormalize(C) -> np.ndarray:
    """Nearest orthonormal matrix (polar decomposition via SVD)."""
    U, _, Vt = np.linalg.svd(_arr(C))
    return U @ Vt


def enu_to_ned(v) -> np.ndarray:
    """Swap a vector (or stack of vectors, last axis 3) between ENU and NED (and RFU/FRD)."""
    v = _arr(v)
    return np.stack([v[..., 1], v[..., 0], -v[..., 2]], -1)


ned_to_enu = enu_to_ned
rfu_to_frd = enu_to_ned
frd_to_rfu = enu_to_ned


def dcm_enu_rfu_to_ned_frd(C) -> np.ndarray:
    """``C_frd^ned = P C_rfu^enu P`` (and back: the same function)."""
    return P_SWAP @ _arr(C) @ P_SWAP


def euler_to_ned(roll, pitch, heading):
    """insgnss (ENU/RFU) Euler angles to NED/FRD roll, pitch, yaw (KF-GINS, pyins).

    The three angles coincide numerically (see module docstring); yaw is wrapped to
    (-pi, pi]. This function exists so that the conversion is explicit and tested.
    """
    yaw = np.mod(_arr(heading) + np.pi, 2 * np.pi) - np.pi
    return _arr(roll).copy(), _arr(pitch).copy(), yaw


def euler_from_ned(roll, pitch, yaw):
    """NED/FRD roll, pitch, yaw to insgnss roll, pitch, heading in [0, 2 pi)."""
    return _arr(roll).copy(), _arr(pitch).copy(), np.mod(_arr(yaw), 2 * np.pi)


def wrap_pi(a):
    """Wrap angles to (-pi, pi]."""
    return -(np.mod(-_arr(a) + np.pi, 2 * np.pi) - np.pi)


def attitude_error(C_est, C_true) -> np.ndarray:
    """Small-angle misalignment ``phi`` in the l-frame with ``C_est = exp([phi x]) C_true``."""
    return dcm_to_rotvec(_arr(C_est) @ np.swapaxes(_arr(C_true), -1, -2))
