"""Every frame and quaternion conversion in the engine (docs/architecture.md §10: frame
conversions live in frames.py only).

Conventions (REP 103, docs/architecture.md §3):

- World frame ENU (x east, y north, z up); body frame FLU (x forward, y left, z up).
- Camera optical frame: z forward, x right, y down.
- NED (x north, y east, z down) and FRD (x forward, y right, z down) exist only at the MAVLink
  edge.
- Quaternions are Hamilton quaternions stored xyzw (PyBullet and scipy order). ``q_a_b`` and
  ``R_a_b`` map b-frame vectors into frame a: ``v_a = R_a_b @ v_b``. Composition therefore chains
  adjacent frames: ``q_a_c = q_a_b ⊗ q_b_c``, ``R_a_c = R_a_b @ R_b_c``.
- Euler angles are roll, pitch, yaw in the ZYX intrinsic sequence (yaw about z, then pitch about
  the new y, then roll about the newest x): ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``, the same as
  ``pybullet.getQuaternionFromEuler([roll, pitch, yaw])``.

Every function is vectorised over leading dimensions: quaternions are ``(..., 4)``, vectors
``(..., 3)``, rotation matrices ``(..., 3, 3)``, angles ``(...)``; leading dimensions broadcast.
A single ``(4,)`` quaternion gives a single ``(3, 3)`` matrix, and so on.

The matrix-to-quaternion conversion follows F. L. Markley, "Unit Quaternion from Rotation
Matrix", J. Guidance, Control, and Dynamics 31(2), 2008 (a refinement of Shepperd's 1978
method): it builds the candidate from the largest of (trace, R00, R11, R22), so it never divides
by a small number, and is accurate for every rotation including 180 degrees.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .control.compiled import jit

from unetyemu_ecs.units import wrap_angle_rad

__all__ = [
    "R_ENU_NED",
    "R_NED_ENU",
    "R_FLU_FRD",
    "R_FRD_FLU",
    "R_FLU_OPTICAL",
    "Q_NED_ENU_XYZW",
    "Q_FLU_FRD_XYZW",
    "row_norm",
    "quat_xyzw_to_wxyz",
    "quat_wxyz_to_xyzw",
    "quat_normalize_xyzw",
    "R_from_quat_xyzw",
    "quat_xyzw_from_R",
    "quat_multiply_xyzw",
    "quat_conjugate_xyzw",
    "quat_rotate_xyzw",
    "quat_xyzw_from_euler_rpy",
    "euler_rpy_from_quat_xyzw",
    "yaw_rad_from_quat_xyzw",
    "enu_to_ned",
    "ned_to_enu",
    "flu_to_frd",
    "frd_to_flu",
    "quat_enu_flu_to_ned_frd",
    "quat_ned_frd_to_enu_flu",
    "yaw_enu_to_ned_rad",
    "yaw_ned_to_enu_rad",
]

# ENU <-> NED swaps x/y and flips z; the matrix is symmetric and its own inverse.
R_ENU_NED = np.array([[0.0, 1.0, 0.0],
                      [1.0, 0.0, 0.0],
                      [0.0, 0.0, -1.0]])
R_NED_ENU = R_ENU_NED.T.copy()

# FLU <-> FRD flips y and z (a 180 degree turn about the forward axis); its own inverse.
R_FLU_FRD = np.diag([1.0, -1.0, -1.0])
R_FRD_FLU = R_FLU_FRD.T.copy()

# Columns are the optical axes written in FLU: x right = -y_flu, y down = -z_flu, z fwd = +x_flu.
R_FLU_OPTICAL = np.array([[0.0, 0.0, 1.0],
                          [-1.0, 0.0, 0.0],
                          [0.0, -1.0, 0.0]])

# The same two axis changes as quaternions: 180 degrees about (1, 1, 0)/sqrt(2) and about x.
Q_NED_ENU_XYZW = np.array([np.sqrt(0.5), np.sqrt(0.5), 0.0, 0.0])
Q_FLU_FRD_XYZW = np.array([1.0, 0.0, 0.0, 0.0])

for _R in (R_ENU_NED, R_NED_ENU, R_FLU_FRD, R_FRD_FLU, R_FLU_OPTICAL,
           Q_NED_ENU_XYZW, Q_FLU_FRD_XYZW):
    _R.setflags(write=False)
del _R


def _f64(x: ArrayLike) -> np.ndarray:
    return np.asarray(x, dtype=np.float64)


# ---------------------------------------------------------------------------------------------
# Quaternion storage order
# ---------------------------------------------------------------------------------------------

def quat_xyzw_to_wxyz(q: ArrayLike) -> np.ndarray:
    """Reorder quaternions from xyzw (engine, PyBullet) to wxyz (MAVLink, Eigen).

    Parameters
    ----------
    q : (..., 4) float, xyzw

    Returns
    -------
    (..., 4) float64, wxyz (a new array)
    """
    return _f64(q)[..., [3, 0, 1, 2]]


def quat_wxyz_to_xyzw(q: ArrayLike) -> np.ndarray:
    """Reorder quaternions from wxyz (MAVLink, Eigen) to xyzw (engine, PyBullet).

    Parameters
    ----------
    q : (..., 4) float, wxyz

    Returns
    -------
    (..., 4) float64, xyzw (a new array)
    """
    return _f64(q)[..., [1, 2, 3, 0]]


# ---------------------------------------------------------------------------------------------
# Vectors
# ---------------------------------------------------------------------------------------------

def row_norm(v: np.ndarray) -> np.ndarray:
    """Euclidean norm (N,) of each row of (N, k) vectors ``v`` (half the cost of ``np.linalg.norm(v, axis=1)``
    for a few rows)."""
    return np.sqrt(np.einsum("ij,ij->i", v, v))


# ---------------------------------------------------------------------------------------------
# Quaternion algebra
# ---------------------------------------------------------------------------------------------

def quat_normalize_xyzw(q: ArrayLike) -> np.ndarray:
    """Scale quaternions to unit norm.

    Parameters
    ----------
    q : (..., 4) float, xyzw, non-zero

    Returns
    -------
    (..., 4) float64, xyzw, unit norm
    """
    q = _f64(q)
    return q / np.sqrt(np.einsum("...i,...i->...", q, q))[..., None]


def R_from_quat_xyzw(q: ArrayLike) -> np.ndarray:
    """Convert quaternions ``q_a_b`` to rotation matrices ``R_a_b``.

    The input is normalised first, so slightly drifted quaternions still give orthonormal
    matrices.

    Parameters
    ----------
    q : (..., 4) float, xyzw

    Returns
    -------
    (..., 3, 3) float64, with ``v_a = R @ v_b``
    """
    q = _f64(q)
    return _R_from_quats_xyzw(np.ascontiguousarray(q.reshape(-1, 4))).reshape(q.shape[:-1] + (3, 3))


@jit
def _unit_quat_xyzw(q):
    """The components of ``q`` (4,) xyzw scaled to unit norm, as :func:`quat_normalize_xyzw` computes them."""
    n = np.sqrt((q[0] * q[0] + q[2] * q[2]) + (q[1] * q[1] + q[3] * q[3]))    # summed in its einsum's order
    return q[0] / n, q[1] / n, q[2] / n, q[3] / n


@jit
def set_R_from_quat_xyzw(q, R):
    """Write into ``R`` (3, 3) the rotation matrix of the quaternion ``q`` (4,) xyzw, normalised first: the
    textbook formulas (:func:`R_from_quat_xyzw` for arrays; kernels call this one)."""
    x, y, z, w = _unit_quat_xyzw(q)
    R[0, 0] = 1.0 - 2.0 * (y * y + z * z)
    R[0, 1] = 2.0 * (x * y - w * z)
    R[0, 2] = 2.0 * (x * z + w * y)
    R[1, 0] = 2.0 * (x * y + w * z)
    R[1, 1] = 1.0 - 2.0 * (x * x + z * z)
    R[1, 2] = 2.0 * (y * z - w * x)
    R[2, 0] = 2.0 * (x * z - w * y)
    R[2, 1] = 2.0 * (y * z + w * x)
    R[2, 2] = 1.0 - 2.0 * (x * x + y * y)


@jit
def _R_from_quats_xyzw(q):
    """(K, 3, 3) of (K, 4) quaternions xyzw."""
    R = np.empty((q.shape[0], 3, 3))
    for k in range(q.shape[0]):
        set_R_from_quat_xyzw(q[k], R[k])
    return R


def quat_xyzw_from_R(R: ArrayLike) -> np.ndarray:
    """Convert rotation matrices ``R_a_b`` to unit quaternions ``q_a_b`` (Markley 2008).

    Of the four algebraically equivalent candidates, the one built on the largest of
    (trace, R00, R11, R22) is used, so no candidate with a near-zero norm is ever normalised.
    The sign is chosen so that ``w >= 0``.

    Parameters
    ----------
    R : (..., 3, 3) float, proper rotation matrices

    Returns
    -------
    (..., 4) float64, xyzw, unit norm, w >= 0
    """
    R = _f64(R)
    r00, r01, r02 = R[..., 0, 0], R[..., 0, 1], R[..., 0, 2]
    r10, r11, r12 = R[..., 1, 0], R[..., 1, 1], R[..., 1, 2]
    r20, r21, r22 = R[..., 2, 0], R[..., 2, 1], R[..., 2, 2]
    tr = r00 + r11 + r22
    # candidates[..., k, :] is 4*q_k times the quaternion (xyzw), k = x, y, z, w.
    candidates = np.stack([
        np.stack([1.0 + 2.0 * r00 - tr, r01 + r10, r02 + r20, r21 - r12], axis=-1),
        np.stack([r01 + r10, 1.0 + 2.0 * r11 - tr, r12 + r21, r02 - r20], axis=-1),
        np.stack([r02 + r20, r12 + r21, 1.0 + 2.0 * r22 - tr, r10 - r01], axis=-1),
        np.stack([r21 - r12, r02 - r20, r10 - r01, 1.0 + tr], axis=-1),
    ], axis=-2)
    pick = np.argmax(np.stack([r00, r11, r22, tr], axis=-1), axis=-1)
    q = np.take_along_axis(candidates, pick[..., None, None], axis=-2)[..., 0, :]
    q = quat_normalize_xyzw(q)
    return np.where(q[..., 3:4] < 0.0, -q, q)


def quat_multiply_xyzw(a: ArrayLike, b: ArrayLike) -> np.ndarray:
    """Compose quaternions with the Hamilton product ``a ⊗ b``.

    ``R(a ⊗ b) = R(a) @ R(b)``, so ``q_a_c = quat_multiply_xyzw(q_a_b, q_b_c)``.

    Parameters
    ----------
    a, b : (..., 4) float, xyzw; leading dimensions broadcast

    Returns
    -------
    (..., 4) float64, xyzw
    """
    a, b = _f64(a), _f64(b)
    ax, ay, az, aw = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bx, by, bz, bw = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack([
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ], axis=-1)


def quat_conjugate_xyzw(q: ArrayLike) -> np.ndarray:
    """Conjugate quaternions; for unit quaternions this is the inverse, ``q_b_a`` from ``q_a_b``.

    Parameters
    ----------
    q : (..., 4) float, xyzw

    Returns
    -------
    (..., 4) float64, xyzw
    """
    return _f64(q) * np.array([-1.0, -1.0, -1.0, 1.0])


def quat_rotate_xyzw(q: ArrayLike, v: ArrayLike) -> np.ndarray:
    """Rotate vectors by unit quaternions: ``v_a = R(q_a_b) @ v_b``, e.g. ENU from FLU.

    Parameters
    ----------
    q : (..., 4) float, xyzw, unit norm (not re-normalised, for speed)
    v : (..., 3) float; leading dimensions broadcast with ``q``

    Returns
    -------
    (..., 3) float64
    """
    q, v = _f64(q), _f64(v)
    u, w = q[..., :3], q[..., 3:4]
    # v + 2w(u x v) + 2u x (u x v), written with t = 2 u x v to save one cross product.
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


# ---------------------------------------------------------------------------------------------
# Euler angles (ZYX intrinsic: yaw, pitch, roll)
# ---------------------------------------------------------------------------------------------

def quat_xyzw_from_euler_rpy(roll_rad: ArrayLike, pitch_rad: ArrayLike,
                             yaw_rad: ArrayLike) -> np.ndarray:
    """Build ``q = qz(yaw) ⊗ qy(pitch) ⊗ qx(roll)`` (as ``pybullet.getQuaternionFromEuler``).

    Parameters
    ----------
    roll_rad, pitch_rad, yaw_rad : (...) float [rad]; broadcast together

    Returns
    -------
    (..., 4) float64, xyzw, unit norm
    """
    hr, hp, hy = (0.5 * _f64(a) for a in (roll_rad, pitch_rad, yaw_rad))
    cr, sr = np.cos(hr), np.sin(hr)
    cp, sp = np.cos(hp), np.sin(hp)
    cy, sy = np.cos(hy), np.sin(hy)
    return np.stack(np.broadcast_arrays(
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    ), axis=-1)


def euler_rpy_from_quat_xyzw(q: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Extract ZYX roll, pitch, yaw from quaternions (inverse of ``quat_xyzw_from_euler_rpy``).

    Pitch uses ``atan2`` against the horizontal component instead of ``asin`` so it stays
    accurate near +-90 degrees; at exactly +-90 degrees (gimbal lock) roll and yaw are not
    separable and the split between them is arbitrary.

    Parameters
    ----------
    q : (..., 4) float, xyzw

    Returns
    -------
    roll_rad : (...) float64 [rad], in (-pi, pi]
    pitch_rad : (...) float64 [rad], in [-pi/2, pi/2]
    yaw_rad : (...) float64 [rad], in (-pi, pi]
    """
    q = _f64(q)
    rpy = _euler_rpy_from_quats_xyzw(np.ascontiguousarray(q.reshape(-1, 4)))
    if q.ndim == 1:
        return rpy[0, 0], rpy[0, 1], rpy[0, 2]
    return tuple(rpy[:, i].reshape(q.shape[:-1]) for i in range(3))


@jit
def euler_rpy_of_quat_xyzw(q):
    """:func:`euler_rpy_from_quat_xyzw` of one quaternion ``q`` (4,): ``(roll, pitch, yaw)`` [rad] (kernels call
    this one)."""
    x, y, z, w = _unit_quat_xyzw(q)
    r00 = 1.0 - 2.0 * (y * y + z * z)
    r10 = 2.0 * (x * y + w * z)
    r20 = 2.0 * (x * z - w * y)
    r21 = 2.0 * (y * z + w * x)
    r22 = 1.0 - 2.0 * (x * x + y * y)
    return np.arctan2(r21, r22), np.arctan2(-r20, np.hypot(r00, r10)), np.arctan2(r10, r00)


@jit
def _euler_rpy_from_quats_xyzw(q):
    """(K, 3) roll, pitch, yaw of (K, 4) quaternions xyzw."""
    out = np.empty((q.shape[0], 3))
    for k in range(q.shape[0]):
        out[k, 0], out[k, 1], out[k, 2] = euler_rpy_of_quat_xyzw(q[k])
    return out


def yaw_rad_from_quat_xyzw(q: ArrayLike) -> np.ndarray:
    """Extract the ZYX yaw (heading of the body x axis about the world z axis).

    For ``q_enu_flu`` this is 0 facing east, counter-clockwise positive (REP 103); for
    ``q_ned_frd`` it is the NED heading, 0 facing north, clockwise positive.

    Parameters
    ----------
    q : (..., 4) float, xyzw

    Returns
    -------
    (...) float64 [rad], in (-pi, pi]
    """
    q = _f64(q)
    yaw = _yaws_of_quats_xyzw(np.ascontiguousarray(q.reshape(-1, 4)))
    return yaw[0] if q.ndim == 1 else yaw.reshape(q.shape[:-1])


@jit
def yaw_of_quat_xyzw(q):
    """:func:`yaw_rad_from_quat_xyzw` of one quaternion ``q`` (4,) [rad] (kernels call this one)."""
    x, y, z, w = q[0], q[1], q[2], q[3]
    # atan2 is scale-invariant, so the un-normalised matrix entries are fine here
    xx, yy, zz, ww = x * x, y * y, z * z, w * w
    return np.arctan2(2.0 * (x * y + w * z), xx + yy + zz + ww - 2.0 * (yy + zz))


@jit
def _yaws_of_quats_xyzw(q):
    yaw = np.empty(q.shape[0])
    for k in range(q.shape[0]):
        yaw[k] = yaw_of_quat_xyzw(q[k])
    return yaw


# ---------------------------------------------------------------------------------------------
# MAVLink edge: ENU/FLU <-> NED/FRD
# ---------------------------------------------------------------------------------------------

def enu_to_ned(v_enu: ArrayLike) -> np.ndarray:
    """Express ENU vectors (positions, velocities, accelerations) in NED.

    Parameters
    ----------
    v_enu : (..., 3) float, ENU

    Returns
    -------
    (..., 3) float64, NED: (north, east, down) = (y, x, -z)
    """
    v = _f64(v_enu)
    return np.stack([v[..., 1], v[..., 0], -v[..., 2]], axis=-1)


def ned_to_enu(v_ned: ArrayLike) -> np.ndarray:
    """Express NED vectors in ENU.

    Parameters
    ----------
    v_ned : (..., 3) float, NED

    Returns
    -------
    (..., 3) float64, ENU: (east, north, up) = (y, x, -z)
    """
    v = _f64(v_ned)
    return np.stack([v[..., 1], v[..., 0], -v[..., 2]], axis=-1)


def flu_to_frd(v_flu: ArrayLike) -> np.ndarray:
    """Express FLU body vectors (rates, accelerations, forces) in FRD.

    Parameters
    ----------
    v_flu : (..., 3) float, FLU

    Returns
    -------
    (..., 3) float64, FRD: (x, -y, -z)
    """
    return _f64(v_flu) * np.array([1.0, -1.0, -1.0])


def frd_to_flu(v_frd: ArrayLike) -> np.ndarray:
    """Express FRD body vectors in FLU.

    Parameters
    ----------
    v_frd : (..., 3) float, FRD

    Returns
    -------
    (..., 3) float64, FLU: (x, -y, -z)
    """
    return _f64(v_frd) * np.array([1.0, -1.0, -1.0])


def quat_enu_flu_to_ned_frd(q_enu_flu: ArrayLike) -> np.ndarray:
    """Convert a body attitude from ``q_enu_flu`` to ``q_ned_frd`` (PX4/MAVLink convention).

    ``q_ned_frd = q_NED_ENU ⊗ q_enu_flu ⊗ q_FLU_FRD``. The result is still stored xyzw; use
    ``quat_xyzw_to_wxyz`` for MAVLink's wxyz order.

    Parameters
    ----------
    q_enu_flu : (..., 4) float, xyzw

    Returns
    -------
    (..., 4) float64, xyzw
    """
    return quat_multiply_xyzw(quat_multiply_xyzw(Q_NED_ENU_XYZW, q_enu_flu), Q_FLU_FRD_XYZW)


def quat_ned_frd_to_enu_flu(q_ned_frd: ArrayLike) -> np.ndarray:
    """Convert a body attitude from ``q_ned_frd`` to ``q_enu_flu`` (inverse of the above).

    ``q_enu_flu = q_ENU_NED ⊗ q_ned_frd ⊗ q_FRD_FLU``.

    Parameters
    ----------
    q_ned_frd : (..., 4) float, xyzw

    Returns
    -------
    (..., 4) float64, xyzw
    """
    q_enu_ned = quat_conjugate_xyzw(Q_NED_ENU_XYZW)
    q_frd_flu = quat_conjugate_xyzw(Q_FLU_FRD_XYZW)
    return quat_multiply_xyzw(quat_multiply_xyzw(q_enu_ned, q_ned_frd), q_frd_flu)


def yaw_enu_to_ned_rad(yaw_enu_rad: ArrayLike) -> np.ndarray:
    """Convert an ENU yaw (0 = east, CCW+) to a NED heading (0 = north, CW+).

    Parameters
    ----------
    yaw_enu_rad : (...) float [rad]

    Returns
    -------
    (...) float64 [rad], ``wrap(pi/2 - yaw)`` in (-pi, pi]
    """
    return wrap_angle_rad(0.5 * np.pi - _f64(yaw_enu_rad))


def yaw_ned_to_enu_rad(yaw_ned_rad: ArrayLike) -> np.ndarray:
    """Convert a NED heading (0 = north, CW+) to an ENU yaw (0 = east, CCW+).

    Parameters
    ----------
    yaw_ned_rad : (...) float [rad]

    Returns
    -------
    (...) float64 [rad], ``wrap(pi/2 - heading)`` in (-pi, pi]
    """
    return wrap_angle_rad(0.5 * np.pi - _f64(yaw_ned_rad))
