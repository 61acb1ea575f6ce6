"""Payloads and the gravity torque on the joints, against a pendulum computed by hand."""

import numpy as np
import pytest

from kinfw.model import (
    STANDARD_GRAVITY,
    BlockSamples,
    JointComplianceBlock,
    Payloads,
    RobotModelError,
    gravity_torques,
    load_robot,
    massless_links,
)
from tests.robots import PENDULUM_KG as M_KG
from tests.robots import PENDULUM_L_M as L_M
from tests.robots import pendulum_urdf

G = 9.81


@pytest.fixture(scope="module")
def pendulum():
    return load_robot(pendulum_urdf())


def test_the_gravity_torque_of_a_pendulum_is_m_g_l_cos_q(pendulum):
    """Rotating x about y by q puts the mass at (L cos q, 0, -L sin q); gravity's torque
    about +y is then (p x F).y = M g L cos q, its derivative -M g L sin q."""
    q = np.linspace(-2.5, 2.5, 11)[:, None]
    tau, dtau = gravity_torques(pendulum, ("j",), q)
    np.testing.assert_allclose(tau[:, 0], M_KG * G * L_M * np.cos(q[:, 0]), atol=1e-9)
    np.testing.assert_allclose(dtau[:, 0, 0], -M_KG * G * L_M * np.sin(q[:, 0]), atol=1e-9)


def test_a_payload_on_the_tool_adds_its_moment_and_gravity_can_point_anywhere(pendulum):
    q = np.array([[0.3], [1.1], [-0.7]])
    payloads = Payloads(("tool",), [0, -1, 0], [3.0, 0.0, 1.5], [[0.1, 0, 0], [0, 0, 0], [0, 0, 0]])
    tau, _ = gravity_torques(pendulum, ("j",), q, payloads)
    # each payload's lever along the arm: the tool at 2L, the first's com 0.1 m beyond
    payload_moment = np.array([3.0 * (2 * L_M + 0.1), 0.0, 1.5 * 2 * L_M])
    expected = (M_KG * L_M + payload_moment) * G * np.cos(q[:, 0])
    np.testing.assert_allclose(tau[:, 0], expected, atol=1e-9)
    # gravity along +x (root frame): the mass at (L cos q, 0, -L sin q) feels F = (M g, 0, 0),
    # (p x F).y = p_z F_x = -M g L sin q
    tau_x, _ = gravity_torques(pendulum, ("j",), q, gravity=(G, 0.0, 0.0), derivative=False)
    np.testing.assert_allclose(tau_x[:, 0], -M_KG * G * L_M * np.sin(q[:, 0]), atol=1e-9)


def test_payloads_subset_concatenate_and_kinds():
    a = Payloads.constant(3, "tool", 2.0, (0.0, 0.0, 0.1))
    b = Payloads.none(2)
    both = a.concatenate(b)
    assert len(both) == 5 and both.frames == ("tool",)
    assert both.frame_index.tolist() == [0, 0, 0, -1, -1]
    first, of_sample = both.kinds()
    assert len(first) == 2 and of_sample.tolist()[:3] == [of_sample[0]] * 3
    assert both.subset([4, 0]).mass_kg.tolist() == [0.0, 2.0]
    assert both.any and not b.any
    with pytest.raises(ValueError, match="mass_kg"):
        Payloads(("tool",), [0], [-1.0])
    with pytest.raises(ValueError, match="without a frame"):
        Payloads(("tool",), [-1], [1.0])


def test_links_without_inertias_are_named_and_compliance_is_refused():
    bare = load_robot(pendulum_urdf(inertial=False))
    assert massless_links(bare, ("j",)) == {"j": ("arm", "tool")}
    samples = BlockSamples(bare, ("j",), np.zeros((3, 1)))
    with pytest.raises(RobotModelError, match=r"arm, tool have no <inertial>.*\(j\)"):
        JointComplianceBlock.from_spec("").for_data(samples)


def test_block_samples_default_to_no_payload_and_standard_gravity(pendulum):
    samples = BlockSamples(pendulum, ("j",), np.zeros((4, 1)))
    assert not samples.payloads.any and len(samples.payloads) == 4
    assert samples.gravity.tolist() == list(STANDARD_GRAVITY)
    with pytest.raises(ValueError, match="expected 4 samples"):
        BlockSamples(pendulum, ("j",), np.zeros((4, 1)), Payloads.none(3))
