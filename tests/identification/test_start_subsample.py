"""Start values from a well-spread subsample (the hand-eye stage before a refinement,
a pixel group's target start): the refinement converges to the same fit as from the
start on every view."""

from __future__ import annotations

import re

import numpy as np
import pytest

import kinfw.identification._pipeline as pipeline
import kinfw.observations._pixels as pixels_module
from kinfw.identification import identify
from kinfw.model import builtin_head_urdf, load_robot
from kinfw.observations import evenly_spaced
from kinfw.simulation import simulate_measurements

_NUMBER = re.compile(r"-?\d+\.\d+(?:e-?\d+)?")


def _numbers(xml: str) -> np.ndarray:
    return np.array([float(x) for x in _NUMBER.findall(xml)])


def test_evenly_spaced_keeps_the_ends_and_spreads_the_rest():
    np.testing.assert_array_equal(evenly_spaced(10, 4), [0, 3, 6, 9])
    np.testing.assert_array_equal(evenly_spaced(7, 3), [0, 3, 6])
    np.testing.assert_array_equal(evenly_spaced(3, 5), [0, 1, 2])
    np.testing.assert_array_equal(evenly_spaced(5, 1), [0])
    for m in range(1, 60):
        for n in range(2, 60):
            k = evenly_spaced(m, n)
            assert len(k) == min(m, n) and k[0] == 0 and k[-1] == m - 1
            assert (np.diff(k) >= 1).all()
            if m > n:  # gaps of floor or ceil of the even spacing
                assert np.ptp(np.diff(k)) <= 1


@pytest.fixture(scope="module")
def robot():
    return load_robot(builtin_head_urdf())


@pytest.mark.slow
@pytest.mark.parametrize("pixels", [False, True])
def test_a_subsampled_start_converges_to_the_fit_from_every_view(robot, pixels, monkeypatch):
    sim = simulate_measurements(
        robot,
        stages=(1, 2),
        stage2_samples=80,
        pixels=pixels,
        board="chessboard:4x3:0.08" if pixels else None,
        seed=3,
    )
    every = identify(robot, sim.data)
    monkeypatch.setattr(pipeline, "HANDEYE_START_VIEWS", 12)
    monkeypatch.setattr(pixels_module, "START_IMAGES", 10)
    subsampled = identify(robot, sim.data)
    full_views = [c.n_views for c in every.cameras.cameras]
    start_views = [c.n_views for c in subsampled.cameras.cameras]
    # each camera's own 12 picks, and those of the other camera it also saw
    assert all(12 <= s <= 24 and s < f for s, f in zip(start_views, full_views, strict=True))
    a, b = _numbers(every.urdf_xml), _numbers(subsampled.urdf_xml)
    assert len(a) == len(b)
    np.testing.assert_allclose(b, a, rtol=0, atol=1e-9)
    assert every.refined.cost == pytest.approx(subsampled.refined.cost, rel=1e-10)


def test_the_pixel_target_start_uses_every_image_up_to_the_limit(monkeypatch):
    sim = simulate_measurements(
        load_robot(builtin_head_urdf()),
        stages=(1, 2),
        stage2_samples=30,
        pixels=True,
        board="chessboard:4x3:0.08",
        seed=4,
    )
    group = sim.data.groups("pixels")[0]
    n_images = len(group.images()[0])
    assert pixels_module.start_images(group) is group
    monkeypatch.setattr(pixels_module, "START_IMAGES", 5)
    fewer = pixels_module.start_images(group)
    samples, rows = fewer.images()
    all_samples, all_rows = group.images()
    picked = evenly_spaced(n_images, 5)
    np.testing.assert_array_equal(samples, all_samples[picked])
    for r, k in zip(rows, picked, strict=True):  # the images' points, unchanged
        np.testing.assert_array_equal(fewer.uv[r], group.uv[all_rows[k]])
