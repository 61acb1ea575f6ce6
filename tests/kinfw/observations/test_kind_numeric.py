"""The kinds' numeric hooks: numpy prediction against the CasADi residual, simulation and
drawing descriptions.

Truth: the CasADi residual of each built-in kind, evaluated with the frames' poses and the
blocks' values as numeric inputs, against the numpy prediction (the residual of a
predicted row is zero; of a measured row it is the hand-written pose or point error
against the numpy prediction); the noise statistics the kinds are asked to simulate; hand
geometry for the drawings.
"""

from __future__ import annotations

import numpy as np
import pytest

from kinfw.geometry import (
    inverse_transform,
    matrix_from_rotation_vector,
    rotation_angle,
    transform_from_rotation_translation,
)
from kinfw.model import BlockKey
from kinfw.observations import (
    MissingValue,
    NumericContext,
    PointObservations,
    PoseObservations,
    SymbolicContext,
    TargetObservations,
    kind_of,
    node_name,
    offset_key,
    random_small_rotations,
)

N = 7  # samples
FRAMES = ("flange", "camera")


def _random_poses(rng, n, scale=0.5):
    R = matrix_from_rotation_vector(rng.normal(size=(n, 3)))
    return transform_from_rotation_translation(R, rng.normal(scale=scale, size=(n, 3)))


@pytest.fixture
def world():
    """Random frame poses at N samples and random block values, as numbers."""
    rng = np.random.default_rng(42)
    w_T = {f: _random_poses(rng, N) for f in FRAMES}
    values = {
        BlockKey("target", "board"): _random_poses(rng, 1)[0],
        BlockKey("marker", "m1"): _random_poses(rng, 1, 0.05)[0],
        BlockKey("frame", "tracker"): _random_poses(rng, 1, 2.0)[0],
        offset_key("flange", "ball"): rng.normal(scale=0.05, size=3),
    }
    return w_T, values, NumericContext(lambda f: w_T[f], values)


def _groups():
    """One group per built-in kind and variant (measured_in, marker, known offset);
    the measured rows are placeholders (the tests replace them)."""
    s, eye = np.arange(N), np.tile(np.eye(4), (N, 1, 1))
    return [
        PoseObservations("flange", s, eye),
        PoseObservations("flange", s, eye, marker="m1", measured_in="tracker"),
        TargetObservations("camera", s, eye, target="board"),
        PointObservations("flange", s, np.zeros((N, 3)), offset=[0.01, -0.02, 0.03]),
        PointObservations("flange", s, np.zeros((N, 3)), marker="ball", measured_in="tracker"),
    ]


def _casadi_residuals(group, w_T, values, data):
    """The kind's CasADi residual at every row, frames and blocks as numeric inputs."""
    import casadi as ca

    kind = kind_of(group)
    frame_syms = {f: ca.SX.sym(f, 4, 4) for f in FRAMES}
    value_syms = {
        k: ca.SX.sym(str(k), *(v.shape if v.ndim == 2 else (3, 1))) for k, v in values.items()
    }
    m = ca.SX.sym("m", data.shape[1])
    r = kind.residual(group, SymbolicContext(ca, frame_syms, value_syms, None), m)
    fn = ca.Function("r", [*frame_syms.values(), *value_syms.values(), m], [r])
    consts = [ca.DM(v if v.ndim == 2 else v[:, None]) for v in values.values()]
    return np.stack(
        [
            np.asarray(fn(*[ca.DM(w_T[f][i]) for f in FRAMES], *consts, ca.DM(data[i]))).ravel()
            for i in range(len(data))
        ]
    )


@pytest.mark.parametrize("index", range(5))
def test_numpy_prediction_is_the_casadi_residuals_prediction(world, index):
    w_T, values, context = world
    group = _groups()[index]
    kind = kind_of(group)
    predicted = kind.predict(group, context)
    assert predicted.shape == (N, kind.data(group).shape[1])
    # the residual of the predicted measurement is zero
    np.testing.assert_allclose(
        _casadi_residuals(group, w_T, values, predicted), 0.0, rtol=0, atol=1e-12
    )
    # of a noisy measurement: measured - predicted, with the numpy prediction
    rng = np.random.default_rng(index)
    noisy = kind.simulate(group, context, rng, {"position": 0.01, "rotation": 0.05})
    measured = kind.data(noisy)
    r = _casadi_residuals(group, w_T, values, measured)
    if measured.shape[1] == 3:
        expected = measured - predicted
    else:  # a pose: position error, then 0.5 vee(R_pred^T R_meas - R_meas^T R_pred)
        Rm = np.swapaxes(measured[:, :9].reshape(N, 3, 3), 1, 2)
        Rp = np.swapaxes(predicted[:, :9].reshape(N, 3, 3), 1, 2)
        E = np.swapaxes(Rp, 1, 2) @ Rm - np.swapaxes(Rm, 1, 2) @ Rp
        expected = np.column_stack(
            [
                measured[:, 9:] - predicted[:, 9:],
                0.5 * np.stack([E[:, 2, 1], E[:, 0, 2], E[:, 1, 0]], 1),
            ]
        )
    assert np.abs(r).max() > 1e-3  # the noise shows
    np.testing.assert_allclose(r, expected, rtol=0, atol=1e-12)


def test_prediction_by_hand_geometry(world):
    w_T, values, context = world
    pose, marked, target, point, _ball = _groups()
    np.testing.assert_allclose(
        kind_of(pose).predict(pose, context)[:, 9:], w_T["flange"][:, :3, 3], rtol=0, atol=1e-15
    )
    tracker_T_marker = (
        values[BlockKey("frame", "tracker")] @ w_T["flange"] @ values[BlockKey("marker", "m1")]
    )
    np.testing.assert_allclose(
        kind_of(marked).predict(marked, context)[:, 9:],
        tracker_T_marker[:, :3, 3],
        rtol=0,
        atol=1e-14,
    )
    camera_T_board = inverse_transform(w_T["camera"]) @ values[BlockKey("target", "board")]
    np.testing.assert_allclose(
        kind_of(target).with_data(target, kind_of(target).predict(target, context)).camera_T_target,
        camera_T_board,
        rtol=0,
        atol=1e-14,
    )
    w_p = np.einsum("nij,j->ni", w_T["flange"][:, :3, :3], point.offset) + w_T["flange"][:, :3, 3]
    np.testing.assert_allclose(kind_of(point).predict(point, context), w_p, rtol=0, atol=1e-15)


def test_a_missing_value_is_named(world):
    _, _, context = world
    group = PointObservations("flange", np.arange(N), np.zeros((N, 3)), marker="nowhere")
    with pytest.raises(MissingValue, match="no value for offset:flange:nowhere"):
        kind_of(group).predict(group, context)


def test_simulated_noise_has_the_requested_statistics():
    n, sigma_m, sigma_rad = 20000, 2e-3, 0.01
    rng = np.random.default_rng(3)
    w_T = _random_poses(rng, n)
    context = NumericContext(lambda f: w_T, {})
    s = np.arange(n)
    pose = PoseObservations("flange", s, np.tile(np.eye(4), (n, 1, 1)))
    point = PointObservations("flange", s, np.zeros((n, 3)), offset=[0.0, 0.1, 0.0])
    sigmas = {"position": sigma_m, "rotation": sigma_rad}
    noisy = kind_of(pose).simulate(pose, context, rng, sigmas).meas_T_frame
    dp = noisy[:, :3, 3] - w_T[:, :3, 3]
    np.testing.assert_allclose(dp.std(axis=0), sigma_m, rtol=0.03)
    angles = rotation_angle(np.swapaxes(w_T[:, :3, :3], 1, 2) @ noisy[:, :3, :3])
    np.testing.assert_allclose(np.sqrt(np.mean(angles**2)), sigma_rad, rtol=0.03)
    meas = kind_of(point).simulate(point, context, rng, sigmas).meas_p_point
    dp = meas - (w_T[:, :3, :3] @ [0.0, 0.1, 0.0] + w_T[:, :3, 3])
    np.testing.assert_allclose(dp.std(axis=0), sigma_m, rtol=0.03)
    np.testing.assert_allclose(dp.mean(axis=0), 0.0, atol=4 * sigma_m / np.sqrt(n))


def test_pose_noise_is_drawn_as_perturb_poses_draws_it():
    """The stream of kinfw.simulation.perturb_poses: dp (n, 3), axes (n, 3),
    angles (n,), in that order (written out here by hand)."""
    rng_hand, rng_kind = np.random.default_rng(9), np.random.default_rng(9)
    w_T = _random_poses(np.random.default_rng(1), 5)
    dp = rng_hand.normal(0.0, 1e-3, size=(5, 3))
    axes = rng_hand.normal(size=(5, 3))
    angles = rng_hand.normal(0.0, 0.02, size=5)
    dR = matrix_from_rotation_vector(axes / np.linalg.norm(axes, axis=1)[:, None] * angles[:, None])
    group = PoseObservations("flange", np.arange(5), np.tile(np.eye(4), (5, 1, 1)))
    out = (
        kind_of(group)
        .simulate(
            group, NumericContext(lambda f: w_T), rng_kind, {"position": 1e-3, "rotation": 0.02}
        )
        .meas_T_frame
    )
    np.testing.assert_allclose(out[:, :3, 3], w_T[:, :3, 3] + dp, rtol=0, atol=1e-15)
    np.testing.assert_allclose(out[:, :3, :3], w_T[:, :3, :3] @ dR, rtol=0, atol=1e-15)
    assert random_small_rotations(np.random.default_rng(0), 2, 0.0).shape == (2, 3, 3)


def test_drawings_of_the_built_in_kinds(world):
    w_T, values, context = world
    rng = np.random.default_rng(5)
    sigmas = {"position": 0.01, "rotation": 0.05}
    pose, marked, target, point, ball = (
        kind_of(g).simulate(g, context, rng, sigmas) for g in _groups()
    )
    d = kind_of(pose).drawing(pose, context)
    assert d.node == "poses/flange" and d.focus and d.missing is None
    np.testing.assert_array_equal(d.w_p_measured, pose.meas_T_frame[:, :3, 3])
    np.testing.assert_array_equal(d.w_R_measured, pose.meas_T_frame[:, :3, :3])
    np.testing.assert_array_equal(d.w_p_predicted, w_T["flange"][:, :3, 3])
    # measured in the tracker: brought into w by the tracker's pose
    d = kind_of(marked).drawing(marked, context)
    w_T_meas = inverse_transform(values[BlockKey("frame", "tracker")]) @ marked.meas_T_frame
    assert d.node == "poses/flange@m1"
    np.testing.assert_allclose(d.w_p_measured, w_T_meas[:, :3, 3], rtol=0, atol=1e-14)
    np.testing.assert_allclose(
        d.w_p_predicted,
        (w_T["flange"] @ values[BlockKey("marker", "m1")])[:, :3, 3],
        rtol=0,
        atol=1e-14,
    )
    # a target where the camera saw it, not framed; predicted: the target's origin
    d = kind_of(target).drawing(target, context)
    assert d.node == "targets/camera/board" and not d.focus
    np.testing.assert_allclose(
        d.w_p_measured, (w_T["camera"] @ target.camera_T_target)[:, :3, 3], rtol=0, atol=1e-14
    )
    np.testing.assert_allclose(
        d.w_p_predicted, np.tile(values[BlockKey("target", "board")][:3, 3], (N, 1)), rtol=0, atol=0
    )
    assert kind_of(target).camera_frames(target) == ("camera",)
    # a point: a ball (no orientation)
    d = kind_of(point).drawing(point, context)
    assert d.node == "points/flange" and d.w_R_measured is None
    np.testing.assert_array_equal(d.w_p_measured, point.meas_p_point)
    # without the values: the measurement frame is needed, the marker only to predict
    bare = NumericContext(
        lambda f: w_T[f], {BlockKey("frame", "tracker"): values[BlockKey("frame", "tracker")]}
    )
    d = kind_of(ball).drawing(ball, bare)
    assert d.w_p_predicted is None and d.missing == offset_key("flange", "ball")
    assert d.w_p_measured.shape == (N, 3)
    with pytest.raises(MissingValue, match="frame:tracker"):
        kind_of(marked).drawing(marked, NumericContext(lambda f: w_T[f]))
    assert node_name("a/b", "c/d", marker="e") == "a_b/c_d@e"
