"""The plausibility guard's verdict against hand-computed geometry: a planar 2R arm (links
0.5 m and 0.3 m) whose elbow origin and tool mount are moved by known amounts."""

import math

import numpy as np
import pytest

from kinfw.identification.checks import ChangeBound, plausibility, robot_size
from kinfw.model import Robot
from tests.robots import PLANAR_2R


def _moved(elbow_xyz: str = "0.5 0 0", tool_rpy: str = "0 0 0") -> Robot:
    xml = PLANAR_2R.replace('<origin xyz="0.5 0 0" rpy="0 0 0"/>', f'<origin xyz="{elbow_xyz}"/>')
    xml = xml.replace(
        '<origin xyz="0.3 0 0" rpy="0 0 0"/>', f'<origin xyz="0.3 0 0" rpy="{tool_rpy}"/>'
    )
    return Robot(xml, "<moved>")


def test_the_robot_size_is_the_largest_distance_between_joint_origins():
    # origins at q = 0: root and j1 at 0, j2 at 0.5 m, the tool at 0.8 m along x
    assert robot_size(Robot(PLANAR_2R)) == pytest.approx(0.8, abs=1e-12)


def test_each_move_and_turn_is_measured_against_the_bound():
    nominal = Robot(PLANAR_2R)
    # the elbow 30 mm further out (and 4 mm sideways: a turn about j1, which moves nothing
    # j1 does not); the tool tilted 3 deg off the elbow's axis
    calibrated = _moved(elbow_xyz="0.53 0.004 0", tool_rpy="0.0523598775598 0 0")
    v = plausibility(nominal, calibrated, (1e-3, math.radians(0.1)))
    # 5 x the prior is 5 mm / 0.5 deg: the floor 20 mm / 2 deg wins; 5 % of 0.8 m is 40 mm
    assert v.bound_m == pytest.approx(0.020)
    assert v.bound_rad == pytest.approx(math.radians(2.0))
    by_name = {c.name: c for c in v.changes}
    elbow, tool = by_name["j2"], by_name["tool_joint"]
    assert elbow.what == "joint origin" and tool.what == "mount"
    # the distance between the parallel j1 and j2 axes: 0.5 m -> hypot(0.53, 0.004)
    assert elbow.shift_m == pytest.approx(math.hypot(0.53, 0.004) - 0.5, abs=1e-12)
    assert elbow.turn_rad == pytest.approx(0.0, abs=1e-12)
    assert elbow.ratio == pytest.approx((math.hypot(0.53, 0.004) - 0.5) / 0.020, abs=1e-9)
    # the tool's z axis 3 deg off the elbow's, its origin still 0.3 m from the axis
    assert tool.turn_rad == pytest.approx(math.radians(3.0), abs=1e-9)
    assert tool.shift_m == pytest.approx(0.0, abs=1e-12)
    assert tool.ratio == pytest.approx(1.5, abs=1e-9)
    assert not v.plausible
    assert [c.name for c in v.beyond] == ["j2", "tool_joint"]  # largest ratio first (1.5008, 1.5)


def test_a_turn_about_the_axis_above_is_no_change():
    # the tool turned about the elbow's axis and the elbow about j1's: no rigid motion of
    # the robot and no zero offset tells these apart from the nominal
    calibrated = _moved(elbow_xyz="0.4330127018922193 0.25 0", tool_rpy="0 0 0.3")
    v = plausibility(Robot(PLANAR_2R), calibrated, None)
    assert v.largest_ratio == pytest.approx(0.0, abs=1e-9)


def test_a_large_prior_widens_the_bound_up_to_five_percent_of_the_robot():
    nominal, calibrated = Robot(PLANAR_2R), _moved(elbow_xyz="0.535 0 0")
    assert plausibility(nominal, calibrated, (6e-3, 0.01)).bound_m == pytest.approx(0.030)
    # 5 x 10 mm = 50 mm is above 5 % of 0.8 m: the size caps it at 40 mm
    capped = plausibility(nominal, calibrated, (10e-3, 0.01))
    assert capped.bound_m == pytest.approx(0.040)
    assert "5% of the robot's size" in capped.why
    assert capped.plausible  # 35 mm
    given = plausibility(nominal, calibrated, None, bound=ChangeBound(max_m=0.030))
    assert given.bound_m == 0.030 and not given.plausible


def test_the_roots_pose_in_a_stance_link_is_a_change():
    nominal, calibrated = Robot(PLANAR_2R), _moved(elbow_xyz="0.5 0.05 0")
    v = plausibility(nominal, calibrated, None, stance=("tool",))
    pose = next(c for c in v.changes if c.what == "pose")
    assert pose.name == "tool in world"
    # at q = 0 the tool sits 50 mm further along y in the root; two joints on the way, so
    # the bound is sqrt(2) x 20 mm
    assert pose.shift_m == pytest.approx(0.05, abs=1e-12)
    assert pose.turn_rad == pytest.approx(0.0, abs=1e-12)
    assert pose.ratio == pytest.approx(0.05 / (math.sqrt(2.0) * 0.020), abs=1e-9)


def test_an_unchanged_urdf_is_plausible():
    v = plausibility(Robot(PLANAR_2R), Robot(PLANAR_2R), None)
    assert v.plausible and v.changes == () and v.largest_ratio == 0.0
    assert np.isfinite(v.size_m)


def test_a_placeholder_joint_has_no_nominal_to_bound():
    calibrated = _moved(tool_rpy="0.5 0 0")  # 29 deg
    placeholder = PLANAR_2R.replace("</robot>", '<kinfw placeholder="tool_joint"/></robot>')
    assert not plausibility(Robot(PLANAR_2R), calibrated, None).plausible
    v = plausibility(Robot(placeholder), calibrated, None)
    assert v.plausible and v.changes == ()
    with pytest.raises(ValueError, match=r"<kinfw placeholder> names \['tool'\]"):
        Robot(PLANAR_2R.replace("</robot>", '<kinfw placeholder="tool"/></robot>'))
