"""Cameras anywhere: the URDF as users write it (issue 24, item 3).

Setups on the 6R arm of tests/robots.py, each with its cameras' optical frames as URDF
links on fixed joints:

- ``eye_to_hand``: a static camera (``camera_link`` on a fixed joint to the root) and a
  board on the flange (``target_frame``);
- ``stereo``: a static stereo pair (two optical frames 12 cm apart on one fixed mount)
  sharing one board on the flange;
- ``eye_in_hand``: a camera on the flange (its own link) and a board fixed in the world;
- ``wrist``: a camera on ``l5`` (not the end of the chain) and a board fixed in the world.

Truths: the true robot's Pinocchio forward kinematics at configurations the fit never
saw (``camera_T_board`` of every camera), exact recovery from noise-free pixels through
the whole calibration (hand-eye, refinement, URDF export), and the known pixel noise.
"""

from __future__ import annotations

import numpy as np
import pytest

from kinfw.camera import CameraIntrinsics
from kinfw.geometry import inverse_transform, transform_from_rotation_translation
from kinfw.identification import identify, refine
from kinfw.identification.handeye import calibrate_cameras
from kinfw.identification.problem import build_problem
from kinfw.model import Robot, geometry_from_cpc, load_robot
from kinfw.observations import DatasetError
from kinfw.simulation import perturb_robot, simulate_pixels
from kinfw.urdf import export_urdf
from kinfw.verification.evaluation import pose_discrepancy
from tests.robots import ARM_6R

NAMES = ("j1", "j2", "j3", "j4", "j5", "j6")
Q0 = np.array([0.3, -0.4, 0.9, 0.2, 0.7, -0.3])
CAMERA = CameraIntrinsics(640, 480, 600.0, 600.0, 319.5, 239.5, name="simulated")
BOARD_P = np.array([[0.03 * i - 0.105, 0.03 * j - 0.06, 0.0] for j in range(5) for i in range(8)])
#: optical frame (z forward, x right, y down) looking along the root's -x
_LOOK_BACK = 'rpy="-1.5707963267948966 0 1.5707963267948966"'

SETUPS = {
    "eye_to_hand": (
        f"""
  <joint name="camera_joint" type="fixed">
    <parent link="world"/><child link="camera_link"/>
    <origin xyz="1.3 0.0 0.4" {_LOOK_BACK}/>
  </joint>
  <link name="camera_link"/>""",
        ("camera_link",),
        "flange",
    ),
    "stereo": (
        f"""
  <joint name="stereo_joint" type="fixed">
    <parent link="world"/><child link="stereo_link"/>
    <origin xyz="1.3 0.0 0.4" {_LOOK_BACK}/>
  </joint>
  <link name="stereo_link"/>
  <joint name="left_joint" type="fixed">
    <parent link="stereo_link"/><child link="left_optical"/>
    <origin xyz="-0.06 0 0" rpy="0 0.05 0"/>
  </joint>
  <link name="left_optical"/>
  <joint name="right_joint" type="fixed">
    <parent link="stereo_link"/><child link="right_optical"/>
    <origin xyz="0.06 0 0" rpy="0 -0.05 0"/>
  </joint>
  <link name="right_optical"/>""",
        ("left_optical", "right_optical"),
        "flange",
    ),
    "eye_in_hand": (
        """
  <joint name="hand_camera_joint" type="fixed">
    <parent link="flange"/><child link="hand_camera"/>
    <origin xyz="0.03 -0.05 0.08" rpy="0.1 -0.2 0.3"/>
  </joint>
  <link name="hand_camera"/>""",
        ("hand_camera",),
        None,
    ),
    "wrist": (
        """
  <joint name="wrist_camera_joint" type="fixed">
    <parent link="l5"/><child link="wrist_camera"/>
    <origin xyz="0.05 0.02 0.03" rpy="0.1 -0.2 0.3"/>
  </joint>
  <link name="wrist_camera"/>""",
        ("wrist_camera",),
        None,
    ),
}


def setup_urdf(name: str) -> str:
    """The 6R arm with the setup's camera links."""
    return ARM_6R.replace("</robot>", SETUPS[name][0] + "\n</robot>")


def _board_pose(robot: Robot, cameras: tuple[str, ...], target_frame: str | None):
    """The board's pose (in ``target_frame``, or the world), facing the first camera at
    Q0: 5 cm off the flange, or 0.5 m in front of a moving camera."""
    w_T_c = robot.frame_poses(Q0, cameras[0], NAMES)
    if target_frame is None:
        return w_T_c @ transform_from_rotation_translation(np.eye(3), [0.0, 0.0, 0.5])
    f_T_b = inverse_transform(robot.frame_poses(Q0, target_frame, NAMES)) @ w_T_c
    f_T_b[:3, 3] = [0.0, 0.0, 0.05]
    return f_T_b


def scene(name: str, n: int, seed: int, sigma_px: float = 0.0, n_test: int = 0):
    """(nominal, truth, board pose, training data, held-out data) of a setup: the truth
    a perturbed nominal (2 mm / 0.5 deg), configurations around Q0 that see the board;
    the held-out images are of other configurations, from the same truth and board."""
    _, cameras, target_frame = SETUPS[name]
    nominal = load_robot(setup_urdf(name))
    rng = np.random.default_rng(seed)
    truth = load_robot(perturb_robot(nominal, rng))
    board = _board_pose(truth, cameras, target_frame)
    qs = Q0 + rng.uniform(-0.4, 0.4, size=(20 * (n + n_test), 6))
    data, _ = simulate_pixels(
        truth,
        qs,
        NAMES,
        cameras=dict.fromkeys(cameras, CAMERA),
        board_p=BOARD_P,
        w_T_board=board,
        rng=rng,
        sigma_px=sigma_px,
        target_frame=target_frame,
    )
    assert data.n_samples >= n + n_test
    held_out = data.subset(range(n, n + n_test)) if n_test else None
    return nominal, truth, board, data.subset(range(n)), held_out


def camera_T_boards(robot: Robot, name: str, board, qs) -> dict[str, np.ndarray]:
    """Each camera's view of the board at ``qs`` under ``robot`` (Pinocchio FK)."""
    _, cameras, target_frame = SETUPS[name]
    w_T_b = board if target_frame is None else robot.frame_poses(qs, target_frame, NAMES) @ board
    return {c: inverse_transform(robot.frame_poses(qs, c, NAMES)) @ w_T_b for c in cameras}


Q_TEST = Q0 + np.random.default_rng(99).uniform(-0.4, 0.4, size=(50, 6))


def _fitted_board(calibration) -> np.ndarray:
    return {(u.kind, u.name): u.value for u in calibration.refined.unknowns}[("target", "board")]


@pytest.mark.slow
@pytest.mark.parametrize("name", list(SETUPS))
def test_noise_free_pixels_recover_every_setup_exactly(name):
    nominal, truth, board, data, _ = scene(name, 30, seed=4)
    calibration = identify(nominal, data)
    assert calibration.refined.converged
    calibrated = load_robot(calibration.urdf_xml)  # the exported URDF, read back
    fitted = camera_T_boards(calibrated, name, _fitted_board(calibration), Q_TEST)
    true = camera_T_boards(truth, name, board, Q_TEST)
    start = camera_T_boards(nominal, name, board, Q_TEST)
    for camera in true:
        dp, dr = pose_discrepancy(fitted[camera], true[camera])
        assert dp < 1e-9 and dr < 1e-9, (camera, dp, dr)
        assert pose_discrepancy(start[camera], true[camera])[0] > 1e-3  # the nominal was off


def _pixels(robot: Robot, name: str, board, qs) -> dict[str, np.ndarray]:
    """Each camera's pixels (n, k, 2) of the board's points at ``qs`` (OpenCV)."""
    import cv2

    out = {}
    for camera, c_T_b in camera_T_boards(robot, name, board, qs).items():
        uv = []
        for T in c_T_b:
            rvec, _ = cv2.Rodrigues(T[:3, :3])
            p, _ = cv2.projectPoints(BOARD_P, rvec, T[:3, 3], CAMERA.matrix, CAMERA.distortion)
            uv.append(p.reshape(-1, 2))
        out[camera] = np.array(uv)
    return out


@pytest.mark.slow
@pytest.mark.parametrize("name", ["eye_to_hand", "stereo"])
def test_noisy_pixels_predict_within_the_noise(name):
    sigma = 0.5
    nominal, truth, board, data, _ = scene(name, 40, seed=5, sigma_px=sigma)
    calibration = identify(nominal, data)
    refined = calibration.refined
    sigma_hat = dict(refined.noise.sigmas)["pixel"]
    assert 0.9 * sigma < sigma_hat < 1.1 * sigma  # the estimated noise is the simulated one
    calibrated = load_robot(calibration.urdf_xml)
    fitted = _pixels(calibrated, name, _fitted_board(calibration), Q_TEST)
    true = _pixels(truth, name, board, Q_TEST)
    # the prediction error of a least-squares fit with p free parameters from n residual
    # rows of noise sigma has mean square sigma^2 p / n per row on average (the fitted
    # model's covariance); allow 3 times its RMS for the spread of the test poses
    p = refined.identifiability.rank
    n = sum(r.component("pixel").size for r in refined.residuals)
    bound = 3 * sigma * np.sqrt(p / n)
    for camera in true:
        err = np.sqrt(np.mean(np.sum((fitted[camera] - true[camera]) ** 2, axis=-1) / 2))
        assert err < bound, (camera, err, bound)
        nominal_err = np.sqrt(
            np.mean(np.sum((_pixels(nominal, name, board, Q_TEST)[camera] - true[camera]) ** 2, -1))
        )
        assert nominal_err > 10 * bound


def test_a_static_camera_and_a_world_board_are_refused_with_the_fix():
    nominal, _, _, data, _ = scene("eye_to_hand", 8, seed=6)
    (g,) = data.groups("pixels")
    from dataclasses import replace

    wrong = data.with_groups([replace(g, target_frame=None)])  # "the board is in the world"
    with pytest.raises(DatasetError, match=r'does not move relative to the camera.*"target_frame"'):
        calibrate_cameras(nominal, wrong)


def test_a_head_camera_seeing_a_board_on_the_hand_is_a_target_on_a_frame():
    """FIGAROH's real TIAGo eye-hand session (tests/data/tiago_figaroh): the head camera
    sees a board on the hand. Read as ``pose`` observations measured in the camera with a
    marker on ``arm_7_link`` (tests/kinfw/observations/test_measured_in_robot.py), or as
    ``target`` observations with ``target_frame = arm_7_link``: one model, so one fit (the
    same residuals and the same board pose in arm_7_link), torso held out of both."""
    from kinfw.identification import refine
    from kinfw.measurements import measurements_from_figaroh_csv, observed_joints
    from kinfw.observations import TargetObservations
    from tests.erd import urdf_path
    from tests.paths import DATA

    tiago = load_robot(urdf_path("tiago_description/robots/tiago_no_hand.urdf"))
    csv = DATA / "tiago_figaroh" / "eye_hand_calibration_recorded_data_48c_hey5_12_test1.csv"
    poses = measurements_from_figaroh_csv(
        csv, robot=tiago, frame="arm_7_link", measured_in="xtion_rgb_optical_frame"
    )
    (g,) = poses.poses
    targets = poses.with_groups(
        [
            TargetObservations(
                camera="xtion_rgb_optical_frame",
                sample=g.sample,
                camera_T_target=g.meas_T_frame,
                target="board",
                target_frame="arm_7_link",
            )
        ]
    )
    a = refine(tiago, poses, parameters="frames")
    b = refine(tiago, targets, parameters="frames")
    np.testing.assert_allclose(
        b.residuals[0].component("position"), a.residuals[0].component("position"), atol=1e-9
    )
    found_a = {(u.kind, u.name): u.value for u in a.unknowns}
    found_b = {(u.kind, u.name): u.value for u in b.unknowns}
    np.testing.assert_allclose(  # to the solver's convergence on real (noisy) data
        found_b[("target", "board")], found_a[("marker", "marker1")], rtol=0, atol=1e-7
    )
    # the torso moves camera and board alike: not observed, in either reading
    assert observed_joints(targets, tiago) == observed_joints(poses, tiago)
    assert "torso_lift_joint" not in observed_joints(targets, tiago)


def _exported_pixels(nominal: Robot, name: str, problem, x, qs) -> np.ndarray:
    """Every camera's pixels of the board at ``qs`` for the problem's parameters ``x``,
    through the exported URDF, Pinocchio and OpenCV (not the CasADi model), flattened."""
    robot = load_robot(export_urdf(nominal, geometry_from_cpc(problem.model_at(x))).urdf_xml)
    board = {(u.kind, u.name): u.value for u in problem.unknowns_at(x)}["target", "board"]
    return np.concatenate([p.ravel() for p in _pixels(robot, name, board, qs).values()])


@pytest.mark.slow
@pytest.mark.parametrize("name", ["eye_in_hand", "eye_to_hand"])
def test_noise_free_pixels_move_the_export_only_along_determined_directions(name):
    """Noise-free images (the noise estimate at its floor) leave the world motion of the
    robot with its board free: the exported URDF differs from the nominal only along
    directions the pixels determine. The null space of the pixels' Jacobian, by central
    differences through the exported URDF (Pinocchio, OpenCV's projection), holds none of
    the estimate (the robot's chart coordinates in m and rad, the board's weighted by
    UNKNOWN_WEIGHT), as for plane contacts. Before the rounding slack of the return to the
    start, 3.5-5.6 mm of it was left there (``j1`` exported moved by millimetres)."""
    from kinfw.identification.problem._refine import UNKNOWN_WEIGHT

    nominal, _, _, data, _ = scene(name, 30, seed=3)
    result = refine(nominal, data)
    assert dict(result.noise.sigmas)["pixel"] < 1e-6  # noise-free: at the floor
    problem = build_problem(nominal, data)
    assert problem.names == result.parameter_names
    cols = np.flatnonzero(result.free)
    robot = np.concatenate([np.full(b.size, b in problem.robot_blocks) for b in problem.blocks])
    scale = np.where(robot[cols], 1.0, UNKNOWN_WEIGHT)
    h, x, qs = 1e-6, result.estimate, data.qs
    columns = [
        _exported_pixels(nominal, name, problem, x + h * e, qs)
        - _exported_pixels(nominal, name, problem, x - h * e, qs)
        for e in np.eye(len(x))[cols]
    ]
    J = np.stack(columns, axis=1) / (2 * h) / scale
    c = np.linalg.norm(J, axis=0)
    _, s, Vt = np.linalg.svd(J / c, full_matrices=False)
    null = Vt[s < 1e-7 * s[0]]
    assert len(null) == 6  # the world motion
    Q = np.linalg.qr((null / c).T)[0]
    y = scale * x[cols]
    assert np.linalg.norm(y) > 1e-3  # the fit moved
    assert np.linalg.norm(Q.T @ y) < 1e-9 * np.linalg.norm(y)
