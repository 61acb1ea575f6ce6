"""Samples and pose pairs recorded twice: found with the earlier copy they repeat, to
1e-12 relative; a sample whose joint values repeat but whose observation differs is no
duplicate (kinfw.measurements.duplicate_samples, drop_duplicate_samples, duplicate_pairs)."""

import warnings
from dataclasses import replace

import numpy as np
import pytest

from kinfw.measurements import (
    PosePairs,
    drop_duplicate_pairs,
    drop_duplicate_samples,
    duplicate_pairs,
    duplicate_samples,
)
from kinfw.model import load_robot
from kinfw.simulation import random_configurations, simulate_at
from tests.robots import ARM_6R


def _data(n=12, seed=0):
    robot = load_robot(ARM_6R)
    rng = np.random.default_rng(seed)
    lower, upper = robot.joint_limits(robot.joint_names)
    qs = random_configurations(lower, upper, n, rng, fraction=0.8)
    return simulate_at(robot, qs, robot.joint_names, frames=("flange",), rng=rng, noise_m=1e-4)


def test_repeated_samples_are_named_with_the_sample_they_repeat():
    data = _data().subset([0, 1, 2, 1, 3, 0, 0])
    np.testing.assert_array_equal(duplicate_samples(data), [[3, 1], [5, 0], [6, 0]])
    assert duplicate_samples(_data()).shape == (0, 2)


def test_equal_joint_values_with_another_observation_are_no_duplicate():
    """The same configuration measured twice (the noise differs): two measurements."""
    data = _data().subset([0, 1, 2, 0])
    (g,) = data.poses
    T = g.meas_T_frame.copy()
    T[3, 0, 3] *= 1 + 1e-9  # sample 3's x differs from sample 0's by 1e-9 relative
    assert duplicate_samples(replace(data, poses=(replace(g, meas_T_frame=T),))).shape == (0, 2)
    T[3, 0, 3] = g.meas_T_frame[3, 0, 3] * (1 + 1e-14)  # rounding: still one measurement
    found = duplicate_samples(replace(data, poses=(replace(g, meas_T_frame=T),)))
    np.testing.assert_array_equal(found, [[3, 0]])


def test_a_joint_held_still_does_not_hide_or_fake_duplicates():
    """Every sample shares joint j1's value (a one-joint-at-a-time protocol): only the
    copies are found."""
    data = _data(n=30)
    data = replace(data, qs=np.column_stack([np.zeros(30), data.qs[:, 1:]]))
    twice = data.subset(np.r_[np.arange(30), np.arange(5)])
    np.testing.assert_array_equal(duplicate_samples(twice)[:, 1], np.arange(5))
    np.testing.assert_array_equal(duplicate_samples(twice)[:, 0], 30 + np.arange(5))


def test_dropping_warns_once_with_a_few_indices_and_the_rest_counted():
    data = _data()
    twice = data.subset(np.repeat(np.arange(12), 2))
    with pytest.warns(UserWarning) as record:
        once = drop_duplicate_samples(twice)
    (w,) = record
    first = str(w.message).splitlines()[0]
    assert len(first) < 200, first
    assert "12 of the 24 samples repeat an earlier one: 1 (= 0), 3 (= 2), 5 (= 4)" in first
    assert "and 7 more" in first and "--keep-duplicates" in str(w.message)
    np.testing.assert_array_equal(once.qs, data.qs)
    np.testing.assert_array_equal(once.poses[0].meas_T_frame, data.poses[0].meas_T_frame)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert drop_duplicate_samples(data) is data


def test_repeated_pose_pairs_are_found_and_dropped():
    data = _data()
    hands = data.poses[0].meas_T_frame
    sensors = np.linalg.inv(hands)
    pairs = PosePairs(hands[[0, 1, 2, 3, 1]], sensors[[0, 1, 2, 3, 1]], "p.csv")
    np.testing.assert_array_equal(duplicate_pairs(pairs), [[4, 1]])
    other = PosePairs(hands[[0, 1, 2, 3, 1]], sensors[[0, 1, 2, 3, 2]], "p.csv")
    assert duplicate_pairs(other).shape == (0, 2)  # same hand pose, another view
    with pytest.warns(UserWarning, match=r"^p.csv: 1 of the 5 pose pairs repeat .*: 4 \(= 1\);"):
        kept = drop_duplicate_pairs(pairs)
    np.testing.assert_array_equal(kept.base_T_hands, hands[:4])


def test_repeated_images_are_duplicates_and_another_image_of_the_board_is_not():
    """Pixels observations (several corners per sample): an image recorded twice is
    found; the same configuration's image with one corner moved by 1e-6 px is not."""
    from tests.kinfw.observations.test_cameras_anywhere import scene

    *_, data, _ = scene("eye_in_hand", 6, seed=0)
    twice = data.subset([0, 1, 2, 3, 1, 0])
    np.testing.assert_array_equal(duplicate_samples(twice), [[4, 1], [5, 0]])
    (g,) = twice.groups("pixels")
    uv = g.uv.copy()
    uv[np.flatnonzero(g.sample == 5)[0], 0] += 1e-6
    moved = twice.with_groups([replace(g, uv=uv)])
    np.testing.assert_array_equal(duplicate_samples(moved), [[4, 1]])
