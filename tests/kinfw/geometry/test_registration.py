"""Tests of identification.registration.register_points (Arun et al. / Shih et al. 3.3)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from kinfw.geometry import (
    matrix_from_rotation_vector,
    register_points,
    rotation_angle,
    transform_from_rotation_translation,
)

PLATE = 0.02 * np.array([[x, y, 0.0] for y in (-1, 0, 1) for x in (-1, 0, 1)])


def random_poses(rng: np.random.Generator, n: int) -> np.ndarray:
    rotvecs = rng.normal(size=(n, 3))
    rotvecs *= (rng.uniform(0.0, np.pi, n) / np.linalg.norm(rotvecs, axis=1))[:, None]
    return transform_from_rotation_translation(
        matrix_from_rotation_vector(rotvecs), rng.normal(0.0, 1.0, (n, 3))
    )


def apply(T: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Points p (N, 3) mapped by T (..., 4, 4) -> (..., N, 3)."""
    return np.einsum("...ij,kj->...ki", T[..., :3, :3], p) + T[..., None, :3, 3]


def horn_rotation(frame_p: np.ndarray, meas_p: np.ndarray) -> np.ndarray:
    """meas_R_frame by Horn's unit-quaternion method (1987): always a proper rotation."""
    a = frame_p - frame_p.mean(axis=0)
    b = meas_p - meas_p.mean(axis=0)
    S = a.T @ b  # S[i, j] = sum a_i b_j
    (sxx, sxy, sxz), (syx, syy, syz), (szx, szy, szz) = S
    N = np.array(
        [
            [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
            [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
            [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
            [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
        ]
    )
    w, x, y, z = np.linalg.eigh(N)[1][:, -1]
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def test_recovers_single_pose_exactly() -> None:
    rng = np.random.default_rng(1)
    frame_p = rng.normal(0.0, 0.1, (6, 3))
    meas_T_frame = random_poses(rng, 1)[0]
    got = register_points(frame_p, apply(meas_T_frame, frame_p))
    assert got.shape == (4, 4)
    np.testing.assert_allclose(got, meas_T_frame, rtol=0, atol=1e-12)


def test_recovers_batch_exactly() -> None:
    rng = np.random.default_rng(2)
    frame_p = rng.normal(0.0, 0.1, (5, 3))
    meas_T_frames = random_poses(rng, 50)
    got = register_points(frame_p, apply(meas_T_frames, frame_p))
    assert got.shape == (50, 4, 4)
    np.testing.assert_allclose(got, meas_T_frames, rtol=0, atol=1e-12)


def test_recovers_coplanar_plate_exactly_with_three_points() -> None:
    rng = np.random.default_rng(3)
    meas_T_frames = random_poses(rng, 20)
    for frame_p in (PLATE, PLATE[[0, 2, 7]]):
        got = register_points(frame_p, apply(meas_T_frames, frame_p))
        np.testing.assert_allclose(got, meas_T_frames, rtol=0, atol=1e-12)


def test_batched_frame_points_broadcast() -> None:
    rng = np.random.default_rng(4)
    frame_ps = rng.normal(0.0, 0.1, (7, 4, 3))
    meas_T_frames = random_poses(rng, 7)
    meas_ps = (
        np.einsum("nij,nkj->nki", meas_T_frames[:, :3, :3], frame_ps)
        + meas_T_frames[:, None, :3, 3]
    )
    np.testing.assert_allclose(
        register_points(frame_ps, meas_ps), meas_T_frames, rtol=0, atol=1e-12
    )


def test_reflection_fix_on_coplanar_noisy_points() -> None:
    # Coplanar plate points: H has a zero third column, so the sign of the last singular
    # vectors is arbitrary and the naive V U^T is a reflection about half the time.
    rng = np.random.default_rng(5)
    meas_T_frames = random_poses(rng, 200)
    meas_ps = apply(meas_T_frames, PLATE) + rng.normal(0.0, 1e-3, (200, 9, 3))
    H = np.einsum(
        "nki,kj->nij", meas_ps - meas_ps.mean(axis=1, keepdims=True), PLATE - PLATE.mean(axis=0)
    )
    U, _, Vt = np.linalg.svd(H)
    naive_det = np.linalg.det(U @ Vt)
    assert np.sum(naive_det < 0) >= 20  # the reflection case really occurs here

    got = register_points(PLATE, meas_ps)
    R = got[:, :3, :3]
    np.testing.assert_allclose(np.linalg.det(R), 1.0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        R @ np.swapaxes(R, 1, 2), np.broadcast_to(np.eye(3), R.shape), rtol=0, atol=1e-12
    )
    for k in np.flatnonzero(naive_det < 0)[:20]:
        np.testing.assert_allclose(R[k], horn_rotation(PLATE, meas_ps[k]), rtol=0, atol=1e-9)
    assert rotation_angle(np.swapaxes(R, 1, 2) @ meas_T_frames[:, :3, :3]).max() < 0.2


def test_reflection_fix_on_mirrored_points_is_least_squares_rotation() -> None:
    # A mirror image of a non-coplanar set: the best orthogonal matrix is a reflection,
    # the best rotation (Horn's method, independent) is what must come back.
    rng = np.random.default_rng(6)
    frame_p = rng.normal(0.0, 0.1, (8, 3))
    meas_p = frame_p * np.array([1.0, 1.0, -1.0]) + np.array([0.3, -0.2, 1.0])
    got = register_points(frame_p, meas_p)
    np.testing.assert_allclose(np.linalg.det(got[:3, :3]), 1.0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got[:3, :3], horn_rotation(frame_p, meas_p), rtol=0, atol=1e-9)
    np.testing.assert_allclose(
        got[:3, 3], meas_p.mean(axis=0) - got[:3, :3] @ frame_p.mean(axis=0), rtol=0, atol=1e-12
    )


def test_noisy_points_match_horn() -> None:
    rng = np.random.default_rng(7)
    frame_p = rng.normal(0.0, 0.05, (9, 3))
    meas_T_frames = random_poses(rng, 30)
    meas_ps = apply(meas_T_frames, frame_p) + rng.normal(0.0, 0.01, (30, 9, 3))
    got = register_points(frame_p, meas_ps)
    for k in range(30):
        np.testing.assert_allclose(
            got[k, :3, :3], horn_rotation(frame_p, meas_ps[k]), rtol=0, atol=1e-9
        )


def test_position_error_statistics() -> None:
    # With the plate centred on its origin, the registered position error is the mean of
    # the point errors: std sigma / sqrt(N) per axis.
    rng = np.random.default_rng(8)
    n, sigma = 4000, 5e-4
    meas_T_frames = random_poses(rng, n)
    meas_ps = apply(meas_T_frames, PLATE) + rng.normal(0.0, sigma, (n, 9, 3))
    err = register_points(PLATE, meas_ps)[:, :3, 3] - meas_T_frames[:, :3, 3]
    rms = np.sqrt(np.mean(err**2, axis=0))
    np.testing.assert_allclose(rms, sigma / np.sqrt(9), rtol=0.10)
    np.testing.assert_allclose(err.mean(axis=0), 0.0, rtol=0, atol=4 * sigma / 3 / np.sqrt(n))


@settings(max_examples=50, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), scale=st.sampled_from([1e-3, 1.0, 1e3]))
def test_invariant_to_point_order_and_length_unit(seed: int, scale: float) -> None:
    rng = np.random.default_rng(seed)
    frame_p = rng.normal(0.0, 0.1, (6, 3))
    meas_p = apply(random_poses(rng, 1)[0], frame_p) + rng.normal(0.0, 0.005, (6, 3))
    ref = register_points(frame_p, meas_p)
    perm = rng.permutation(6)
    np.testing.assert_allclose(
        register_points(frame_p[perm], meas_p[perm]), ref, rtol=0, atol=1e-12
    )
    scaled = register_points(scale * frame_p, scale * meas_p)
    np.testing.assert_allclose(scaled[:3, :3], ref[:3, :3], rtol=0, atol=1e-10)
    np.testing.assert_allclose(scaled[:3, 3] / scale, ref[:3, 3], rtol=0, atol=1e-10)


def test_too_few_points() -> None:
    with pytest.raises(ValueError, match="at least 3 points, got 2"):
        register_points(np.eye(3)[:2], np.eye(3)[:2])


def test_collinear_frame_points() -> None:
    line = np.outer(np.arange(4.0), [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match=r"frame_p: points are collinear"):
        register_points(line, np.eye(4)[:, :3])


def test_collinear_measured_points_name_the_batch_index() -> None:
    rng = np.random.default_rng(9)
    frame_p = rng.normal(size=(4, 3))
    meas_ps = np.stack([frame_p, np.zeros((4, 3)), frame_p])
    with pytest.raises(ValueError, match=r"meas_p\[1\]: points are collinear or coincident"):
        register_points(frame_p, meas_ps)


def test_shape_errors() -> None:
    with pytest.raises(ValueError, match=r"frame_p: expected shape \(N, 3\)"):
        register_points(np.zeros((4, 2)), np.zeros((4, 3)))
    with pytest.raises(ValueError, match="same number of points, got 4 and 5"):
        register_points(np.eye(4)[:, :3], np.zeros((5, 3)))
    with pytest.raises(ValueError, match="batch sizes differ"):
        register_points(np.zeros((2, 4, 3)), np.zeros((3, 4, 3)))
    with pytest.raises(ValueError, match="meas_p: contains non-finite values"):
        register_points(np.eye(4)[:, :3], np.full((4, 3), np.nan))
