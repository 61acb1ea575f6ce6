"""The one rigid-frame chart: numpy against CasADi, inverse round trip, hand geometry."""

import casadi as ca
import numpy as np

from kinfw.geometry import (
    cayley_rotation,
    chart_from_rigid,
    matrix_from_rotation_vector,
    rigid_from_chart,
    rigid_from_chart_casadi,
    transform_from_rotation_translation,
)


def _start(rng):
    axis = rng.normal(size=3)
    return transform_from_rotation_translation(
        matrix_from_rotation_vector(axis / np.linalg.norm(axis) * rng.uniform(-3, 3)),
        rng.normal(size=3),
    )


def test_numpy_matches_casadi():
    rng = np.random.default_rng(0)
    d_sym = ca.SX.sym("d", 6)
    for _ in range(20):
        T0, d = _start(rng), rng.normal(size=6)
        f = ca.Function("T", [d_sym], [rigid_from_chart_casadi(T0, d_sym)])
        np.testing.assert_allclose(np.array(f(d)), rigid_from_chart(T0, d), atol=1e-15, rtol=0)


def test_batched_equals_one_by_one():
    rng = np.random.default_rng(1)
    T0 = np.stack([_start(rng) for _ in range(5)])
    d = rng.normal(size=(5, 6))
    batched = rigid_from_chart(T0, d)
    for k in range(5):
        np.testing.assert_array_equal(batched[k], rigid_from_chart(T0[k], d[k]))


def test_inverse_round_trip():
    rng = np.random.default_rng(2)
    T0 = np.stack([_start(rng) for _ in range(50)])
    d = rng.normal(size=(50, 6))  # |d[:3]| < pi well inside the chart's domain
    np.testing.assert_allclose(chart_from_rigid(T0, rigid_from_chart(T0, d)), d, atol=1e-12)


def test_rotation_part_is_a_turn_of_twice_the_gibbs_angle():
    # hand geometry: cayley(tan(theta/2) u) is the rotation by theta about u
    u = np.array([1.0, 2.0, 2.0]) / 3.0
    for theta in (-2.5, -0.3, 0.0, 1e-4, 1.0, 3.0):
        np.testing.assert_allclose(
            cayley_rotation(np.tan(theta / 2) * u),
            matrix_from_rotation_vector(theta * u),
            atol=1e-14,
        )
    # d[:3] is the rotation vector to first order, d[3:] adds in the outer frame
    T = rigid_from_chart(np.eye(4), [1e-7, 0, 0, 0.1, 0.2, 0.3])
    np.testing.assert_allclose(T[:3, 3], [0.1, 0.2, 0.3])
    np.testing.assert_allclose(T[2, 1], 1e-7, rtol=1e-6)
