"""A simulated plane fixed to a URDF link other than the root (``plane_frame``, ``kinfw
simulate --plane-frame``): the probes touch it where the true robot holds that link, the
file says so (``measured_in``), and a link that moves is refused.

Truth: the true robot's own pose of the link (Pinocchio FK) and the plane as given in it.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from kinfw.cli._main import main
from kinfw.geometry import inverse_transform
from kinfw.model import load_robot
from kinfw.simulation import simulate_measurements
from tests.robots import ARM_6R

TABLE = (
    '<joint name="table_joint" type="fixed"><parent link="world"/><child link="table"/>'
    '<origin xyz="0.5 0.1 -0.2" rpy="0.3 0.0 0.2"/></joint><link name="table"/></robot>'
)
#: The plane in the table's frame: its top, 0.35 m above the table's origin along its z.
PLANE_IN_TABLE = np.array([0.0, 0.0, 2.0, 0.7])  # n not normalised: (0, 0, 1), d = 0.35 m


@pytest.fixture(scope="module")
def nominal():
    return load_robot(ARM_6R.replace("</robot>", TABLE))


def test_the_probes_touch_the_plane_where_the_true_robot_holds_its_link(nominal):
    sim = simulate_measurements(
        nominal,
        contacts=[("flange", None)],
        plane=PLANE_IN_TABLE,
        plane_frame="table",
        contact_samples=30,
        noise_m=0.0,
        seed=3,
    )
    (group,) = sim.data.groups("plane")
    assert group.measured_in == "table" and sim.plane_frame == "table"
    (probe,) = sim.probes
    T = sim.truth.frame_poses(sim.data.q_of(sim.joint_names), "flange", sim.joint_names)
    p_root = T[:, :3, :3] @ probe.offset + T[:, :3, 3]
    table_T_root = inverse_transform(
        sim.truth.frame_poses(np.zeros(len(sim.truth.joint_names)), "table")
    )
    p_table = p_root @ table_T_root[:3, :3].T + table_T_root[:3, 3]
    np.testing.assert_allclose(p_table[:, 2], 0.35, rtol=0, atol=1e-9)
    assert np.ptp(p_table[:, :2], axis=0).min() > 0.05  # spread over the table, not one spot
    # the plane reported in the root is the same plane
    n, d = sim.plane[:3], sim.plane[3]
    np.testing.assert_allclose(p_root @ n, d, rtol=0, atol=1e-9)


def test_a_plane_frame_that_moves_or_is_missing_or_not_a_plane_is_refused(nominal):
    common = {"contacts": [("flange", None)], "contact_samples": 5, "seed": 3}
    with pytest.raises(ValueError, match=r"'l6' moves with the joints \['j1', "):
        simulate_measurements(nominal, plane=PLANE_IN_TABLE, plane_frame="l6", **common)
    with pytest.raises(ValueError, match="'desk' is not a frame of the URDF"):
        simulate_measurements(nominal, plane=PLANE_IN_TABLE, plane_frame="desk", **common)
    with pytest.raises(ValueError, match="only a plane can be fixed"):
        simulate_measurements(nominal, sphere=(0.3, 0.1, 0.4, 0.02), plane_frame="table", **common)


def test_the_command_writes_the_planes_frame_and_calibrate_reads_it(nominal, tmp_path, capsys):
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(nominal.urdf_xml)
    argv = ["simulate", "--urdf", urdf, "--contacts", "flange", "--plane-frame", "table"]
    argv += ["--plane", "0,0,1,0.35", "--contact-samples", "40", "--noise-mm", "0.05"]
    argv += ["--out", tmp_path / "d.json", "--truth-out", tmp_path / "t.urdf", "--json"]
    assert main([str(a) for a in argv]) == 0
    said = json.loads(capsys.readouterr().out)
    assert said["plane_frame"] == "table"
    doc = json.loads((tmp_path / "d.json").read_text())
    planes = [o for s in doc["samples"] for o in s["observations"] if o["kind"] == "plane"]
    assert len(planes) == 40 and {o.get("measured_in") for o in planes} == {"table"}
    argv = ["calibrate", tmp_path / "d.json", "--urdf", urdf, "--out", tmp_path / "c.urdf"]
    assert main([str(a) for a in [*argv, "--params", "offsets"]]) == 0
