"""The tree CPC model against Pinocchio FK, hand geometry and the paper's parameter count."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from kinfw.geometry import rotation_angle, rotation_vector_from_matrix
from kinfw.model import (
    cpc_fk_function,
    cpc_from_geometry,
    cpc_from_robot,
    geometry_from_cpc,
    geometry_from_robot,
    load_robot,
    rotation_from_axis,
)
from tests.paths import HEAD_URDF as HEAD
from tests.robots import ARM_6R, PRISMATIC_TREE

HEAD_FRAMES = ("left_plate", "right_plate")

CASES = [
    pytest.param(ARM_6R, ("flange",), id="arm6r"),
    pytest.param(PRISMATIC_TREE, ("tool_a", "cam", "tool_b"), id="prismatic-tree"),
    pytest.param(HEAD, (*HEAD_FRAMES, "left_camera", "right_camera"), id="iis-head"),
]


def _random_qs(robot, names, n, rng):
    lower, upper = robot.joint_limits(names)
    lower = np.where(np.isfinite(lower), lower, -np.pi)
    upper = np.where(np.isfinite(upper), upper, np.pi)
    return rng.uniform(lower, upper, size=(n, len(names)))


def _pose_error(Ta, Tb):
    """Max position (m) and orientation (rad) discrepancy over a batch of poses."""
    dp = np.linalg.norm(Ta[..., :3, 3] - Tb[..., :3, 3], axis=-1).max()
    dr = rotation_angle(np.swapaxes(Ta[..., :3, :3], -1, -2) @ Tb[..., :3, :3]).max()
    return dp, dr


@pytest.mark.parametrize(("urdf", "frames"), CASES)
def test_cpc_fk_equals_pinocchio_fk(urdf, frames):
    robot = load_robot(urdf)
    model = cpc_from_robot(robot, frames)
    names = model.topology.joint_names
    qs = _random_qs(robot, names, 300, np.random.default_rng(0))
    for frame in frames:
        dp, dr = _pose_error(model.frame_poses(qs, frame), robot.frame_poses(qs, frame, names))
        assert dp < 1e-12 and dr < 1e-12, (frame, dp, dr)


@pytest.mark.parametrize(("urdf", "frames"), CASES)
def test_canonical_gauge_fixes_the_redundant_parameters(urdf, frames):
    model = cpc_from_robot(load_robot(urdf), frames)
    revolute = np.array(model.topology.revolute)
    assert np.all(model.beta == 0.0)
    assert np.all(model.l[revolute, 2] == 0.0)
    assert np.all(model.l[~revolute] == 0.0)
    assert np.all(model.b[:, 2] >= -1e-12)
    np.testing.assert_allclose(np.linalg.norm(model.b, axis=1), 1.0, atol=1e-15)


def test_identifiable_count_is_32_for_the_head_plates():
    """4 per revolute + 2 per prismatic + 6 per end effector (DESIGN.md, Table 1)."""
    model = cpc_from_robot(load_robot(HEAD), HEAD_FRAMES)
    assert model.topology.joint_names == (
        "x_table",
        "y_table",
        "pan",
        "tilt",
        "vergence_left",
        "vergence_right",
    )
    assert model.n_parameters == 4 * 4 + 2 * 2 + 6 * 2 == 32
    assert len(set(model.parameter_names)) == 32


def test_rotation_of_eq4_takes_z_onto_b_by_the_minimal_rotation():
    rng = np.random.default_rng(3)
    b = rng.normal(size=(200, 3))
    b[:, 2] = np.abs(b[:, 2])
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    R = rotation_from_axis(b)
    np.testing.assert_allclose(R[:, :, 2], b, atol=1e-15)
    np.testing.assert_allclose(
        np.swapaxes(R, 1, 2) @ R, np.broadcast_to(np.eye(3), R.shape), atol=1e-14
    )
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-14)
    # minimal: rotation axis is z x b, angle acos(b_z)
    w = rotation_vector_from_matrix(R)
    np.testing.assert_allclose(w[:, 2], 0.0, atol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(w, axis=1), np.arccos(b[:, 2]), atol=1e-12)
    with pytest.raises(ValueError, match="singular"):
        rotation_from_axis([0.0, 0.0, -1.0])


def test_negative_and_antiparallel_axes_flip_the_frame_not_the_reading():
    model = cpc_from_robot(load_robot(ARM_6R), ("flange",))
    # j1 is URDF axis 0 0 -1 seen from the world z: flipped; j3 is anti-parallel to j2.
    assert model.sign[0] == -1.0
    assert model.sign[2] == -1.0
    np.testing.assert_allclose(model.b[2], [0.0, 0.0, 1.0], atol=1e-15)


def test_geometry_round_trip_is_exact():
    robot = load_robot(PRISMATIC_TREE)
    model = cpc_from_robot(robot, ("tool_a", "cam", "tool_b"))
    again = cpc_from_geometry(geometry_from_cpc(model))
    for field in ("b", "beta", "l", "sign", "tool_T"):
        np.testing.assert_allclose(getattr(again, field), getattr(model, field), atol=1e-14)


def test_any_gauge_canonicalises_to_the_same_fk():
    """A model with nonzero beta and l_z (the paper's gauge) has an equal canonical model."""
    robot = load_robot(ARM_6R)
    model = cpc_from_robot(robot, ("flange",))
    rng = np.random.default_rng(4)
    from dataclasses import replace

    odd = replace(model, beta=rng.normal(size=6), l=model.l + rng.normal(size=(6, 3)) * 0.05)
    canonical = cpc_from_geometry(geometry_from_cpc(odd))
    assert np.all(canonical.beta == 0.0) and np.all(canonical.l[:, 2] == 0.0)
    qs = _random_qs(robot, model.topology.joint_names, 100, rng)
    dp, dr = _pose_error(canonical.frame_poses(qs, "flange"), odd.frame_poses(qs, "flange"))
    assert dp < 1e-12 and dr < 1e-12


def test_geometry_from_robot_gives_world_axes_by_hand():
    robot = load_robot(PRISMATIC_TREE)
    geo = geometry_from_robot(robot, ("cam",))
    # base at rpy (3.0, 0.1, -0.5): px moves along the base x axis
    base_R = robot.frame_poses(np.zeros(3), "base", geo.topology.joint_names)[:3, :3]
    np.testing.assert_allclose(geo.axes[0], base_R[:, 0], atol=1e-15)


def test_chart_is_identity_at_zero_and_first_order_in_radians_and_metres():
    model = cpc_from_robot(load_robot(HEAD), HEAD_FRAMES)
    zero = model.perturbed(np.zeros(model.n_parameters))
    np.testing.assert_allclose(zero.b, model.b, atol=1e-15)
    np.testing.assert_allclose(zero.tool_T, model.tool_T, atol=1e-15)
    eps = 1e-6
    for k, (owner, field) in enumerate(model.parameter_names):
        d = np.zeros(model.n_parameters)
        d[k] = eps
        moved = model.perturbed(d)
        if field.startswith("b_tilt"):
            j = model.topology.joint_names.index(owner)
            angle = np.arctan2(
                np.linalg.norm(np.cross(moved.b[j], model.b[j])), moved.b[j] @ model.b[j]
            )
            assert angle == pytest.approx(eps, rel=1e-6)
        elif field.startswith("rot"):
            e = model.topology.frames.index(owner)
            dR = model.tool_T[e, :3, :3].T @ moved.tool_T[e, :3, :3]
            assert rotation_angle(dR) == pytest.approx(eps, rel=1e-6)


@pytest.mark.parametrize(("urdf", "frames"), CASES)
def test_casadi_fk_equals_numpy_fk_of_the_perturbed_model(urdf, frames):
    robot = load_robot(urdf)
    model = cpc_from_robot(robot, frames)
    rng = np.random.default_rng(5)
    qs = _random_qs(robot, model.topology.joint_names, 50, rng)
    delta = rng.normal(size=model.n_parameters) * 0.05
    fk = cpc_fk_function(model).map(len(qs))
    outs = fk(qs.T, np.tile(delta, (len(qs), 1)).T)
    outs = outs if isinstance(outs, (list, tuple)) else [outs]
    moved = model.perturbed(delta)
    for frame, out in zip(frames, outs, strict=True):
        T_ca = np.array(out).reshape(4, len(qs), 4).transpose(1, 0, 2)
        np.testing.assert_allclose(T_ca, moved.frame_poses(qs, frame), atol=1e-13)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_fk_is_invariant_to_configuration_order(seed):
    rng = np.random.default_rng(seed)
    model = cpc_from_robot(load_robot(ARM_6R), ("flange",))
    qs = rng.uniform(-3, 3, size=(20, 6))
    perm = rng.permutation(20)
    np.testing.assert_array_equal(model.frame_poses(qs)[perm], model.frame_poses(qs[perm]))


def test_chart_coordinates_invert_the_chart():
    model = cpc_from_robot(load_robot(HEAD), (*HEAD_FRAMES, "left_camera"))
    delta = np.random.default_rng(6).normal(size=model.n_parameters) * 0.05
    moved = model.perturbed(delta)
    np.testing.assert_allclose(model.chart_coordinates(moved), delta, atol=1e-12)


@pytest.mark.parametrize(("urdf", "frames"), CASES)
def test_frame_poses_batch_in_batch_out(urdf, frames):
    """(J,) gives one pose, (n, J) n poses with the axis kept for n = 1; all equal
    Pinocchio's FK of the same configurations."""
    robot = load_robot(urdf)
    model = cpc_from_robot(robot, frames)
    names = model.topology.joint_names
    qs = _random_qs(robot, names, 3, np.random.default_rng(5))
    pin_all = np.stack([robot.frame_poses(qs, f, names) for f in frames], axis=1)  # (3, E)
    single, one, batch = qs[0], qs[:1], qs
    assert model.frame_poses(single, frames[0]).shape == (4, 4)
    assert model.frame_poses(one, frames[0]).shape == (1, 4, 4)
    assert model.frame_poses(batch, frames[0]).shape == (3, 4, 4)
    assert model.frame_poses(single).shape == (len(frames), 4, 4)
    assert model.frame_poses(one).shape == (1, len(frames), 4, 4)
    assert model.frame_poses(np.empty((0, len(names)))).shape == (0, len(frames), 4, 4)
    for e, frame in enumerate(frames):
        for got, want in (
            (model.frame_poses(single, frame), pin_all[0, e]),
            (model.frame_poses(one, frame), pin_all[:1, e]),
            (model.frame_poses(batch, frame), pin_all[:, e]),
        ):
            dp, dr = _pose_error(got, want)
            assert dp < 1e-12 and dr < 1e-12, (frame, dp, dr)
    for got, want in (
        (model.frame_poses(single), pin_all[0]),
        (model.frame_poses(one), pin_all[:1]),
    ):
        dp, dr = _pose_error(got, want)
        assert dp < 1e-12 and dr < 1e-12, (dp, dr)
    with pytest.raises(
        ValueError,
        match=rf"qs: expected shape \({len(names)},\) or "
        rf"\(n, {len(names)}\).*got \(1, 1, {len(names)}\)",
    ):
        model.frame_poses(qs[None, :1])
