"""Adding a hand-eye closed form without touching the library: the extension recipe of
docs/architecture.md, done here.

The start defined below is Horaud & Dornaika's (1995) quaternion form of ``A X = X B``:
each relative motion gives ``q(A_ij) q_X = q_X q(B_ij)``, i.e. ``(L(q_A) - R(q_B)) q_X
= 0``, solved by the smallest right singular vector of the stacked 4x4 blocks; then the
translation from ``(R_A - I) t_X = R_X t_B - t_A`` by linear least squares. It is one
function and one :func:`register_start` call; the truth is built with Pinocchio
(tests/pin_se3.py).
"""

from __future__ import annotations

import numpy as np
import pytest

from kinfw.geometry import average_transform, quat_xyzw_from_matrix
from kinfw.identification.handeye import (
    HANDEYE_METHODS,
    START_METHODS,
    StartMethod,
    candidate_starts,
    fit_method,
    handeye_methods,
    register_start,
    shah_axyb,
    solve_axxb,
    unregister_start,
)
from tests.pin_se3 import angle, inverse, random_axis, rotation, transform

CALLS: list[int] = []


def _left(q):
    """``L(q)`` with ``q ⊗ p = L(q) p``, quaternions xyzw."""
    v, w = q[:3], q[3]
    out = np.empty((4, 4))
    out[:3, :3] = w * np.eye(3) + np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    out[:3, 3], out[3, :3], out[3, 3] = v, -v, w
    return out


def _right(p):
    """``R(p)`` with ``q ⊗ p = R(p) q``, quaternions xyzw."""
    u, s = p[:3], p[3]
    out = np.empty((4, 4))
    out[:3, :3] = s * np.eye(3) - np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
    out[:3, 3], out[3, :3], out[3, 3] = u, -u, s
    return out


def horaud_axxb(A, B):
    """``(X, Y)`` of ``A[i] X B[i] = Y`` (``A = base_T_hand``, ``B = camera_T_target``)."""
    CALLS.append(len(A))
    i, j = np.triu_indices(len(A), k=1)
    A_ij = np.linalg.inv(A[j]) @ A[i]
    B_ij = B[j] @ np.linalg.inv(B[i])
    q_A, q_B = quat_xyzw_from_matrix(A_ij[:, :3, :3]), quat_xyzw_from_matrix(B_ij[:, :3, :3])
    q_A *= np.sign(q_A[:, 3:4] + (q_A[:, 3:4] == 0))  # w >= 0: both turn by the same angle
    q_B *= np.sign(q_B[:, 3:4] + (q_B[:, 3:4] == 0))
    M = np.concatenate([_left(a) - _right(b) for a, b in zip(q_A, q_B, strict=True)])
    q_X = np.linalg.svd(M)[2][-1]
    X = np.eye(4)
    x, y, z, w = q_X / np.linalg.norm(q_X)  # the rotation of the unit quaternion q_X
    X[:3, :3] = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    lhs = (A_ij[:, :3, :3] - np.eye(3)).reshape(-1, 3)
    rhs = (B_ij[:, :3, 3] @ X[:3, :3].T - A_ij[:, :3, 3]).reshape(-1)
    X[:3, 3] = np.linalg.lstsq(lhs, rhs, rcond=None)[0]
    return X, average_transform(A @ X @ B)


@pytest.fixture
def horaud():
    """The start registered for one test, removed after it."""
    CALLS.clear()
    register_start("horaud", StartMethod("axxb", horaud_axxb))
    yield
    unregister_start("horaud")


def _scene(seed, n=10):
    """Truth ``hand_T_camera``, ``base_T_target`` and exact poses of an eye-in-hand setup."""
    rng = np.random.default_rng(seed)
    hand_T_camera = transform(rotation(random_axis(rng) * 2.0), [0.03, -0.02, 0.08])
    base_T_target = transform(rotation(random_axis(rng)), [0.5, 0.1, 0.2])
    base_T_hands = np.stack(
        [
            transform(rotation(random_axis(rng) * rng.uniform(0.2, 1.5)), rng.uniform(-0.3, 0.3, 3))
            for _ in range(n)
        ]
    )
    camera_T_targets = inverse(hand_T_camera) @ inverse(base_T_hands) @ base_T_target
    return hand_T_camera, base_T_target, base_T_hands, camera_T_targets


@pytest.mark.parametrize("seed", range(3))
def test_the_registered_start_is_a_candidate_and_exact(horaud, seed):
    hand_T_camera, base_T_target, A, B = _scene(seed)
    X, Y = candidate_starts(A, B, problem="axxb")["horaud"]
    assert angle(X[:3, :3].T @ hand_T_camera[:3, :3]) < 1e-9
    np.testing.assert_allclose(X[:3, 3], hand_T_camera[:3, 3], atol=1e-9)
    np.testing.assert_allclose(Y, base_T_target, atol=1e-9)
    assert list(START_METHODS)[-1] == "horaud"  # after the built-ins


def test_the_solver_fits_from_it_when_it_tries_the_closed_forms(horaud):
    """One camera pose turned by 20 deg among 10: the first fit is not clean, so the
    solver fits from every closed form, the registered one included, and ends at the
    truth of the other nine."""
    hand_T_camera, _, A, B = _scene(7)
    B[4, :3, :3] = rotation([0.0, np.radians(20.0), 0.0]) @ B[4, :3, :3]
    result = solve_axxb(base_T_hands=A, camera_T_targets=B)
    assert CALLS, "the registered start was never called"
    assert result.rejected == (4,)
    np.testing.assert_allclose(result.hand_T_camera, hand_T_camera, atol=1e-9)


def test_names_are_unique_and_built_ins_stay(horaud):
    with pytest.raises(ValueError, match="already registered"):
        register_start("horaud", StartMethod("axxb", horaud_axxb))
    with pytest.raises(ValueError, match="built-in"):
        unregister_start("park")
    with pytest.raises(ValueError, match="'axxb' or 'axyb'"):
        register_start("other", StartMethod("axbx", horaud_axxb))
    assert "other" not in START_METHODS


@pytest.fixture
def renamed():
    """Horaud's form and kinfw's own Shah form of ``A = X B Y`` under names OpenCV does not
    use, for one test."""
    register_start("horaud_q", StartMethod("axxb", horaud_axxb))
    register_start("shah_again", StartMethod("axyb", shah_axyb))
    yield
    unregister_start("horaud_q")
    unregister_start("shah_again")


@pytest.mark.parametrize("setup", ["eye-in-hand", "eye-to-hand"])
def test_fit_method_fits_registered_starts_of_either_problem_in_its_letters(renamed, setup):
    """``kinfw handeye --method NAME``'s fit: an ``axxb`` start gives ``(hand_T_camera,
    base_T_target)`` as it is, an ``axyb`` start ``(camera_T_hand, base_T_target)``,
    which fit_method inverts; both equal the scene's truth (eye-to-hand: the same
    equation with base and hand exchanged, the poses given as base_T_hand)."""
    mount_T_camera, holder_T_target, A, B = _scene(3)
    base_T_hands = A if setup == "eye-in-hand" else inverse(A)
    assert handeye_methods() == (*HANDEYE_METHODS, "horaud_q", "shah_again")
    for name in ("horaud_q", "shah_again"):
        X, Y = fit_method(name, base_T_hands=base_T_hands, camera_T_targets=B, setup=setup)
        np.testing.assert_allclose(X, mount_T_camera, atol=1e-9)
        np.testing.assert_allclose(Y, holder_T_target, atol=1e-9)


def test_a_registered_start_named_like_an_opencv_method_is_opencvs_there(horaud):
    """``horaud`` is OpenCV's name: fit_method keeps OpenCV's, handeye_methods adds
    nothing, and the registered start is not called."""
    _, _, A, B = _scene(4)
    assert handeye_methods() == HANDEYE_METHODS
    fit_method("horaud", base_T_hands=A, camera_T_targets=B, setup="eye-in-hand")
    assert not CALLS
    with pytest.raises(ValueError, match="unknown hand-eye method 'nobody'"):
        fit_method("nobody", base_T_hands=A, camera_T_targets=B, setup="eye-in-hand")
