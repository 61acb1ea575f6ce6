"""The shipped robot blocks of a model spec (compliance, gear scale, coupling) and their
registry, against a pendulum solved by hand and against their own inverses."""

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import pytest

from kinfw.model import (
    BlockKey,
    BlockSamples,
    GearScaleBlock,
    JointComplianceBlock,
    JointCouplingBlock,
    ModelSpec,
    ParameterName,
    SpecBlock,
    block_from_spec,
    block_names,
    load_robot,
    register_block,
)
from tests.paths import HEAD_URDF
from tests.robots import PENDULUM_KG as M_KG
from tests.robots import PENDULUM_L_M as L_M
from tests.robots import pendulum_urdf

G = 9.81  # STANDARD_GRAVITY's


@pytest.fixture(scope="module")
def pendulum():
    return load_robot(pendulum_urdf())


def _fixed_point(q_cmd: float, c: float) -> float:
    """``q = q_cmd + c M g L cos q`` by plain iteration (a contraction for small c)."""
    q = q_cmd
    for _ in range(200):
        q = q_cmd + c * M_KG * G * L_M * np.cos(q)
    return q


def test_compliance_deflects_to_the_fixed_point_and_back(pendulum):
    c = 2e-3  # rad/Nm: a soft joint, 19 mrad at the horizontal
    spec = ModelSpec.parse(["compliance"])
    samples = BlockSamples(pendulum, ("j",), np.zeros((1, 1)))
    spec = spec.bound(samples).with_values([[c]])
    q_cmd = np.array([[-1.0], [0.0], [0.4], [2.0]])
    q = spec.joint_values(pendulum, ("j",), q_cmd)
    expected = [_fixed_point(x, c) for x in q_cmd[:, 0]]
    np.testing.assert_allclose(q[:, 0], expected, atol=1e-14)
    assert abs(q[1, 0] - q_cmd[1, 0]) == pytest.approx(c * M_KG * G * L_M, rel=1e-3)
    np.testing.assert_allclose(spec.readings(pendulum, ("j",), q), q_cmd, atol=1e-14)


def _hook(block, q, q_read, samples) -> float:
    """The CasADi hook's joint value at ``q`` for readings ``q_read`` (one sample)."""
    import casadi as ca

    names = samples.joint_names
    q_sym = ca.SX.sym("q", 1)
    s_sym = ca.SX.sym("s", block.sample_width(names))
    f = ca.Function(
        "f",
        [q_sym, s_sym],
        [block.casadi_joint_values(q_sym, ca.DM.zeros(block.size), block.start, names, s_sym)],
    )
    inputs = block.sample_inputs(samples.at(np.array([[q_read]])))
    return float(f(q, inputs[0]))


def test_the_casadi_hook_solves_the_deflection_to_second_order(pendulum):
    """The graph linearises the torque at the readings: with the joint moved 0.02 rad by
    earlier hooks (a zero offset) its error is c tau'' dq^2 / 2 ~ 2e-8 rad, not the
    first-order c tau' dq ~ 2e-6 a torque at the readings would leave."""
    c = 1e-5
    samples = BlockSamples(pendulum, ("j",), np.zeros((1, 1)))
    block = JointComplianceBlock.from_spec("").for_data(samples).with_start([c])
    q_read, offset = 0.4, 0.02
    exact = _fixed_point(q_read + offset, c)
    hooked = _hook(block, q_read + offset, q_read, samples)
    first_order = c * M_KG * G * L_M * np.sin(q_read) * offset
    assert abs(hooked - exact) < 0.05 * first_order
    assert abs(hooked - exact) < c * M_KG * G * L_M * offset**2
    assert _hook(block, 0.4, 0.4, samples) == pytest.approx(_fixed_point(0.4, c), abs=1e-12)


def test_gear_scale_and_coupling_map_the_readings_and_back():
    head = load_robot(HEAD_URDF)
    names = ("pan", "tilt", "vergence_left", "vergence_right")
    spec = ModelSpec.parse(["gear-scale:tilt", "coupling:vergence_right=-1*vergence_left"])
    spec = spec.with_values([[0.02], [-1.0]])
    r = np.array([[0.1, 0.2, 0.3, 0.4], [-0.5, 0.6, -0.2, 0.1]])
    q = spec.joint_values(head, names, r)
    np.testing.assert_allclose(q[:, 1], 1.02 * r[:, 1])
    np.testing.assert_allclose(q[:, 3], r[:, 3] - r[:, 2])
    np.testing.assert_allclose(q[:, [0, 2]], r[:, [0, 2]])
    np.testing.assert_allclose(spec.readings(head, names, q), r, atol=1e-15)


def test_spec_texts_parse_and_round_trip():
    assert {"compliance", "gear-scale", "coupling"} <= set(block_names())
    fixed = block_from_spec("coupling:joint_3=-1*joint_2")
    assert isinstance(fixed, JointCouplingBlock) and not fixed.free[0]
    assert fixed.start.tolist() == [-1.0] and fixed.names == (("joint_3", "coupling:joint_2"),)
    estimated = block_from_spec("coupling:joint_3=?*joint_2")
    assert estimated.free[0] and estimated.start.tolist() == [0.0]
    assert block_from_spec("coupling:a=?0.5*b").start.tolist() == [0.5]
    spec = ModelSpec((GearScaleBlock.from_spec("tilt").with_start([0.003]), fixed))
    again = ModelSpec.from_list(spec.to_list())
    assert again.texts == spec.texts
    assert [b.start.tolist() for b in again.blocks] == [[0.003], [-1.0]]
    for bad, match in [
        ("spring:tilt", "unknown block 'spring'; known blocks: compliance, coupling"),
        ("gear-scale:", "expected gear-scale:JOINT"),
        ("coupling:a=b", r"expected coupling:JOINT=K\*OTHER"),
        ("coupling:a=2*a", "coupled to itself"),
        ("coupling:a=x*b", r"expected coupling:JOINT=K\*OTHER"),
        ("coupling:a=1.2.3*b", "'1.2.3' is not a number"),
    ]:
        with pytest.raises(ValueError, match=match):
            block_from_spec(bad)
    with pytest.raises(ValueError, match="listed twice"):
        ModelSpec.parse(["gear-scale:tilt", "gear-scale:tilt"])


def test_a_block_on_a_joint_off_the_measured_paths_is_refused():
    head = load_robot(HEAD_URDF)
    samples = BlockSamples(head, ("pan", "tilt"), np.zeros((2, 2)))
    with pytest.raises(ValueError, match=r"'vergence_left' is not a movable joint.*pan, tilt"):
        GearScaleBlock.from_spec("vergence_left").for_data(samples)


@dataclass(frozen=True, slots=True)
class ConstantOffsetBlock(SpecBlock):
    """A block of another package: a constant offset ``b`` (rad) added to one joint's
    reading (what a zero offset does; here only the registry and the default numeric
    side are exercised)."""

    joint: str = ""
    block_name: ClassVar[str] = "test-offset"

    @classmethod
    def from_spec(cls, argument: str) -> "ConstantOffsetBlock":
        return cls(BlockKey("test-offset", argument), joint=argument)

    @property
    def fields(self) -> tuple[str, ...]:
        return ("offset",)

    @property
    def names(self) -> tuple[ParameterName, ...]:
        return (ParameterName(self.joint, "offset"),)

    @property
    def units(self) -> tuple[str, ...]:
        return ("rad",)

    def casadi_joint_values(self, q: Any, d: Any, c: Any, joint_names, s=None) -> Any:
        import casadi as ca

        e = np.zeros(len(joint_names))
        e[joint_names.index(self.joint)] = 1.0
        return q + self.casadi_value(d, c)[0] * ca.DM(e)


def test_the_registry_takes_a_new_block_and_refuses_clashes():
    register_block(ConstantOffsetBlock)
    block = block_from_spec("test-offset:tilt")
    assert isinstance(block, ConstantOffsetBlock) and block.spec == "test-offset:tilt"
    # its numeric side is its CasADi hook evaluated (RobotBlock.joint_values)
    head = load_robot(HEAD_URDF)
    samples = BlockSamples(head, ("pan", "tilt"), np.array([[0.1, 0.2]]))
    moved = block.with_start([0.01]).joint_values(samples.qs, samples)
    np.testing.assert_allclose(moved, [[0.1, 0.21]])
    np.testing.assert_allclose(block.with_start([0.01]).readings(moved, samples), [[0.1, 0.2]])

    @dataclass(frozen=True, slots=True)
    class Other(ConstantOffsetBlock):
        block_name: ClassVar[str] = "compliance"

    with pytest.raises(ValueError, match="'compliance' is taken by JointComplianceBlock"):
        register_block(Other)
    with pytest.raises(ValueError, match="expected a SpecBlock subclass"):
        register_block(dict)


def test_fixate_and_reach_command_through_the_spec():
    """With a gear scale on the tilt, the command the controllers get is the reading that
    turns the joint to the solved value: q / (1 + s)."""
    from kinfw.control import fixate, reach

    head = load_robot(HEAD_URDF)
    geared = head.with_spec(ModelSpec.parse(["gear-scale:tilt"]).with_values([[0.02]]))
    tilt = head.joint_names.index("tilt")
    point = np.array([2.0, 0.3, 0.4])
    fix = fixate(geared, point)
    assert fix.command[tilt] == pytest.approx(fix.q[tilt] / 1.02, abs=1e-15)
    assert fixate(head, point).command is not None
    got = reach(geared, "left_plate", head.frame_poses(fix.q, "left_plate")[:3, 3])
    assert got.command[tilt] == pytest.approx(got.q[tilt] / 1.02, abs=1e-15)
    others = [k for k in range(len(head.joint_names)) if k != tilt]
    np.testing.assert_array_equal(got.command[others], got.q[others])
