"""kinfw.geometry against Pinocchio's SE3 / quaternion maths (independent truth)."""

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from kinfw.geometry import (
    check_rotation,
    check_transform,
    inverse_transform,
    matrix_from_rotation_vector,
    quat_xyzw_from_matrix,
    rot_z,
    rotation_angle,
    rotation_vector_from_matrix,
    transform_from_xyz_quat_xyzw,
    xyz_quat_xyzw_from_transform,
)

unit = st.floats(-1.0, 1.0, allow_nan=False)
vec3 = st.tuples(unit, unit, unit).map(np.array)


def _random_rotvecs(rng, n, max_angle=np.pi):
    axes = rng.normal(size=(n, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    return axes * rng.uniform(0.0, max_angle, size=(n, 1))


def test_exp_and_log_match_pinocchio_over_the_whole_range():
    rng = np.random.default_rng(0)
    w = _random_rotvecs(rng, 500)
    w[:5] *= 1e-10  # near zero
    w[5:10] *= (np.pi - 1e-7) / np.linalg.norm(w[5:10], axis=1, keepdims=True)  # near pi
    R = matrix_from_rotation_vector(w)
    for k in range(len(w)):
        np.testing.assert_allclose(R[k], pin.exp3(w[k]), atol=1e-14)
    w_back = rotation_vector_from_matrix(R)
    for k in range(len(w)):
        np.testing.assert_allclose(pin.exp3(w_back[k]), R[k], atol=1e-13)
    np.testing.assert_allclose(rotation_angle(R), np.linalg.norm(w, axis=1), atol=1e-12)


def test_log_at_exactly_pi_returns_a_valid_rotation_vector():
    for axis in np.eye(3):
        R = pin.exp3(np.pi * axis)
        w = rotation_vector_from_matrix(R)
        assert np.linalg.norm(w) == pytest.approx(np.pi, abs=1e-12)
        np.testing.assert_allclose(pin.exp3(w), R, atol=1e-14)


def test_quaternion_matches_pinocchio_xyzw_storage():
    rng = np.random.default_rng(1)
    R = matrix_from_rotation_vector(_random_rotvecs(rng, 300))
    q = quat_xyzw_from_matrix(R)
    for k in range(len(R)):
        qp = pin.Quaternion(R[k]).coeffs()  # Eigen stores (x, y, z, w)
        qp = qp if qp[3] >= 0 else -qp
        np.testing.assert_allclose(q[k], qp, atol=1e-12)
    assert np.all(q[:, 3] >= 0.0)


def test_ninety_degrees_about_z_by_hand():
    s = np.sqrt(0.5)
    T = transform_from_xyz_quat_xyzw([1.0, 2.0, 3.0], [0.0, 0.0, s, s])
    expected = np.array([[0, -1, 0, 1], [1, 0, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]], float)
    np.testing.assert_allclose(T, expected, atol=1e-15)
    np.testing.assert_allclose(rot_z(np.pi / 2), expected[:3, :3], atol=1e-15)


@settings(max_examples=200, deadline=None)
@given(vec3, vec3)
def test_xyz_quat_round_trip(xyz, w):
    T = np.eye(4)
    T[:3, :3] = pin.exp3(3.0 * w)
    T[:3, 3] = xyz
    p, q = xyz_quat_xyzw_from_transform(T)
    np.testing.assert_allclose(transform_from_xyz_quat_xyzw(p, q), T, atol=1e-14)


def test_inverse_transform_matches_pinocchio_se3_inverse():
    rng = np.random.default_rng(2)
    for _ in range(50):
        M = pin.SE3.Random()
        np.testing.assert_allclose(
            inverse_transform(M.homogeneous), M.inverse().homogeneous, atol=1e-14
        )
    batch = np.stack([pin.SE3.Random().homogeneous for _ in range(10)])
    np.testing.assert_allclose(
        inverse_transform(batch) @ batch, np.broadcast_to(np.eye(4), batch.shape), atol=1e-14
    )
    assert rng is not None


def test_check_transform_names_the_culprit():
    T = np.eye(4)
    bad = np.stack([T, T, T])
    bad[2, :3, :3] *= 2.0
    with pytest.raises(ValueError, match=r"world_T_plate\[2\]: not a rotation"):
        check_transform(bad, "world_T_plate")
    with pytest.raises(ValueError, match=r"expected shape \(4, 4\) or \(n, 4, 4\), got \(3, 4\)"):
        check_transform(np.eye(4)[:3], "base_T_flange")
    reflection = np.diag([1.0, 1.0, -1.0])
    with pytest.raises(ValueError, match="det"):
        check_rotation(reflection, "R")
    nan = np.eye(4)
    nan[0, 3] = np.nan
    with pytest.raises(ValueError, match="finite"):
        check_transform(nan, "T")
