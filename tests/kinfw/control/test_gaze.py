"""kinfw.control against independent truth: points built by Pinocchio FK (the
intersection of both optical axes of a configuration), hand geometry of a pan camera,
brute-force searches over joint ranges, finite differences, and OpenCV's projection."""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from kinfw.camera import CameraIntrinsics
from kinfw.control import GazeSolver, fixate, ray_errors_rad
from kinfw.model import Robot, RobotModelError, UnknownFrameError, load_robot
from tests.fixation import (
    CAMERAS,
    axes_intersection,
    camera_poses,
    fk_errors_rad,
    ideal_fixation_points,
)
from tests.paths import HEAD_URDF
from tests.robots import IDEAL_HEAD, PAN_CAMERA


@pytest.fixture(scope="module")
def ideal() -> Robot:
    return Robot(IDEAL_HEAD)


@pytest.fixture(scope="module")
def pan_camera() -> Robot:
    return Robot(PAN_CAMERA)


def test_ideal_head_fixates_fk_points_exactly(ideal):
    solver = GazeSolver(ideal)
    assert solver.free_joints == ("pan", "tilt", "vergence_left", "vergence_right")
    lower, upper = ideal.joint_limits()
    for q_true, point in ideal_fixation_points(ideal, 30, seed=1):
        q_start = np.array([q_true[0], 0.0, 0.0, 0.0, 0.0])  # slide where it was
        fix = solver.fixate(point, q_start=q_start)
        measured = fk_errors_rad(ideal, fix.q, point)
        assert np.all(measured < 1e-9), (q_true, measured)
        np.testing.assert_allclose(fix.error_rad, measured, atol=1e-12)
        assert fix.fixated
        assert np.all(fix.q >= lower) and np.all(fix.q <= upper)
        assert fix.q[0] == q_start[0]  # the slide is not free: it keeps q_start exactly
        # in front of both cameras, not behind (the angle would be pi there)
        camera_ps = np.einsum(
            "kji,kj->ki",
            camera_poses(ideal, fix.q)[:, :3, :3],
            point - camera_poses(ideal, fix.q)[:, :3, 3],
        )
        assert np.all(camera_ps[:, 2] > 0.0)


def test_freed_slide_is_solved_and_others_keep_q_start(ideal):
    """Pan held at its value in the configuration that built the point (so the point
    can be fixated without it), the slide freed instead."""
    for q_true, point in ideal_fixation_points(ideal, 10, seed=2):
        q_start = np.array([0.25, q_true[1], 0.0, 0.0, 0.0])
        _check_freed_slide(ideal, point, q_start)


def _check_freed_slide(ideal, point, q_start):
    fix = fixate(
        ideal,
        point,
        q_start=q_start,
        free_joints=("slide", "vergence_left", "vergence_right", "tilt"),
    )
    assert fix.free_joints == ("slide", "vergence_left", "vergence_right", "tilt")
    assert fix.q[1] == q_start[1]  # pan not freed
    assert np.all(fk_errors_rad(ideal, fix.q, point) < 1e-9)


def test_pixels_project_where_asked(ideal):
    """camera_rays from pixels: at the solution the point projects to those pixels.

    The pixels are made consistent by construction: a configuration, the point on the
    right camera's ray through (u, v), and the left pixel where that point projects."""
    left = CameraIntrinsics(640, 480, 500.0, 505.0, 330.0, 235.0, k1=-0.2, k2=0.05, p1=1e-3)
    right = CameraIntrinsics(640, 480, 480.0, 482.0, 315.0, 245.0, k1=0.1, p2=-2e-3)
    rng = np.random.default_rng(3)
    for _ in range(10):
        q = np.array([0.1, rng.uniform(-1, 1), rng.uniform(-0.5, 0.5), -0.1, 0.1])
        uv_right = rng.uniform([150, 100], [490, 380])
        root_T = camera_poses(ideal, q)
        ray_right = right.rays(uv_right)
        point = root_T[1, :3, :3] @ (rng.uniform(0.8, 3.0) * ray_right) + root_T[1, :3, 3]
        uv_left = left.project((point - root_T[0, :3, 3]) @ root_T[0, :3, :3])
        rays = np.stack([left.rays(uv_left), ray_right])
        fix = fixate(ideal, point, camera_rays=rays, q_start=np.array([0.1, 0, 0, 0, 0]))
        assert fix.fixated
        at = camera_poses(ideal, fix.q)
        for k, (camera, uv) in enumerate(((left, uv_left), (right, uv_right))):
            camera_p = (point - at[k, :3, 3]) @ at[k, :3, :3]
            np.testing.assert_allclose(camera.project(camera_p), uv, atol=1e-6)


@settings(max_examples=15)
@given(
    xyz=st.tuples(*[st.floats(-3.0, 3.0)] * 3),
    rpy=st.tuples(*[st.floats(-math.pi, math.pi)] * 3),
)
def test_moving_the_root_moves_nothing(xyz, rpy):
    """The IIS head under an extra rigid root motion, with the point moved alike, gets
    the same joint values (the closest fixation too): nothing depends on the root frame."""
    moved_xml = (
        HEAD_URDF.read_text()
        .replace('<link name="world">', '<link name="new_root"/>\n  <link name="world">', 1)
        .replace(
            '<joint name="world_to_base"',
            f'<joint name="new_root_to_world" type="fixed"><parent link="new_root"/>'
            f'<child link="world"/><origin xyz="{" ".join(map(repr, xyz))}" '
            f'rpy="{" ".join(map(repr, rpy))}"/></joint>\n  <joint name="world_to_base"',
            1,
        )
    )
    moved = Robot(moved_xml)
    assert moved.root_link == "new_root"
    new_root_T_world = moved.frame_poses(np.zeros(6), "world")
    for world_p in ([0.6, 0.4, 1.1], [1.5, 1.2, 0.5]):
        fix = _head_solver().fixate(world_p)
        moved_p = new_root_T_world[:3, :3] @ world_p + new_root_T_world[:3, 3]
        fix_moved = fixate(moved, moved_p)
        np.testing.assert_allclose(fix_moved.q, fix.q, atol=1e-9)
        np.testing.assert_allclose(fix_moved.error_rad, fix.error_rad, atol=1e-10)


@functools.cache
def _head() -> Robot:  # Hypothesis tests cannot take function-scoped fixtures
    return Robot(HEAD_URDF.read_text(), str(HEAD_URDF))


@functools.cache
def _head_solver() -> GazeSolver:
    return GazeSolver(_head())


# -- the built-in IIS head: closest fixation ------------------------------------------


def stereographic_residual(robot: Robot, q: np.ndarray, free: list[int], point) -> callable:
    """r(x): the two stereographic coordinates 2 s_xy / (|s| + s_z) per camera, by FK."""

    def r(x):
        qq = q.copy()
        qq[free] = x
        root_T = camera_poses(robot, qq)
        s = np.einsum("kji,kj->ki", root_T[:, :3, :3], point - root_T[:, :3, 3])
        return (2.0 * s[:, :2] / (np.linalg.norm(s, axis=1) + s[:, 2])[:, None]).ravel()

    return r


@pytest.mark.parametrize("distance_m", [0.5, 1.0, 2.0])
def test_iis_head_closest_fixation_is_a_local_minimum(head, distance_m):
    """At 0.5 - 2 m the IIS head cannot fixate exactly (vertical disparity); the answer
    is a stationary point and a local minimum of the sum of squared stereographic
    residuals over the directions the joints move them in (finite differences on FK)."""
    solver = GazeSolver(head)
    q0 = np.array([0.5, 0.25, math.pi / 2, 0.52, 0.8, 0.75])
    root_T = camera_poses(head, q0)
    centre = root_T[:, :3, 3].mean(axis=0)
    ahead = root_T[:, :3, 2].sum(axis=0)
    point = centre + distance_m * ahead / np.linalg.norm(ahead)
    fix = solver.fixate(point)
    assert not fix.fixated and not fix.at_limits
    measured = fk_errors_rad(head, fix.q, point)
    np.testing.assert_allclose(fix.error_rad, measured, rtol=1e-12, atol=1e-15)
    assert np.all(measured > math.radians(0.5))  # the vertical disparity no joint removes

    free = [head.joint_names.index(n) for n in fix.free_joints]
    r = stereographic_residual(head, fix.q, free, point)
    x = fix.q[free]
    h = 1e-6
    jac = np.column_stack([(r(x + h * e) - r(x - h * e)) / (2 * h) for e in np.eye(len(x))])
    _, s, vt = np.linalg.svd(jac)
    kept = vt[s > 1e-2 * s[0]]  # the solver's rcond: the directions it optimises
    gradient = jac.T @ r(x)
    assert np.all(np.abs(kept @ gradient) < 1e-8 * (1 + np.linalg.norm(r(x)))), kept @ gradient
    # brute force: no step of up to 1e-3 rad along those directions lowers the cost
    cost = r(x) @ r(x)
    rng = np.random.default_rng(4)
    for _ in range(200):
        step = rng.normal(size=len(kept)) @ kept
        step *= rng.uniform(1e-5, 1e-3) / np.linalg.norm(step)
        trial = r(x + step)
        assert trial @ trial >= cost - 1e-15


def test_iis_head_fixates_exactly_where_it_can(head):
    """The IIS head fixates exactly only on a surface near 4 m: points built there by FK
    (vergence_left, pan, tilt chosen; vergence_right and both distances solved so the
    two optical axes meet, by SciPy on FK) are fixated to 1e-9 rad, although the valley
    towards the exact answer is nearly flat (pan against both vergences: the truncated
    solve alone stops at 1e-5 rad; solve_weak_directions follows the valley)."""
    from scipy.optimize import least_squares

    rng = np.random.default_rng(5)
    solver = GazeSolver(head)
    for _ in range(5):
        q = np.array(
            [
                0.5,
                0.25,
                math.pi / 2 + rng.uniform(-0.3, 0.3),
                0.52 + rng.uniform(-0.1, 0.1),
                0.81,
                0.76,
            ]
        )
        q[4] += rng.uniform(-0.1, 0.1)

        def gap(v, q=q):
            qq = q.copy()
            qq[5] = v[0]
            root_T = camera_poses(head, qq)
            c, d = root_T[:, :3, 3], root_T[:, :3, 2]
            return c[0] + v[1] * d[0] - c[1] - v[2] * d[1]

        fit = least_squares(gap, [0.76, 4.0, 4.0], xtol=1e-15, ftol=1e-15, gtol=1e-15)
        assert np.linalg.norm(fit.fun) < 1e-12 and 2.0 < fit.x[1] < 8.0
        q[5] = fit.x[0]
        point, _, _ = axes_intersection(camera_poses(head, q))
        fix = solver.fixate(point)
        measured = fk_errors_rad(head, fix.q, point)
        np.testing.assert_allclose(fix.error_rad, measured, rtol=1e-9, atol=1e-15)
        assert fix.fixated and np.all(measured < 1e-9), measured
    q = np.array([0.5, 0.25, math.pi / 2, 0.52, 0.81, 0.76])
    q[5] = least_squares(
        lambda v: _axes_gap(head, q, v), [0.76, 4.0, 4.0], xtol=1e-15, ftol=1e-15, gtol=1e-15
    ).x[0]
    point, _, _ = axes_intersection(camera_poses(head, q))
    fix = solver.fixate(point)
    assert fix.fixated and np.all(fk_errors_rad(head, fix.q, point) < 1e-6)


def _axes_gap(head, q, v):
    qq = q.copy()
    qq[5] = v[0]
    root_T = camera_poses(head, qq)
    c, d = root_T[:, :3, 3], root_T[:, :3, 2]
    return c[0] + v[1] * d[0] - c[1] - v[2] * d[1]


# -- closed form, limits, degenerate points -------------------------------------------


def test_centre_on_axis_closed_form_is_exact(pan_camera):
    """A camera whose optical centre is on the pan axis: the closed-form start is the
    answer, pan = atan2(y, x) by hand, with no Gauss-Newton step needed."""
    for angle in np.linspace(-0.95, 0.95, 9):
        point = [2.0 * math.cos(angle), 2.0 * math.sin(angle), 0.3]
        fix = fixate(pan_camera, point, cameras=("camera",))
        assert fix.iterations <= 2
        assert fix.q[0] == pytest.approx(angle, abs=1e-12)
        assert (
            fix.error_rad[0] < 1e-12
            and fk_errors_rad(pan_camera, fix.q, point, cameras=("camera",))[0] < 1e-12
        )


def test_pan_camera_closest_fixation_by_hand(pan_camera):
    """A point above the pan camera's horizon: best pan = atan2(y, x), remaining angle
    atan(h / r) (hand geometry)."""
    r, h, angle = 1.5, 0.4, 0.3
    fix = fixate(
        pan_camera, [r * math.cos(angle), r * math.sin(angle), 0.3 + h], cameras=("camera",)
    )
    assert fix.q[0] == pytest.approx(angle, abs=1e-9)
    assert fix.error_rad[0] == pytest.approx(math.atan2(h, r), abs=1e-12)
    assert not fix.fixated


@pytest.mark.parametrize("angle", [1.5, -2.0, 3.0, math.pi])
def test_beyond_pan_limit_gives_the_brute_force_closest(pan_camera, angle):
    """A point that needs pan beyond its range (up to exactly behind the start): pan at
    the limit, in at_limits, not fixated, error = the minimum over a grid of the range."""
    point = np.array([1.2 * math.cos(angle), 1.2 * math.sin(angle), 0.3 + 0.1])
    fix = fixate(pan_camera, point, cameras=("camera",))
    limit = math.copysign(1.0, math.sin(angle)) if angle != math.pi else None
    if limit is not None:
        assert fix.q[0] == limit
    assert fix.at_limits == ("pan",)
    assert not fix.fixated
    grid = np.linspace(-1.0, 1.0, 20001)
    poses = pan_camera.frame_poses(grid[:, None], "camera")
    brute = ray_errors_rad(poses, np.array([0.0, 0.0, 1.0]), point)
    assert fix.error_rad[0] == pytest.approx(brute.min(), abs=1e-9)
    assert fk_errors_rad(pan_camera, fix.q, point, cameras=("camera",))[0] == pytest.approx(
        fix.error_rad[0], abs=1e-12
    )


def test_point_at_a_camera_is_a_clear_error(ideal, pan_camera):
    with pytest.raises(RobotModelError, match="optical centre"):
        fixate(pan_camera, [0.0, 0.0, 0.3], cameras=("camera",))


def test_point_behind_the_head_gives_its_closest_fixation(ideal):
    """Behind the head (pan +-2 and vergence +-0.7 cannot turn the cameras round): no
    crash, joints within limits, the error the model reports is the one FK measures, and
    no grid configuration of pan and vergences does better."""
    point = np.array([-1.5, 0.0, 0.5])
    fix = fixate(ideal, point)
    lower, upper = ideal.joint_limits()
    assert np.all(fix.q >= lower) and np.all(fix.q <= upper)
    measured = fk_errors_rad(ideal, fix.q, point)
    np.testing.assert_allclose(fix.error_rad, measured, atol=1e-12)
    assert not fix.fixated
    # brute force: each camera's best over a grid of (pan, its vergence) at tilt 0
    pans = np.linspace(-2, 2, 401)
    vergences = np.linspace(-0.7, 0.7, 141)
    grid = np.array([[fix.q[0], p, 0.0, v, v] for p in pans for v in vergences])
    brute = np.stack(
        [
            ray_errors_rad(ideal.frame_poses(grid, c), np.array([0.0, 0.0, 1.0]), point)
            for c in CAMERAS
        ]
    )
    assert np.sum(fix.error_rad**2) <= np.min(np.sum(brute**2, axis=0)) + 1e-9


def test_bad_inputs_are_clear_errors(ideal, pan_camera):
    with pytest.raises(RobotModelError, match="point: expected 3 finite numbers"):
        fixate(ideal, [1.0, 2.0])
    with pytest.raises(RobotModelError, match="point: expected 3 finite numbers"):
        fixate(ideal, [1.0, np.nan, 2.0])
    with pytest.raises(RobotModelError, match=r"camera_rays: expected shape \(2, 3\)"):
        fixate(ideal, [2.0, 0.0, 0.5], camera_rays=[[0, 0, 1]])
    with pytest.raises(RobotModelError, match=r"'right_camera'.*does not point forward"):
        fixate(ideal, [2.0, 0.0, 0.5], camera_rays=[[0, 0, 1], [0.1, 0, -1]])
    with pytest.raises(RobotModelError, match="q_start: expected 5 finite values"):
        fixate(ideal, [2.0, 0.0, 0.5], q_start=np.zeros(4))
    with pytest.raises(UnknownFrameError, match="no frame 'nose'"):
        fixate(ideal, [2.0, 0.0, 0.5], cameras=("nose",))
    with pytest.raises(RobotModelError, match="no cameras given"):
        fixate(pan_camera, [2.0, 0.0, 0.3])  # no <kinfw cameras> hint
    with pytest.raises(RobotModelError, match="'camera_joint' is not movable"):
        fixate(pan_camera, [2.0, 0.0, 0.3], cameras=("camera",), free_joints=("camera_joint",))
    with pytest.raises(RobotModelError, match="'right_camera': none of the free joints"):
        fixate(ideal, [2.0, 0.0, 0.5], free_joints=("vergence_left",))


# -- CameraIntrinsics.rays ------------------------------------------------------------


def test_rays_invert_opencv_projection_with_strong_distortion():
    """Rays projected by cv2.projectPoints (independent) to pixels: rays(pixels) gives the
    rays back, and reprojecting them gives the pixels back. The rays stay within 45 deg
    of the axis, where this strong barrel distortion is still one-to-one."""
    import cv2

    camera = CameraIntrinsics(
        1280, 960, 700.0, 710.0, 650.0, 470.0, k1=-0.35, k2=0.15, p1=2e-3, p2=-1.5e-3, k3=-0.03
    )
    rng = np.random.default_rng(6)
    xy = rng.uniform(-1.0, 1.0, size=(2000, 2))
    xy = xy[np.linalg.norm(xy, axis=1) < 1.0]
    rays = np.column_stack([xy, np.ones(len(xy))])
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    uv, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), camera.matrix, camera.distortion)
    uv = uv.reshape(-1, 2)
    assert np.max(np.abs(uv - camera.project(rays))) < 1e-9  # same convention as OpenCV
    back = camera.rays(uv)
    np.testing.assert_allclose(back, rays, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(back, axis=1), 1.0, atol=1e-15)
    reprojected, _ = cv2.projectPoints(
        back, np.zeros(3), np.zeros(3), camera.matrix, camera.distortion
    )
    np.testing.assert_allclose(reprojected.reshape(-1, 2), uv, atol=1e-9)
    assert camera.rays(uv[:400].reshape(20, 20, 2)).shape == (20, 20, 3)


def test_rank_counts_the_directions_the_joints_turn_the_rays(ideal, pan_camera):
    """Fixation.rank: 3 for two cameras on one tilt (their elevations move together),
    which the ideal head still fixates exactly (its cameras are at one height, so the
    two elevations agree) and the IIS head cannot (the vertical disparity); 1 on a pan
    camera (one joint), 2 for one camera of the IIS head (its tilt and vergence)."""
    _, point = ideal_fixation_points(ideal, 1, seed=3)[0]
    fix = GazeSolver(ideal).fixate(point)
    assert fix.rank == 3 and fix.fixated
    head = load_robot(HEAD_URDF)
    fix = GazeSolver(head).fixate([0.754, 0.503, 0.897])
    assert fix.rank == 3 and not fix.fixated
    assert fixate(pan_camera, [2.0, 0.5, 0.3], cameras=("camera",)).rank == 1
    fix = GazeSolver(head, ("left_camera",)).fixate([0.754, 0.503, 0.897])
    assert fix.rank == 2 and fix.fixated


def test_held_joint_outside_its_limits_is_an_error():
    """The IIS head's x table held at 250 (mm typed as m) is refused before solving."""
    head = load_robot(HEAD_URDF)
    q = np.array([250.0, 0.25, 1.5, 0.5, 0.7, 0.7])
    with pytest.raises(RobotModelError, match=r"'x_table' is held .* 250000 mm"):
        fixate(head, [0.754, 0.503, 0.897], q_start=q)
