"""Hand-eye pose pairs checked against their own motion (A X = X B): good pairs pass,
real ones too (Tabb DS1 in metres); scalar-first quaternions on either side or both, mm
read as m, m read as mm and mixed units are refused, naming the cause
(kinfw.identification.checks.check_pose_pair_data)."""

import numpy as np
import pinocchio as pin
import pytest

from kinfw.geometry import quat_xyzw_from_matrix, transform_from_xyz_quat_xyzw
from kinfw.identification.checks import UnitError, check_pose_pair_data
from kinfw.observations import DatasetError
from tests.identification.handeye.test_handeye import _tabb_ds1
from tests.kinfw.cli.test_cli_handeye import _pairs


def _noisy(setup, seed=0, n=20):
    """Pose pairs with 1 mm per axis and 1 deg of sensor noise."""
    p = _pairs(seed, n, setup, noise=1e-3)
    rng = np.random.default_rng(seed)
    S = p.sensor_T_targets.copy()
    S[:, :3, :3] = S[:, :3, :3] @ np.stack(
        [pin.exp3(v) for v in rng.normal(size=(n, 3)) * np.radians(1.0) / np.sqrt(3)]
    )
    return p.base_T_hands, S


def _stored_scalar_first(T):
    """The poses a reader makes of quaternions stored (w, x, y, z) under qx..qw."""
    q = quat_xyzw_from_matrix(T[:, :3, :3])
    return transform_from_xyz_quat_xyzw(T[:, :3, 3], q[:, [3, 0, 1, 2]])


@pytest.mark.parametrize("setup", ["eye-in-hand", "eye-to-hand"])
def test_good_pairs_pass_with_their_motion_and_view_distance(setup):
    H, S = _noisy(setup)
    d = check_pose_pair_data(H, S, setup=setup)
    assert d.motion_score < 0.05 and d.reordered == ()
    i, j = np.triu_indices(len(H), k=1)
    assert d.n_pairs == len(i)
    assert d.hand_motion_m == pytest.approx(
        np.median(np.linalg.norm(H[j, :3, 3] - H[i, :3, 3], axis=1))
    )
    assert d.view_distance_m == pytest.approx(np.median(np.linalg.norm(S[:, :3, 3], axis=1)))


def test_real_pairs_pass_in_metres_and_are_refused_in_mm_read_as_m():
    """Tabb DS1 (88 poses, a real robot and camera), stored in mm."""
    base_T_hands, cam_T_worlds, _ = _tabb_ds1()
    H, S = base_T_hands.copy(), cam_T_worlds.copy()
    H[:, :3, 3] *= 1e-3
    S[:, :3, 3] *= 1e-3
    d = check_pose_pair_data(H, S)
    assert d.motion_score < 0.05 and 0.5 < d.hand_motion_m < 1.0
    with pytest.raises(UnitError, match=r"^tabb \(read in m\): positions look like millimetres"):
        check_pose_pair_data(base_T_hands, cam_T_worlds, source="tabb")


@pytest.mark.parametrize("setup", ["eye-in-hand", "eye-to-hand"])
@pytest.mark.parametrize("sides", [("hand",), ("sensor",), ("hand", "sensor")])
def test_scalar_first_quaternions_are_refused_naming_the_side(setup, sides):
    H, S = _noisy(setup, seed=1)
    H = _stored_scalar_first(H) if "hand" in sides else H
    S = _stored_scalar_first(S) if "sensor" in sides else S
    named = " and ".join(sides)
    with pytest.raises(
        DatasetError, match=rf"^p.csv: quaternions look scalar-first .*\({named} poses\)"
    ):
        check_pose_pair_data(H, S, setup=setup, source="p.csv")
    # matrices (no quaternions to reorder): no reading is tried, nothing is refused
    assert check_pose_pair_data(H, S, setup=setup, quaternions=()).reordered == ()


@pytest.mark.parametrize(
    ("hand", "sensor", "match"),
    [
        (1e-3, 1e-3, r"positions look like metres read as millimetres .*--unit m\)"),
        (1e3, 1.0, r"the hand positions look like millimetres read as metres, the others not"),
        (1.0, 1e3, r"the sensor positions look like millimetres read as metres, the others not"),
    ],
)
def test_lengths_in_another_unit_are_refused(hand, sensor, match):
    H, S = _noisy("eye-in-hand", seed=2)
    H, S = H.copy(), S.copy()
    H[:, :3, 3] *= hand
    S[:, :3, 3] *= sensor
    with pytest.raises(UnitError, match=match) as info:
        check_pose_pair_data(H, S, source="p.csv", quaternions=())
    assert len(str(info.value).splitlines()[0]) < 200
