"""The pieces of the estimation problem: blocks, noise model, noise estimation, registry."""

from types import SimpleNamespace

import casadi as ca
import numpy as np
import pytest

from kinfw.geometry import matrix_from_rotation_vector, transform_from_rotation_translation
from kinfw.identification.problem import NoiseModel, build_problem, estimate_noise
from kinfw.model import BlockKey, PointBlock, RigidFrameBlock, load_robot
from kinfw.observations import NoiseComponent, PoseKind, kinds, register_kind
from kinfw.simulation import default_target_pose, random_configurations, simulate_at
from tests.paths import HEAD_URDF as HEAD

PLATES = ("left_plate", "right_plate")
CAMERAS = ("left_camera", "right_camera")


def test_block_units_agree_with_the_unit_of_each_name_and_joint_type():
    head = load_robot(HEAD)
    rng = np.random.default_rng(0)
    names = head.topology((*PLATES, *CAMERAS)).joint_names
    qs = random_configurations(*head.joint_limits(names), 8, rng, fraction=0.8)
    data = simulate_at(
        head,
        qs,
        names,
        frames=PLATES,
        cameras=CAMERAS,
        rng=rng,
        w_T_target=default_target_pose(head, qs, names, CAMERAS),
    )
    problem = build_problem(head, data, parameters="offsets")
    assert len(problem.units) == len(problem.names) == problem.n_parameters
    for (owner, field), unit in zip(problem.names, problem.units, strict=True):
        if field == "zero_offset":  # the URDF's joint type decides
            assert unit == ("rad" if head.joint(owner).is_revolute else "m"), owner
        else:  # angles of the charts (axis tilts, rotations), else lengths
            assert unit == ("rad" if field.startswith(("b_tilt", "rot_")) else "m"), field
    _, zero = problem.block(BlockKey("zero_offset"))
    assert "m" in problem.units[zero]  # the head has prismatic joints


def test_the_robot_blocks_casadi_hooks_and_their_numeric_fold_predict_alike():
    """Base, zero offsets and the CPC chart moved at once: the residual functions (the
    blocks' CasADi hooks) and ``model_at`` (their ``moved_model``) predict the same poses."""
    head = load_robot(HEAD)
    rng = np.random.default_rng(3)
    names = head.topology(PLATES).joint_names
    qs = random_configurations(*head.joint_limits(names), 6, rng, fraction=0.8)
    data = simulate_at(head, qs, names, frames=PLATES, rng=rng)
    problem = build_problem(head, data, parameters="offsets")
    x = rng.normal(scale=0.02, size=problem.n_parameters)
    for key in (BlockKey("base"), BlockKey("zero_offset")):
        assert np.any(x[problem.block(key)[1]] != 0)
    model = problem.model_at(x)
    q = data.q_of(model.topology.joint_names)
    for g, (r, _) in zip(problem.groups, problem.raw_residuals(x, False), strict=True):
        predicted = g.group.meas_T_frame[:, :3, 3] - r[:, :3]  # position rows: meas - pred
        T = model.frame_poses(q[g.sample], g.frame)
        np.testing.assert_allclose(T[:, :3, 3], predicted, atol=1e-12, rtol=0)


def test_rigid_and_point_blocks_give_the_same_value_in_numpy_and_casadi():
    rng = np.random.default_rng(1)
    start = transform_from_rotation_translation(
        matrix_from_rotation_vector([0.3, -1.0, 2.0]), [0.1, 0.2, -0.3]
    )
    rigid = RigidFrameBlock(BlockKey("target", "board"), start=start)
    point = PointBlock(BlockKey("offset", "flange:point"), start=np.array([0.01, 0.0, 0.2]))
    for block in (rigid, point):
        d_sym = ca.SX.sym("d", block.size)
        f = ca.Function("v", [d_sym], [block.casadi_value(d_sym)])
        for _ in range(5):
            d = rng.normal(size=block.size)
            np.testing.assert_allclose(
                np.array(f(d)).reshape(np.shape(block.numpy_value(d))),
                block.numpy_value(d),
                atol=1e-15,
                rtol=0,
            )
            np.testing.assert_allclose(block.coordinates(block.numpy_value(d)), d, atol=1e-12)
    assert rigid.names[0] == ("target:board", "rot_x")
    assert rigid.units == ("rad",) * 3 + ("m",) * 3 and point.units == ("m",) * 3
    with pytest.raises(ValueError, match=r"free: expected shape \(6,\)"):
        RigidFrameBlock(BlockKey("base"), free=np.ones(3, bool))


def test_noise_model_falls_back_by_unit_and_names_what_is_missing():
    noise = NoiseModel(1e-3, 2e-3, sigmas={"distance": 5e-4})
    assert noise.position_m == 1e-3 and noise.rotation_rad == 2e-3
    assert noise.sigma(NoiseComponent("distance", 1, "m")) == 5e-4
    assert noise.sigma(NoiseComponent("plane", 1, "m")) == 1e-3  # unit m -> position
    assert noise.sigma(NoiseComponent("bearing", 2, "rad")) == 2e-3
    with pytest.raises(KeyError, match="no sigma for component 'plane'"):
        NoiseModel(sigmas={"distance": 1.0}).sigma(NoiseComponent("plane", 1, "m"))


def test_variance_components_are_estimated_for_any_component_rows():
    """Known noise per component (3-row position 0.5, 1-row distance 2.0), whitened by a
    wrong guess: each estimate comes back within its statistical precision."""
    rng = np.random.default_rng(2)
    position, distance = NoiseComponent("position", 3, "m"), NoiseComponent("distance", 1, "m")
    groups = [
        SimpleNamespace(sample=np.arange(4000), rows=4, components=(position, distance)),
        SimpleNamespace(sample=np.arange(3000), rows=1, components=(distance,)),
    ]
    si = [
        np.column_stack([rng.normal(0, 0.5, (4000, 3)), rng.normal(0, 2.0, (4000, 1))]),
        rng.normal(0, 2.0, (3000, 1)),
    ]

    def whitened(noise):  # rows in the problem's order, divided by the model's sigmas
        return np.concatenate(
            [
                (
                    rows / np.concatenate([np.full(c.rows, noise.sigma(c)) for c in g.components])
                ).ravel()
                for g, rows in zip(groups, si, strict=True)
            ]
        )

    guess = NoiseModel(1.0, 1.0, sigmas={"distance": 1.0})
    least_squares = estimate_noise(whitened(guess), groups, guess, np.zeros(19000))
    robust = estimate_noise(whitened(guess), groups, guess, np.zeros(19000), robust=True)
    trimmed = estimate_noise(
        whitened(robust), groups, robust, np.zeros(19000), robust=True, first=False
    )  # the second round, from the first's sigmas
    for est in (least_squares, robust, trimmed):
        assert est.estimated
        assert est.of("position") == pytest.approx(0.5, rel=0.05)
        assert est.of("distance") == pytest.approx(2.0, rel=0.05)
        assert est.of("rotation") == 1.0  # no rows: unchanged


def test_a_kind_name_or_group_type_can_be_registered_once():
    assert [k.name for k in kinds()][:3] == ["pose", "target", "point"]
    with pytest.raises(ValueError, match="a kind named 'pose' is already registered"):
        register_kind(PoseKind())


def test_noise_estimate_takes_the_leverages_per_row_or_their_sums_per_component():
    """Only each component's sum of leverages enters: per-row leverages and their sums
    per component (what the normal equations give) estimate the same noise."""
    rng = np.random.default_rng(3)
    position, rotation = NoiseComponent("position", 3, "m"), NoiseComponent("rotation", 3, "rad")
    groups = [SimpleNamespace(sample=np.arange(500), rows=6, components=(position, rotation))]
    r = rng.normal(size=3000)
    h = rng.uniform(0.0, 0.02, size=3000)
    h3 = h.reshape(500, 6)
    sums = {"position": float(h3[:, :3].sum()), "rotation": float(h3[:, 3:].sum())}
    guess = NoiseModel(1e-3, 1e-3)
    for robust, first in ((False, True), (True, True), (True, False)):
        per_row = estimate_noise(r, groups, guess, h, robust=robust, first=first)
        per_component = estimate_noise(r, groups, guess, sums, robust=robust, first=first)
        for name in ("position", "rotation"):
            assert per_row.of(name) == pytest.approx(per_component.of(name), rel=1e-14)
            without = estimate_noise(r, groups, guess, np.zeros(3000), robust=robust, first=first)
            assert per_row.of(name) > without.of(name) * (1 + 1e-3)  # fewer dof: larger
