"""calibrate_pose_pairs counts a pair recorded twice once: the covariance of the pairs
once (to rounding) and one warning naming the copies; kept on request, every sigma
shrinks by 1/sqrt(2)."""

import warnings

import numpy as np
import pytest

from kinfw.identification.handeye import calibrate_pose_pairs
from tests.kinfw.cli.test_cli_handeye import _pairs


def _fit(hands, views, **options):
    return calibrate_pose_pairs(
        base_T_hands=hands, camera_T_targets=views, setup="eye-in-hand", **options
    )[0]


def test_pairs_twice_give_the_covariance_of_once_and_one_warning():
    p = _pairs(7, 12, noise=1e-3)
    once = _fit(p.base_T_hands, p.sensor_T_targets)
    hands, views = np.concatenate([p.base_T_hands] * 2), np.concatenate([p.sensor_T_targets] * 2)
    with pytest.warns(UserWarning, match=r"12 of the 24 pose pairs repeat .*: 12 \(= 0\), 13") as w:
        twice = _fit(hands, views)
    assert len(w) == 1
    np.testing.assert_allclose(twice.covariance, once.covariance, rtol=1e-9, atol=1e-18)
    assert twice.n_samples == 12
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        kept = _fit(hands, views, keep_duplicates=True)
    ratio = kept.sigma_translation_m / once.sigma_translation_m
    np.testing.assert_allclose(ratio, 1 / np.sqrt(2), rtol=0.05)
    assert kept.n_samples == 24
