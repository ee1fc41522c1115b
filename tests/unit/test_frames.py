"""Frame and quaternion conversions in unetyemu_ecs.frames (and the angle helpers in units).

Tolerances: the conversions are a handful of float64 multiply-adds and trig calls on O(1)
numbers, so their rounding error is ~1e-15. ``ATOL_ROT = 1e-12`` (rad, or unitless for matrix
entries and unit vectors) leaves ~1000x headroom for that rounding and is still physically
nothing: 1e-12 rad of attitude error moves a point 1 km away by 1 nm.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from unetyemu_ecs import frames as F
from unetyemu_ecs.units import deg_to_rad, rad_to_deg, wrap_angle_rad

ATOL_ROT = 1e-12
N_RANDOM = 1000


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)


def random_unit_quats(rng: np.random.Generator, n: int) -> np.ndarray:
    """Uniformly distributed unit quaternions (normalised 4-D Gaussians), xyzw."""
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def random_euler(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random ZYX angles away from gimbal lock (|pitch| < 89.4 deg), where they are unique."""
    roll = rng.uniform(-np.pi, np.pi, n)
    pitch = rng.uniform(-np.pi / 2 + 0.01, np.pi / 2 - 0.01, n)
    yaw = rng.uniform(-np.pi, np.pi, n)
    return roll, pitch, yaw


def assert_same_rotation(q_a: np.ndarray, q_b: np.ndarray) -> None:
    """q and -q are the same rotation; compare after aligning signs."""
    sign = np.where(np.sum(q_a * q_b, axis=-1, keepdims=True) < 0.0, -1.0, 1.0)
    assert_allclose(q_a, sign * q_b, atol=ATOL_ROT)


# ---------------------------------------------------------------------------------------------
# units.py angle helpers
# ---------------------------------------------------------------------------------------------

def test_wrap_angle_lands_in_half_open_interval_minus_pi_to_pi(rng):
    # GIVEN angles spanning many turns, plus the boundary values
    angles = np.concatenate([rng.uniform(-50.0, 50.0, N_RANDOM), [-np.pi, np.pi, 0.0]])
    # WHEN wrapped
    wrapped = wrap_angle_rad(angles)
    # THEN they lie in (-pi, pi], and differ from the input by whole turns
    # (1e-12 rad: rounding of a 50 rad input is ~1e-14 rad)
    assert np.all(wrapped > -np.pi) and np.all(wrapped <= np.pi)
    turns = (angles - wrapped) / (2.0 * np.pi)
    assert_allclose(turns, np.round(turns), atol=1e-12)


def test_wrap_angle_maps_minus_pi_to_plus_pi():
    # GIVEN the boundary heading -pi  WHEN wrapped  THEN it has the single representation +pi
    assert wrap_angle_rad(-np.pi) == np.pi


def test_degree_radian_round_trip_is_identity(rng):
    # GIVEN random angles in degrees
    angles_deg = rng.uniform(-720.0, 720.0, N_RANDOM)
    # WHEN converted to radians and back
    back_deg = rad_to_deg(deg_to_rad(angles_deg))
    # THEN they are unchanged (1e-12 deg: float64 rounding of a 720 deg value is ~1e-13 deg)
    assert_allclose(back_deg, angles_deg, atol=1e-12)
    assert deg_to_rad(180.0) == pytest.approx(np.pi, abs=1e-15)


# ---------------------------------------------------------------------------------------------
# Vector frame changes (MAVLink edge)
# ---------------------------------------------------------------------------------------------

def test_ned_round_trip_is_identity(rng):
    # GIVEN random ENU vectors
    v_enu = rng.normal(scale=100.0, size=(N_RANDOM, 3))
    # WHEN converted to NED and back
    back = F.ned_to_enu(F.enu_to_ned(v_enu))
    # THEN they are bit-identical (only copies and sign flips are involved)
    assert np.array_equal(back, v_enu)


def test_enu_east_north_up_become_ned_east_north_down():
    # GIVEN unit vectors east, north, up in ENU
    east_north_up_enu = np.eye(3)
    # WHEN converted to NED
    ned = F.enu_to_ned(east_north_up_enu)
    # THEN east is NED +y, north is NED +x, up is NED -z
    assert_allclose(ned, [[0, 1, 0], [1, 0, 0], [0, 0, -1]], atol=0.0)


def test_enu_to_ned_agrees_with_R_NED_ENU(rng):
    # GIVEN random ENU vectors
    v_enu = rng.normal(size=(N_RANDOM, 3))
    # WHEN converted by the function and by the constant matrix
    # THEN both agree (exact: the matrix has only 0 and +-1 entries)
    assert_allclose(F.enu_to_ned(v_enu), v_enu @ F.R_NED_ENU.T, atol=0.0)
    assert_allclose(F.ned_to_enu(v_enu), v_enu @ F.R_ENU_NED.T, atol=0.0)


def test_frd_round_trip_is_identity(rng):
    # GIVEN random FLU vectors
    v_flu = rng.normal(size=(N_RANDOM, 3))
    # WHEN converted to FRD and back
    back = F.frd_to_flu(F.flu_to_frd(v_flu))
    # THEN they are bit-identical
    assert np.array_equal(back, v_flu)
    assert_allclose(F.flu_to_frd(v_flu), v_flu @ F.R_FRD_FLU.T, atol=0.0)


def test_axis_change_matrices_are_proper_rotations():
    # GIVEN the constant frame-change matrices
    for R in (F.R_ENU_NED, F.R_FLU_FRD, F.R_FLU_OPTICAL):
        # THEN each is orthonormal with determinant +1 (no mirror, so quaternions exist)
        assert_allclose(R @ R.T, np.eye(3), atol=0.0)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-15)


def test_axis_change_quaternions_match_their_matrices():
    # GIVEN the quaternion constants  WHEN turned into matrices  THEN they equal the matrices
    assert_allclose(F.R_from_quat_xyzw(F.Q_NED_ENU_XYZW), F.R_NED_ENU, atol=ATOL_ROT)
    assert_allclose(F.R_from_quat_xyzw(F.Q_FLU_FRD_XYZW), F.R_FLU_FRD, atol=ATOL_ROT)


# ---------------------------------------------------------------------------------------------
# Quaternions and matrices
# ---------------------------------------------------------------------------------------------

def test_wxyz_round_trip_is_identity(rng):
    # GIVEN random xyzw quaternions
    q = random_unit_quats(rng, N_RANDOM)
    # WHEN reordered to wxyz
    q_wxyz = F.quat_xyzw_to_wxyz(q)
    # THEN w comes first, and reordering back restores them exactly
    assert np.array_equal(q_wxyz[:, 0], q[:, 3])
    assert np.array_equal(F.quat_wxyz_to_xyzw(q_wxyz), q)


def test_R_from_quat_is_a_proper_rotation(rng):
    # GIVEN random unit quaternions
    q = random_unit_quats(rng, N_RANDOM)
    # WHEN converted to matrices
    R = F.R_from_quat_xyzw(q)
    # THEN each is orthonormal with determinant +1
    assert R.shape == (N_RANDOM, 3, 3)
    assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape),
                    atol=ATOL_ROT)
    assert_allclose(np.linalg.det(R), 1.0, atol=ATOL_ROT)


def test_R_from_quat_is_the_textbook_formula_bit_for_bit(rng):
    # GIVEN random quaternions, exact axis rotations and a fleet shaped (2, K, 4)
    q = np.concatenate([rng.normal(size=(500, 4)), [[0, 0, 0, 1], [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0],
                                                    [0.5, 0.5, 0.5, -0.5], [0, 0, 1e-9, 1]]])
    for quats in (q, q[:500].reshape(2, 250, 4), q[3]):
        # WHEN converted (the few-numpy-calls form)
        R = F.R_from_quat_xyzw(quats)
        # THEN every entry is 1 - 2 (yy + zz), 2 (xy - wz), ... evaluated as written, signs of zero included
        u = F.quat_normalize_xyzw(quats)
        x, y, z, w = u[..., 0], u[..., 1], u[..., 2], u[..., 3]
        textbook = np.stack([1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y),
                             2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x),
                             2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
                            axis=-1).reshape(R.shape)
        assert np.array_equal(R, textbook) and np.array_equal(np.signbit(R), np.signbit(textbook))


def test_single_quaternion_gives_single_matrix():
    # GIVEN one identity quaternion of shape (4,)  WHEN converted  THEN the result is (3, 3)
    R = F.R_from_quat_xyzw([0.0, 0.0, 0.0, 1.0])
    assert R.shape == (3, 3)
    assert_allclose(R, np.eye(3), atol=0.0)
    assert F.quat_xyzw_from_R(np.eye(3)).shape == (4,)


def test_quaternion_matrix_round_trip_is_identity(rng):
    # GIVEN random unit quaternions
    q = random_unit_quats(rng, N_RANDOM)
    # WHEN converted to matrices and back
    back = F.quat_xyzw_from_R(F.R_from_quat_xyzw(q))
    # THEN the same rotation comes back, with the canonical sign w >= 0
    assert np.all(back[:, 3] >= 0.0)
    assert_same_rotation(back, q)


def test_matrix_quaternion_round_trip_is_identity_near_180_degrees(rng):
    # GIVEN rotations of almost exactly 180 deg (trace ~ -1, where naive formulas divide by ~0)
    axes = rng.normal(size=(N_RANDOM, 3))
    axes /= np.linalg.norm(axes, axis=-1, keepdims=True)
    angles = np.pi - rng.uniform(0.0, 1e-9, N_RANDOM)
    q = np.concatenate([axes * np.sin(angles / 2)[:, None], np.cos(angles / 2)[:, None]], -1)
    R = F.R_from_quat_xyzw(q)
    # WHEN converted to quaternions and back to matrices
    back = F.R_from_quat_xyzw(F.quat_xyzw_from_R(R))
    # THEN the matrices are unchanged
    assert_allclose(back, R, atol=ATOL_ROT)


def test_quaternion_product_composes_like_matrix_product(rng):
    # GIVEN two batches of random rotations
    a, b = random_unit_quats(rng, N_RANDOM), random_unit_quats(rng, N_RANDOM)
    # WHEN composed as quaternions
    R_ab = F.R_from_quat_xyzw(F.quat_multiply_xyzw(a, b))
    # THEN the result equals R(a) @ R(b)
    assert_allclose(R_ab, F.R_from_quat_xyzw(a) @ F.R_from_quat_xyzw(b), atol=ATOL_ROT)


def test_quaternion_times_its_conjugate_is_identity(rng):
    # GIVEN random unit quaternions
    q = random_unit_quats(rng, N_RANDOM)
    # WHEN multiplied by their conjugates
    ident = F.quat_multiply_xyzw(q, F.quat_conjugate_xyzw(q))
    # THEN the identity rotation results
    assert_allclose(ident, np.broadcast_to([0.0, 0.0, 0.0, 1.0], ident.shape), atol=ATOL_ROT)


def test_quat_rotate_equals_matrix_times_vector(rng):
    # GIVEN random attitudes q_enu_flu and FLU vectors
    q = random_unit_quats(rng, N_RANDOM)
    v_flu = rng.normal(size=(N_RANDOM, 3))
    # WHEN rotated by the quaternion
    v_enu = F.quat_rotate_xyzw(q, v_flu)
    # THEN the result equals R_enu_flu @ v_flu
    expected = np.einsum("nij,nj->ni", F.R_from_quat_xyzw(q), v_flu)
    assert_allclose(v_enu, expected, atol=ATOL_ROT)


def test_quat_rotate_broadcasts_one_vector_over_a_fleet(rng):
    # GIVEN N attitudes and one body axis (N = 1 and N > 1 catch broadcasting bugs)
    for n in (1, 7):
        q = random_unit_quats(rng, n)
        # WHEN the same FLU x-axis is rotated by every attitude
        fwd_enu = F.quat_rotate_xyzw(q, [1.0, 0.0, 0.0])
        # THEN each row is the first column of that vehicle's matrix
        assert fwd_enu.shape == (n, 3)
        assert_allclose(fwd_enu, F.R_from_quat_xyzw(q)[:, :, 0], atol=ATOL_ROT)


# ---------------------------------------------------------------------------------------------
# Euler angles
# ---------------------------------------------------------------------------------------------

def test_euler_quaternion_round_trip_is_identity(rng):
    # GIVEN random ZYX angles away from gimbal lock
    roll, pitch, yaw = random_euler(rng, N_RANDOM)
    # WHEN converted to quaternions and back
    r2, p2, y2 = F.euler_rpy_from_quat_xyzw(F.quat_xyzw_from_euler_rpy(roll, pitch, yaw))
    # THEN the angles are unchanged; |pitch| <= 89.4 deg keeps the conditioning within 1e3
    assert_allclose(np.stack([r2, p2, y2]), np.stack([roll, pitch, yaw]), atol=1e-10)


def test_euler_convention_is_yaw_then_pitch_then_roll(rng):
    # GIVEN random angles
    roll, pitch, yaw = random_euler(rng, N_RANDOM)
    # WHEN the quaternion is turned into a matrix
    R = F.R_from_quat_xyzw(F.quat_xyzw_from_euler_rpy(roll, pitch, yaw))
    # THEN it equals Rz(yaw) @ Ry(pitch) @ Rx(roll)
    c, s = np.cos, np.sin
    one, zero = np.ones_like(roll), np.zeros_like(roll)
    Rx = np.stack([one, zero, zero, zero, c(roll), -s(roll), zero, s(roll), c(roll)], -1)
    Ry = np.stack([c(pitch), zero, s(pitch), zero, one, zero, -s(pitch), zero, c(pitch)], -1)
    Rz = np.stack([c(yaw), -s(yaw), zero, s(yaw), c(yaw), zero, zero, zero, one], -1)
    expected = Rz.reshape(-1, 3, 3) @ Ry.reshape(-1, 3, 3) @ Rx.reshape(-1, 3, 3)
    assert_allclose(R, expected, atol=ATOL_ROT)


def test_quaternion_from_euler_matches_pybullet(rng):
    # GIVEN PyBullet, the engine whose quaternions we store
    pybullet = pytest.importorskip("pybullet")
    roll, pitch, yaw = random_euler(rng, 200)
    # WHEN both build quaternions from the same angles
    ours = F.quat_xyzw_from_euler_rpy(roll, pitch, yaw)
    theirs = np.array([pybullet.getQuaternionFromEuler([r, p, y])
                       for r, p, y in zip(roll, pitch, yaw)])
    # THEN they are the same rotation (PyBullet computes in float64 too)
    assert_same_rotation(ours, theirs)


def test_euler_from_quaternion_matches_pybullet(rng):
    # GIVEN PyBullet and random attitudes away from gimbal lock
    pybullet = pytest.importorskip("pybullet")
    roll, pitch, yaw = random_euler(rng, 200)
    q = F.quat_xyzw_from_euler_rpy(roll, pitch, yaw)
    # WHEN both extract Euler angles
    ours = np.stack(F.euler_rpy_from_quat_xyzw(q), axis=-1)
    theirs = np.array([pybullet.getEulerFromQuaternion(qi) for qi in q])
    # THEN they agree (1e-10 rad: PyBullet uses asin for pitch, which loses digits near 90 deg)
    assert_allclose(ours, theirs, atol=1e-10)


def test_yaw_from_quaternion_equals_euler_yaw(rng):
    # GIVEN random attitudes, scaled off unit norm to check scale invariance
    roll, pitch, yaw = random_euler(rng, N_RANDOM)
    q = F.quat_xyzw_from_euler_rpy(roll, pitch, yaw) * rng.uniform(0.5, 2.0, (N_RANDOM, 1))
    # WHEN the yaw alone is extracted  THEN it equals the yaw that built them
    assert_allclose(F.yaw_rad_from_quat_xyzw(q), yaw, atol=1e-10)


# ---------------------------------------------------------------------------------------------
# Facts about vehicles and cameras
# ---------------------------------------------------------------------------------------------

def test_flu_x_of_level_body_yawed_90deg_points_north():
    # GIVEN a level body yawed +90 deg in ENU (counter-clockwise from east)
    q_enu_flu = F.quat_xyzw_from_euler_rpy(0.0, 0.0, np.pi / 2)
    # WHEN its forward axis is expressed in ENU
    fwd_enu = F.quat_rotate_xyzw(q_enu_flu, [1.0, 0.0, 0.0])
    # THEN it points to ENU +y (north)
    assert_allclose(fwd_enu, [0.0, 1.0, 0.0], atol=ATOL_ROT)


def test_body_yawed_90deg_in_enu_has_ned_heading_zero():
    # GIVEN a level body facing north: ENU yaw +90 deg
    q_enu_flu = F.quat_xyzw_from_euler_rpy(0.0, 0.0, np.pi / 2)
    # WHEN its attitude is converted to NED/FRD
    q_ned_frd = F.quat_enu_flu_to_ned_frd(q_enu_flu)
    # THEN the NED heading is 0 (north) and the attitude is level (identity)
    assert F.yaw_rad_from_quat_xyzw(q_ned_frd) == pytest.approx(0.0, abs=ATOL_ROT)
    assert_same_rotation(q_ned_frd, np.array([0.0, 0.0, 0.0, 1.0]))


def test_yaw_enu_to_ned_maps_north_to_zero_and_east_to_plus_90deg():
    # GIVEN ENU yaws facing north, east, south, west
    yaw_enu = np.array([np.pi / 2, 0.0, -np.pi / 2, np.pi])
    # WHEN converted to NED headings
    heading_ned = F.yaw_enu_to_ned_rad(yaw_enu)
    # THEN north = 0, east = +90 deg (clockwise), south = 180 deg, west = -90 deg
    assert_allclose(heading_ned, [0.0, np.pi / 2, np.pi, -np.pi / 2], atol=ATOL_ROT)
    assert_allclose(F.yaw_ned_to_enu_rad(heading_ned), wrap_angle_rad(yaw_enu), atol=ATOL_ROT)


def test_ned_frd_attitude_keeps_roll_negates_pitch_and_complements_yaw(rng):
    # GIVEN random ENU/FLU attitudes away from gimbal lock
    roll, pitch, yaw = random_euler(rng, N_RANDOM)
    q_enu_flu = F.quat_xyzw_from_euler_rpy(roll, pitch, yaw)
    # WHEN converted to NED/FRD
    r_ned, p_ned, y_ned = F.euler_rpy_from_quat_xyzw(F.quat_enu_flu_to_ned_frd(q_enu_flu))
    # THEN right-wing-down roll is unchanged, nose-up pitch flips sign (FLU +pitch is nose-down),
    # and the heading is pi/2 - yaw; compared through wrap so +-pi are the same angle
    assert_allclose(wrap_angle_rad(r_ned - roll), 0.0, atol=1e-10)
    assert_allclose(p_ned, -pitch, atol=1e-10)
    assert_allclose(wrap_angle_rad(y_ned - F.yaw_enu_to_ned_rad(yaw)), 0.0, atol=1e-10)


def test_ned_frd_attitude_equals_matrix_sandwich(rng):
    # GIVEN random ENU/FLU attitudes
    q_enu_flu = random_unit_quats(rng, N_RANDOM)
    # WHEN converted to NED/FRD
    R_ned_frd = F.R_from_quat_xyzw(F.quat_enu_flu_to_ned_frd(q_enu_flu))
    # THEN the matrix is R_NED_ENU @ R_enu_flu @ R_FLU_FRD
    expected = F.R_NED_ENU @ F.R_from_quat_xyzw(q_enu_flu) @ F.R_FLU_FRD
    assert_allclose(R_ned_frd, expected, atol=ATOL_ROT)


def test_ned_frd_attitude_round_trip_is_identity(rng):
    # GIVEN random ENU/FLU attitudes
    q_enu_flu = random_unit_quats(rng, N_RANDOM)
    # WHEN converted to NED/FRD and back
    back = F.quat_ned_frd_to_enu_flu(F.quat_enu_flu_to_ned_frd(q_enu_flu))
    # THEN the same rotation comes back
    assert_same_rotation(back, q_enu_flu)


def test_camera_optical_z_on_level_body_facing_east_points_east():
    # GIVEN a level body with yaw 0 (facing east) and a forward-looking camera
    R_enu_flu = F.R_from_quat_xyzw(F.quat_xyzw_from_euler_rpy(0.0, 0.0, 0.0))
    R_enu_optical = R_enu_flu @ F.R_FLU_OPTICAL
    # WHEN the optical z axis (the viewing direction) is expressed in ENU
    view_enu = R_enu_optical @ np.array([0.0, 0.0, 1.0])
    # THEN it points east
    assert_allclose(view_enu, [1.0, 0.0, 0.0], atol=ATOL_ROT)


def test_camera_optical_x_is_right_and_y_is_down_on_level_body_facing_east():
    # GIVEN a level body facing east and a forward-looking camera
    R_enu_optical = F.R_from_quat_xyzw([0.0, 0.0, 0.0, 1.0]) @ F.R_FLU_OPTICAL
    # WHEN the image axes are expressed in ENU
    right_enu = R_enu_optical @ np.array([1.0, 0.0, 0.0])
    down_enu = R_enu_optical @ np.array([0.0, 1.0, 0.0])
    # THEN image x points to the body's right (south) and image y points down
    assert_allclose(right_enu, [0.0, -1.0, 0.0], atol=ATOL_ROT)
    assert_allclose(down_enu, [0.0, 0.0, -1.0], atol=ATOL_ROT)


def test_row_norm_is_the_euclidean_length_of_each_row(rng):
    v = rng.normal(size=(N_RANDOM, 3)) * 100.0
    assert_allclose(F.row_norm(v), np.linalg.norm(v, axis=1), rtol=1e-14)
    assert_allclose(F.row_norm(np.array([[3.0, 4.0], [0.0, 0.0]])), [5.0, 0.0])
