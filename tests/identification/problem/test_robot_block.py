"""A robot-side parameter block defined here, outside the library: a joint's gear scale.

The encoder of one joint reads ``q`` while the joint turns ``(1 + s) q`` (a gear ratio
off by ``s``). :class:`GearScaleBlock` is the whole extension: names, unit, value,
its hook on the joint values (CasADi) and its numeric side; it is passed to
:func:`kinfw.identification.refine` through ``extra_blocks`` and touches no library
file (docs/architecture.md, "Adding a robot-side parameter block").
"""

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pytest

from kinfw.identification import refine
from kinfw.identification.problem import NoiseModel, build_problem
from kinfw.model import CPC_KEY, BlockKey, CPCModel, ParameterName, RobotBlock, load_robot
from kinfw.simulation import perturb_robot, random_configurations, simulate_at
from kinfw.verification.evaluation import pose_discrepancy, random_joint_values
from kinfw.verification.reporting import refine_section
from tests.paths import HEAD_URDF as HEAD

PLATES = ("left_plate", "right_plate")
SIGMA = NoiseModel(0.5e-3, np.radians(0.5) / np.sqrt(3.0))
JOINT = "tilt"
S_TRUE = 0.03  # the joint turns 3 % more than its encoder says


@dataclass(frozen=True, slots=True)
class GearScaleBlock(RobotBlock):
    """``q_effective = (1 + s) q`` for the joint named by the key; ``s`` unitless."""

    @property
    def fields(self) -> tuple[str, ...]:
        return ("gear_scale",)

    @property
    def names(self) -> tuple[ParameterName, ...]:
        return (ParameterName(self.key.name, "gear_scale"),)

    @property
    def units(self) -> tuple[str, ...]:
        return ("unitless",)

    def numpy_value(self, d):
        return float(d[0])

    def casadi_value(self, d, c=None):
        return d[0]

    def casadi_joint_values(
        self, q: Any, d: Any, c: Any, joint_names: tuple[str, ...], s: Any = None
    ) -> Any:
        import casadi as ca

        e = np.zeros(len(joint_names))
        e[joint_names.index(self.key.name)] = 1.0
        return q + d[0] * (q * ca.DM(e))  # the joint's value scaled, the others kept

    def moved_model(self, model: CPCModel, d) -> CPCModel:
        return model  # no CPC model holds a scale: it stands beside the model


GEAR = GearScaleBlock(BlockKey("gear_scale", JOINT))


@pytest.fixture(scope="module")
def geared():
    """Noise-free plate poses of a perturbed head whose tilt joint turns (1 + s) q."""
    nominal = load_robot(HEAD)
    rng = np.random.default_rng(5)
    truth = load_robot(perturb_robot(nominal, rng, origin_mm=5.0, origin_deg=1.0, axis_deg=1.0))
    names = nominal.topology(PLATES).joint_names
    q_read = random_configurations(*nominal.joint_limits(names), 40, rng, fraction=0.8)
    j = names.index(JOINT)
    q_true = q_read.copy()
    q_true[:, j] *= 1.0 + S_TRUE
    data = simulate_at(truth, q_true, names, frames=PLATES, rng=rng)
    return nominal, truth, replace(data, qs=q_read), names, j


def test_a_gear_scale_defined_outside_the_library_is_calibrated_exactly(geared):
    nominal, truth, data, names, j = geared
    result = refine(nominal, data, noise=SIGMA, extra_blocks=(GEAR,))
    assert result.converged
    k = result.parameter_names.index((JOINT, "gear_scale"))
    assert result.free[k]
    assert result.estimate[k] == pytest.approx(S_TRUE, abs=1e-9)
    # the geometry: the model at the true joint values is the truth (Pinocchio's FK)
    q_true = random_joint_values(nominal, names, 100, np.random.default_rng(1))
    q_read = q_true.copy()
    q_read[:, j] /= 1.0 + result.estimate[k]
    for frame in PLATES:
        dp, dr = pose_discrepancy(
            result.model.frame_poses(q_true, frame), truth.frame_poses(q_true, frame, names)
        )
        assert dp < 1e-9 and dr < 1e-9, (frame, dp, dr)
    assert result.identifiability.rank == result.identifiability.n_parameters


def test_without_the_block_the_same_data_do_not_fit(geared):
    nominal, _, data, _, _ = geared
    result = refine(nominal, data, noise=SIGMA)
    # the CPC chart cannot absorb a 3 % scale: about a millimetre of residual, not 1e-9
    worst = max(np.abs(g.component("position")).max() for g in result.residuals)
    assert worst > 1e-4


def test_the_gear_scale_is_reported_with_its_unit(geared):
    nominal, _, data, _, _ = geared
    result = refine(nominal, data, noise=SIGMA, extra_blocks=(GEAR,))
    unit = dict(zip(result.parameter_names, result.parameter_units, strict=True))
    assert unit[(JOINT, "gear_scale")] == "unitless"
    (row,) = [
        p
        for p in refine_section(result, loss="linear").parameters
        if (p.owner, p.field) == (JOINT, "gear_scale")
    ]
    assert row.to_dict()["unit"] == "unitless" and not row.fixed
    assert row.delta_from_start == pytest.approx(S_TRUE, abs=1e-9)
    assert 0.0 < row.std < S_TRUE / 10  # 0.5 mm noise: the scale is well determined


#: The CPC chart's fields of an end frame's tool (the rest are the joints').
TOOL_FIELDS = ("rot_x", "rot_y", "rot_z", "x", "y", "z")


def test_the_block_says_what_it_frees_per_parameter_set_and_takes_no_prior(geared):
    nominal, _, data, _, _ = geared
    for parameters, free in (("full", True), ("frames", False), ("none", False)):
        problem = build_problem(nominal, data, parameters=parameters, extra_blocks=(GEAR,))
        block, _ = problem.block(GEAR.key)
        assert block.free.tolist() == [free], parameters
    problem = build_problem(nominal, data, prior=(1e-3, 1e-2), extra_blocks=(GEAR,))
    _, s = problem.block(GEAR.key)
    assert np.isinf(problem.prior_sigma[s]).all()  # a unitless entry: no prior in m or rad
    _, s_cpc = problem.block(CPC_KEY)
    tools = np.array([n.field in TOOL_FIELDS for n in problem.names[s_cpc]])
    assert tools.sum() == 6 * len(problem.model0.topology.frames)
    assert np.isfinite(problem.prior_sigma[s_cpc][~tools]).all()  # the joints' rad and m
    assert np.isinf(problem.prior_sigma[s_cpc][tools]).all()  # the end frames: as frames
    with pytest.raises(ValueError, match="the key gear_scale:tilt is taken"):
        build_problem(nominal, data, extra_blocks=(GEAR, GEAR))


def test_the_result_model_takes_the_joint_values_after_the_blocks_hook(geared):
    """Every robot block moved at once (zero offsets too, free under a prior): the CasADi
    predictions equal ``model_at``'s model at the scaled joint values ``(1 + s) q``."""
    nominal, _, data, _, j = geared
    problem = build_problem(nominal, data, prior=(1e-3, 1e-2), extra_blocks=(GEAR,))
    x = np.random.default_rng(2).normal(scale=0.02, size=problem.n_parameters)
    _, s = problem.block(GEAR.key)
    model = problem.model_at(x)
    q = data.q_of(model.topology.joint_names)
    q[:, j] *= 1.0 + x[s][0]
    for g, (r, _) in zip(problem.groups, problem.raw_residuals(x, False), strict=True):
        predicted = g.group.meas_T_frame[:, :3, 3] - r[:, :3]  # position rows: meas - pred
        T = model.frame_poses(q[g.sample], g.frame)
        np.testing.assert_allclose(T[:, :3, 3], predicted, atol=1e-12, rtol=0)
