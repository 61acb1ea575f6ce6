"""Frames the URDF lacks, mounted on one of its links: the ``"mounts"`` section, the
URDF edit that adds them (:func:`kinfw.urdf.add_fixed_links`) and ``--mount``.

Truths: Pinocchio's forward kinematics of the edited URDF (the new frame's pose is its
parent's times the mount, exactly), the original text kept line for line, and the
file's round trip."""

from __future__ import annotations

import numpy as np
import pytest

from kinfw.geometry import matrix_from_rotation_vector
from kinfw.measurements import (
    Measurements,
    Mount,
    concatenate_measurements,
    measurements_from_dict,
    measurements_to_dict,
    mounted_robot,
)
from kinfw.model import load_robot
from kinfw.observations import DatasetError
from kinfw.urdf import ExportError, add_fixed_links
from tests.robots import ARM_6R


def _mount_T() -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = matrix_from_rotation_vector([0.4, -0.1, 0.2])
    T[:3, 3] = [0.01, 0.02, -0.03]
    return T


def test_a_fixed_link_is_added_after_every_original_tag():
    T = _mount_T()
    xml = add_fixed_links(ARM_6R, {"cam": ("flange", T), "cam_optical": ("cam", np.eye(4))})
    assert xml.startswith(ARM_6R[: ARM_6R.rindex("</robot>")].rstrip())
    robot, nominal = load_robot(xml), load_robot(ARM_6R)
    rng = np.random.default_rng(0)
    qs = rng.uniform(-1, 1, (5, 6))
    names = nominal.joint_names
    np.testing.assert_allclose(
        robot.frame_poses(qs, "cam_optical", names),
        nominal.frame_poses(qs, "flange", names) @ T,
        rtol=0,
        atol=1e-14,
    )
    assert add_fixed_links(ARM_6R, {}) is ARM_6R
    with pytest.raises(ExportError, match="already has a link or joint 'l6'"):
        add_fixed_links(ARM_6R, {"l6": ("flange", T)})
    with pytest.raises(ExportError, match="parent 'tool0' is not a link"):
        add_fixed_links(ARM_6R, {"cam": ("tool0", T)})


def _doc(mounts):
    return {
        "format": "kinfw-measurements",
        "version": 1,
        "units": {"length": "mm", "angle": "rad"},
        "joint_names": ["j1"],
        "mounts": mounts,
        "samples": [
            {
                "q": [0.1],
                "observations": [
                    {"frame": "cam", "kind": "target", "xyz": [1, 2, 300]}
                    | {"quat_xyzw": [0, 0, 0, 1]}
                ],
            }
        ],
    }


def test_mounts_read_in_the_files_unit_and_write_back_in_si():
    data = measurements_from_dict(
        _doc({"cam": {"parent": "flange", "xyz": [10, 20, -30], "quat_xyzw": [0, 0, 1, 0]}})
    )
    mount = data.mounts["cam"]
    np.testing.assert_allclose(mount.parent_T_frame[:3, 3], [0.01, 0.02, -0.03], atol=1e-15)
    np.testing.assert_allclose(mount.parent_T_frame[:3, :3], np.diag([-1.0, -1.0, 1.0]), atol=0)
    back = measurements_from_dict(measurements_to_dict(data))
    assert back.mounts["cam"].same_as(mount)
    assert back.subset([0]).mounts["cam"].same_as(mount)
    plain = measurements_from_dict(_doc({"cam": {"parent": "flange"}}))
    assert measurements_to_dict(plain)["mounts"] == {"cam": {"parent": "flange"}}
    with pytest.raises(DatasetError, match=r"mounts\.cam.*parent"):
        measurements_from_dict(_doc({"cam": {"on": "flange"}}))


def test_a_frame_mounted_two_ways_is_refused():
    a = measurements_from_dict(_doc({"cam": {"parent": "flange"}}), source="a.json")
    b = measurements_from_dict(_doc({"cam": {"parent": "l6"}}), source="b.json")
    with pytest.raises(DatasetError, match="'cam' is mounted on 'flange' in one part and on 'l6'"):
        concatenate_measurements(a, b)
    with pytest.raises(DatasetError, match="'cam' is mounted on 'flange'"):
        a.with_mounts({"cam": Mount("l6")})
    assert isinstance(a.with_mounts({"cam": Mount("flange")}), Measurements)


def test_mounted_robot_adds_only_what_the_urdf_lacks():
    nominal = load_robot(ARM_6R)
    T = _mount_T()
    robot = mounted_robot(nominal, {"cam": Mount("flange", T)})
    np.testing.assert_allclose(robot.joint("cam_joint").parent_T_child, T, rtol=0, atol=1e-15)
    assert mounted_robot(robot, {"cam": Mount("flange")}) is robot  # exported: already there
    with pytest.raises(DatasetError, match="'cam' is mounted on 'l5', but the URDF"):
        mounted_robot(robot, {"cam": Mount("l5")})
    with pytest.raises(DatasetError, match="parent 'tool0' is not a link"):
        mounted_robot(nominal, {"cam": Mount("tool0")})


def test_the_mount_option_adds_to_the_files_mounts(tmp_path, capsys):
    from kinfw.cli._main import main
    from kinfw.measurements import write_measurements

    path = tmp_path / "d.json"
    write_measurements(path, measurements_from_dict(_doc({})))
    urdf = tmp_path / "n.urdf"
    urdf.write_text(ARM_6R)
    # without the mount, 'cam' is an unknown frame; with it, verify predicts it
    assert main(["verify", str(urdf), str(path)]) == 2
    assert "cam" in capsys.readouterr().err
    assert main(["verify", str(urdf), str(path), "--mount", "cam:flange"]) == 0
    assert main(["verify", str(urdf), str(path), "--mount", "cam"]) == 2
    assert "expected NAME:PARENT" in capsys.readouterr().err


def test_a_target_said_to_be_on_two_frames_is_refused():
    """One board name on two frames in one file: the reader names both observations;
    two files merged, or groups built in memory: the dataset names both groups."""
    obs = [
        {"frame": "cam", "kind": "target", "target": "board", "xyz": [0, 0, 1]}
        | {"quat_xyzw": [0, 0, 0, 1]},
        {"frame": "cam", "kind": "target", "target": "board", "xyz": [0, 0, 1]}
        | {"quat_xyzw": [0, 0, 0, 1], "target_frame": "l6"},
    ]
    doc = _doc({}) | {"samples": [{"q": [0.1], "observations": [o]} for o in obs]}
    with pytest.raises(
        DatasetError,
        match=r"samples\[1\]\.observations\[0\]\.target_frame: target 'board' is on frame 'l6' "
        r"here but fixed in the world in samples\[0\]\.observations\[0\]",
    ):
        measurements_from_dict(doc)
    a, b = (measurements_from_dict(doc | {"samples": doc["samples"][i : i + 1]}) for i in (0, 1))
    with pytest.raises(
        DatasetError, match=r"target 'board' is fixed in the world in .* but on 'l6'"
    ):
        concatenate_measurements(a, b)
    # other names, or the same frame, are fine
    renamed = dict(obs[1], target="board2")
    doc2 = _doc({}) | {"samples": [{"q": [0.1], "observations": [obs[0], renamed]}]}
    assert len(measurements_from_dict(doc2).targets) == 2
