"""A camera's target of the wrong size is named: the scale factor of its poses'
translations against the robot's lengths (kinfw.identification.checks.target_scale)."""

import warnings
from dataclasses import replace

import numpy as np
import pytest

from kinfw.identification.checks import SCALE_FLOOR, target_scale
from kinfw.model import load_robot
from kinfw.simulation import perturb_robot, random_configurations, simulate_at
from tests.robots import ARM_6R

#: The ChArUco square the images were detected with, and the board's true one (m).
GIVEN, TRUE = 0.043, 0.034


@pytest.fixture(scope="module")
def eye_in_hand():
    """A camera on the 6R arm's flange (2 mm / 0.5 deg off the nominal) seeing a fixed
    board at 30 configurations, 0.2 mm / 2 mrad of noise; and the same poses as a board
    detected with the wrong square gives them (every translation GIVEN / TRUE times)."""
    nominal = load_robot(ARM_6R)
    rng = np.random.default_rng(3)
    truth = load_robot(perturb_robot(nominal, rng, origin_mm=2.0, origin_deg=0.5))
    names = nominal.joint_names
    qs = random_configurations(*nominal.joint_limits(names), 30, rng, fraction=0.8)
    data = simulate_at(truth, qs, names, cameras=("flange",), rng=rng, noise_m=2e-4, noise_rad=2e-3)
    (group,) = data.groups("target")
    T = group.camera_T_target.copy()
    T[:, :3, 3] *= GIVEN / TRUE
    return nominal, truth, data, data.with_groups([replace(group, camera_T_target=T)])


def test_the_scale_is_the_boards_against_the_truth_and_near_one_against_the_nominal(
    eye_in_hand,
):
    """Through the true robot the factor is TRUE / GIVEN (0.791) to 1e-3 on the wrong
    poses and 1 on the right ones (sigma ~1e-4: the noise); through the nominal, whose
    errors bias it, within SCALE_FLOOR of those and 4 sigma of its own uncertainty."""
    nominal, truth, right, wrong = eye_in_hand
    for data, expected in ((right, 1.0), (wrong, TRUE / GIVEN)):
        (exact,) = target_scale(truth, truth, data)
        assert (exact.camera, exact.target, exact.n) == ("flange", "target", 30)
        assert abs(exact.scale - expected) < 1e-3 and exact.sigma < 1e-3
        (rough,) = target_scale(nominal, nominal, data)
        assert abs(rough.scale - expected) < min(SCALE_FLOOR, 4 * rough.sigma + 1e-3)
    assert not target_scale(nominal, nominal, right)[0].off
    assert target_scale(nominal, nominal, wrong)[0].off


@pytest.mark.slow
def test_calibrate_names_a_board_of_the_wrong_size(eye_in_hand):
    """The default calibration of the wrong poses fits them (the mount absorbs the
    factor) and warns once, naming the camera, the target and the factor (0.79); the
    right poses calibrate in silence about the scale."""
    from kinfw.verification.reporting import calibrate_and_report

    nominal, _, right, wrong = eye_in_hand
    with pytest.warns(UserWarning, match=r"target 'target' seen by 'flange' looks 0\.7\d+ times"):
        calibrate_and_report(nominal, wrong)
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        calibrate_and_report(nominal, right)
    assert not [w for w in said if "stated size" in str(w.message)]


def test_hand_eye_pose_pairs_give_the_boards_scale():
    """Noise-free eye-in-hand pose pairs (20 random hand poses, a mount and a target
    pose): solve_axxb fits the poses of the wrong board as well as the right ones (it
    absorbs the factor), and translation_scale with its mount gives TRUE / GIVEN and 1 to
    1e-9, with sigma at rounding."""
    from scipy.spatial.transform import Rotation

    from kinfw.geometry import inverse_transform, transform_from_rotation_translation
    from kinfw.identification.handeye import solve_axxb, translation_scale

    rng = np.random.default_rng(7)

    def pose(n=None, length=0.5):
        R = Rotation.random(n, random_state=rng).as_matrix()
        return transform_from_rotation_translation(
            R, rng.uniform(-length, length, (*R.shape[:-2], 3))
        )

    base_T_hands, hand_T_camera, base_T_target = pose(20), pose(length=0.1), pose()
    camera_T_targets = inverse_transform(base_T_hands @ hand_T_camera) @ base_T_target
    for factor in (1.0, GIVEN / TRUE):
        measured = camera_T_targets.copy()
        measured[:, :3, 3] *= factor
        fit = solve_axxb(base_T_hands=base_T_hands, camera_T_targets=measured)
        scale, sigma = translation_scale(
            base_T_links=base_T_hands,
            base_R_cameras=base_T_hands[:, :3, :3] @ fit.hand_T_camera[:3, :3],
            camera_p_targets=measured[:, :3, 3],
        )
        assert abs(scale - 1.0 / factor) < 1e-9 and sigma < 1e-9


@pytest.mark.parametrize("name", ["eye_in_hand", "eye_to_hand"])
def test_image_points_of_a_board_of_the_wrong_size_are_named(name):
    """Images (0.3 px) of the 6R arm's board, a camera on the hand or beside the arm
    (the board then on the flange), the board's points given GIVEN / TRUE times their
    size (the images are the true board's): their PnP poses' factor is TRUE / GIVEN
    within SCALE_FLOOR through the nominal (its errors: 1.7 % beside the arm, where the
    camera is 1.3 m from a board 5 cm off the flange), named with the points' spacing as
    given (30 mm on the true board) and the one it suggests; the true points are not
    named."""
    from tests.kinfw.observations.test_cameras_anywhere import scene

    nominal, _, _, data, _ = scene(name, 20, seed=3, sigma_px=0.3)
    (group,) = data.groups("pixels")
    wrong = data.with_groups([replace(group, target_p=group.target_p * GIVEN / TRUE)])
    (right_scale,) = target_scale(nominal, nominal, data)
    assert not right_scale.off and abs(right_scale.scale - 1.0) < SCALE_FLOOR
    (found,) = target_scale(nominal, nominal, wrong)
    assert found.off and abs(found.scale - TRUE / GIVEN) < SCALE_FLOOR
    assert abs(found.spacing_m - 0.03 * GIVEN / TRUE) < 1e-9
    assert "its points 0.0379 m apart given, 0.03 m?" in found.message()
