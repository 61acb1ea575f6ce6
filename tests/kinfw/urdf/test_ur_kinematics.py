"""UR kinematics file (``ur_description``'s ``kinematics_parameters_file``): written by
kinfw, read back through the xacro package with a chain built as ``ur_description``
builds it (``tests/data/ur_kinematics/ur_arm.urdf.xacro``), and its forward kinematics
compared to 1e-9 with (a) the UR10's published DH table, an independent product of
``Rz Tz Tx Rx``, and (b) Pinocchio's forward kinematics of a calibrated UR10 URDF."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
import yaml

from kinfw.cli._main import main
from kinfw.model import load_robot
from kinfw.urdf import (
    UR_JOINTS,
    ExportError,
    ur_kinematics_from_dh,
    ur_kinematics_from_robot,
    ur_kinematics_text,
)
from tests.paths import DATA

XACRO = DATA / "ur_kinematics" / "ur_arm.urdf.xacro"
JOINTS = UR_JOINTS
LINKS = ("shoulder_link", "upper_arm_link", "forearm_link", "wrist_1_link")
LINKS += ("wrist_2_link", "wrist_3_link")
# UR10 (CB3) DH table as Universal Robots publishes it (metres, rad)
UR10_D = [0.1273, 0.0, 0.0, 0.163941, 0.1157, 0.0922]
UR10_A = [0.0, -0.612, -0.5723, 0.0, 0.0, 0.0]
UR10_ALPHA = [np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0]
# ur_description's ur10 default_kinematics.yaml, as (x, y, z, roll, pitch, yaw) per joint
UR10_ORIGINS = [
    (0.0, 0.0, 0.1273, 0.0, 0.0, 0.0),
    (0.0, 0.0, 0.0, np.pi / 2, 0.0, 0.0),
    (-0.612, 0.0, 0.0, 0.0, 0.0, 0.0),
    (-0.5723, 0.0, 0.163941, 0.0, 0.0, 0.0),
    (0.0, -0.1157, 0.0, np.pi / 2, 0.0, 0.0),
    (0.0, 0.0922, 0.0, np.pi / 2, np.pi, np.pi),
]


def _dh_fk(q, d, a, alpha, theta):
    """``prod_i Rz(theta_i + q_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``: the DH frame 6 in 0."""
    T = np.eye(4)
    for qi, di, ai, al, th in zip(q, d, a, alpha, theta, strict=True):
        c, s, ca, sa = np.cos(th + qi), np.sin(th + qi), np.cos(al), np.sin(al)
        T = T @ np.array(
            [
                [c, -s * ca, s * sa, ai * c],
                [s, c * ca, -c * sa, ai * s],
                [0, sa, ca, di],
                [0, 0, 0, 1],
            ]
        )
    return T


def _yaml_robot(text, tmp_path):
    """The file read back: PyYAML's keys, then the chain ur_description builds from it."""
    data = yaml.safe_load(text)
    assert list(data["kinematics"]) == [
        "shoulder",
        "upper_arm",
        "forearm",
        "wrist_1",
        "wrist_2",
        "wrist_3",
        "hash",
    ]
    for joint in JOINTS:
        seg = joint.removesuffix("_joint").replace("shoulder_pan", "shoulder")
        seg = seg.replace("shoulder_lift", "upper_arm").replace("elbow", "forearm")
        assert set(data["kinematics"][seg]) == {"x", "y", "z", "roll", "pitch", "yaw"}
    path = tmp_path / "my_robot_calibration.yaml"
    path.write_text(text)
    return load_robot(XACRO, xacro_args={"kinematics_parameters_file": str(path)})


@pytest.mark.parametrize("calibrated", [False, True])
def test_ur10_dh_table_to_yaml_to_fk(tmp_path, calibrated):
    rng = np.random.default_rng(1)
    d, a, alpha = np.array(UR10_D), np.array(UR10_A), np.array(UR10_ALPHA)
    theta = np.zeros(6)
    if calibrated:  # a controller's calibration: delta_d, delta_a, delta_alpha, delta_theta
        d, theta = d + rng.normal(0, 1e-3, 6), theta + rng.normal(0, 2e-3, 6)
        a[:5] += rng.normal(0, 1e-3, 5)
        alpha[:5] += rng.normal(0, 2e-3, 5)
    text = ur_kinematics_text(ur_kinematics_from_dh(d, a, alpha, theta))
    robot = _yaml_robot(text, tmp_path)
    qs = rng.uniform(-np.pi, np.pi, (50, 6))
    base_T_dh0 = robot.frame_poses(np.zeros(6), "base_link_inertia", JOINTS)
    fk = np.linalg.inv(base_T_dh0) @ robot.frame_poses(qs, "wrist_3_link", JOINTS)
    dh = np.stack([_dh_fk(q, d, a, alpha, theta) for q in qs])
    np.testing.assert_allclose(fk, dh, atol=1e-9)


def _ur10_urdf(rng=None, *, tilt=0.0, tool_off=False, prefix="", tool_rpy=None):
    """A UR10 URDF (world -> base_link -> base_link_inertia -> 6 joints -> flange -> tool0
    -> camera); with ``rng`` calibrated: every origin moved by mm and mrad, the base fixed
    joint moved, the axes of joints 1-5 tilted by ``tilt`` rad and, with ``tool_off``,
    ``tool0`` moved and the wrist_3 axis tilted (tool0 off that axis); ``tool_rpy``: the
    flange-to-tool0 rotation instead of ur_description's."""

    def joint(name, kind, parent, child, xyz, rpy, axis="0 0 1"):
        xyz_s, rpy_s = " ".join(map(repr, map(float, xyz))), " ".join(map(repr, map(float, rpy)))
        extra = f'<axis xyz="{axis}"/><limit lower="-6" upper="6" effort="1" velocity="1"/>'
        return (
            f'<joint name="{prefix}{name}" type="{kind}">'
            f'<parent link="{"" if parent == "world" else prefix}{parent}"/>'
            f'<child link="{prefix}{child}"/><origin xyz="{xyz_s}" rpy="{rpy_s}"/>'
            f"{extra if kind != 'fixed' else ''}</joint>"
        )

    def moved(xyz, rpy, mm=2e-3, mrad=3e-3):
        if rng is None:
            return xyz, rpy
        return np.add(xyz, rng.normal(0, mm, 3)), np.add(rpy, rng.normal(0, mrad, 3))

    links = ["base_link", "base_link_inertia", *LINKS, "flange", "tool0", "camera"]
    text = '<robot name="ur10"><link name="world"/>'
    text += "".join(f'<link name="{prefix}{n}"/>' for n in links)
    text += joint("base_joint", "fixed", "world", "base_link", *moved((0.1, 0.2, 0.8), (0, 0, 0.3)))
    text += joint(
        "base_inertia", "fixed", "base_link", "base_link_inertia", *moved((0, 0, 0), (0, 0, np.pi))
    )
    parent = "base_link_inertia"
    for k, (name, child) in enumerate(zip(JOINTS, LINKS, strict=True)):
        xyz, rpy = moved(UR10_ORIGINS[k][:3], UR10_ORIGINS[k][3:])
        t = tilt if k < 5 or tool_off else 0.0  # a tilted wrist_3 axis puts tool0 off it
        axis = [np.sin(t) * np.cos(k), np.sin(t) * np.sin(k), np.cos(t)]
        text += joint(
            name, "revolute", parent, child, xyz, rpy, " ".join(map(repr, map(float, axis)))
        )
        parent = child
    text += joint(
        "wrist_3-flange", "fixed", "wrist_3_link", "flange", (0, 0, 0), (0, -np.pi / 2, -np.pi / 2)
    )
    tool_rpy = (np.pi / 2, np.pi, np.pi / 2) if tool_rpy is None else tool_rpy
    tool = moved((0, 0, 0), tool_rpy) if tool_off else ((0, 0, 0), tool_rpy)
    text += joint("flange-tool0", "fixed", "flange", "tool0", *tool)
    text += joint("tool-cam", "fixed", "tool0", "camera", (0.03, -0.05, 0.07), (0.1, 0.2, 0.3))
    return text + "</robot>"


@pytest.mark.parametrize(
    ("tilt", "tool_off", "prefix"),
    [(0.0, False, ""), (2e-3, False, "ur_"), (2e-3, True, "")],
    ids=["origins", "tilted-axes", "tool0-off-axis"],
)
def test_calibrated_ur10_urdf_to_yaml_to_fk(tmp_path, tilt, tool_off, prefix):
    rng = np.random.default_rng(7)
    calibrated = load_robot(_ur10_urdf(rng, tilt=tilt, tool_off=tool_off, prefix=prefix))
    kinematics = ur_kinematics_from_robot(calibrated)
    robot = _yaml_robot(ur_kinematics_text(kinematics), tmp_path)
    qs = rng.uniform(-np.pi, np.pi, (50, 6))
    names = tuple(prefix + j for j in JOINTS)
    base = calibrated.frame_poses(np.zeros(6), prefix + "base_link", names)
    truth = np.linalg.inv(base) @ calibrated.frame_poses(qs, prefix + "tool0", names)
    fk = robot.frame_poses(qs, "tool0", JOINTS) @ kinematics.tool0_T_calibrated_tool0
    np.testing.assert_allclose(fk, truth, atol=1e-9)
    np.testing.assert_allclose(kinematics.root_T_base_link, base, atol=1e-12)
    tilts = [tilt] * 5 + [tilt if tool_off else 0.0]
    np.testing.assert_allclose(kinematics.axis_tilts_rad, tilts, atol=1e-12)
    offset = kinematics.tool0_T_calibrated_tool0
    if tool_off:  # 2 mm / 3 mrad moved: what the file cannot hold is what was moved
        assert 1e-4 < np.linalg.norm(offset[:3, 3]) < 1e-2
    else:  # tool0 on the wrist_3 axis: the file alone reproduces it
        np.testing.assert_allclose(offset, np.eye(4), atol=1e-12)


def test_tool0_turned_upside_down_is_a_half_turn_offset(tmp_path):
    """tool0 turned a half turn about its x (z against the wrist_3 axis): a turn about the
    axis is absorbed by the wrist_3 origin, this one is the offset."""
    flipped = pin.rpy.rpyToMatrix(np.pi / 2, np.pi, np.pi / 2) @ pin.rpy.rpyToMatrix(np.pi, 0, 0)
    calibrated = load_robot(_ur10_urdf(tool_rpy=pin.rpy.matrixToRpy(flipped)))
    kinematics = ur_kinematics_from_robot(calibrated)
    robot = _yaml_robot(ur_kinematics_text(kinematics), tmp_path)
    qs = np.random.default_rng(2).uniform(-np.pi, np.pi, (20, 6))
    base = calibrated.frame_poses(np.zeros(6), "base_link", JOINTS)
    truth = np.linalg.inv(base) @ calibrated.frame_poses(qs, "tool0", JOINTS)
    fk = robot.frame_poses(qs, "tool0", JOINTS) @ kinematics.tool0_T_calibrated_tool0
    np.testing.assert_allclose(fk, truth, atol=1e-9)
    offset = kinematics.tool0_T_calibrated_tool0
    np.testing.assert_allclose(np.trace(offset[:3, :3]), -1.0, atol=1e-12)  # a half turn


def test_nominal_ur10_urdf_gives_ur_descriptions_file():
    kinematics = ur_kinematics_from_robot(load_robot(_ur10_urdf()))
    data = yaml.safe_load(ur_kinematics_text(kinematics))["kinematics"]
    segments = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")
    for k, seg in enumerate(segments):
        xyz = [data[seg][c] for c in "xyz"]
        rpy = [data[seg][c] for c in ("roll", "pitch", "yaw")]
        R = pin.rpy.rpyToMatrix(*UR10_ORIGINS[k][3:])
        np.testing.assert_allclose(xyz, UR10_ORIGINS[k][:3], atol=1e-12)
        np.testing.assert_allclose(pin.rpy.rpyToMatrix(*rpy), R, atol=1e-12)
    assert data["hash"].startswith("kinfw_")


def test_refuses_what_is_not_a_ur_arm():
    with pytest.raises(ExportError, match=r"not a UR arm: ur_description's joints are"):
        ur_kinematics_from_robot(load_robot(_ur10_urdf().replace("shoulder_pan_joint", "j1")))
    swapped = _ur10_urdf().replace(
        '"elbow_joint" type="revolute"', '"elbow_joint" type="prismatic"'
    )
    with pytest.raises(ExportError, match=r"elbow_joint \(prismatic\)"):
        ur_kinematics_from_robot(load_robot(swapped))
    with pytest.raises(ExportError, match=r"no link 'tool0'"):
        ur_kinematics_from_robot(load_robot(_ur10_urdf().replace('"tool0"', '"tool"')))


def test_a_path_is_not_a_robot():
    with pytest.raises(TypeError, match=r"robot"):
        ur_kinematics_from_robot("ur10.urdf")


def test_refuses_an_axis_far_from_z():
    with pytest.raises(ExportError, match=r"'shoulder_pan_joint' turns about .* 8.02 deg off z"):
        ur_kinematics_from_robot(load_robot(_ur10_urdf(tilt=0.14)))


def test_dh_table_needs_six_values_and_no_sixth_link():
    with pytest.raises(ValueError, match=r"d: expected 6 values"):
        ur_kinematics_from_dh(UR10_D[:5], UR10_A, UR10_ALPHA)
    with pytest.raises(ValueError, match=r"a6 = 0.01"):
        ur_kinematics_from_dh(UR10_D, [*UR10_A[:5], 0.01], UR10_ALPHA)


def test_export_ur_kinematics_command(tmp_path, capsys):
    urdf = tmp_path / "cal.urdf"
    urdf.write_text(_ur10_urdf(np.random.default_rng(3), tool_off=True))
    out = tmp_path / "my_robot_calibration.yaml"
    assert main(["export", "ur-kinematics", str(urdf), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "tool0_T_calibrated_tool0" in printed and "base_link in world" in printed
    robot = _yaml_robot(out.read_text(), tmp_path)
    assert robot.has_frame("tool0")
    bad = tmp_path / "arm.urdf"
    bad.write_text(_ur10_urdf().replace("wrist_3_joint", "j6"))
    assert main(["export", "ur-kinematics", str(bad), "--out", str(tmp_path / "x.yaml")]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "not a UR arm" in err
    assert not (tmp_path / "x.yaml").exists()


@pytest.mark.slow
def test_kinfw_calibrated_ur10_exports_to_the_same_fk(tmp_path, capsys):
    """The real path: simulate a UR10 (published DH), calibrate it with kinfw, export the
    calibrated URDF (axes tilted, tool0 moved by the exporter) to the file: the file's
    chain times the printed tool0 offset is the calibrated URDF's FK to 1e-9."""
    from kinfw.verification.studies import ur10_urdf

    (tmp_path / "ur10.urdf").write_text(ur10_urdf())
    run = ["simulate", "--urdf", tmp_path / "ur10.urdf", "--frames", "tool0", "--seed", "3"]
    run += ["--out", tmp_path / "data.json", "--truth-out", tmp_path / "true.urdf"]
    assert main([str(a) for a in run]) == 0
    run = ["calibrate", tmp_path / "data.json", "--urdf", tmp_path / "ur10.urdf"]
    assert main([str(a) for a in [*run, "--out", tmp_path / "cal.urdf"]]) == 0
    out = tmp_path / "ur.yaml"
    assert main(["export", "ur-kinematics", str(tmp_path / "cal.urdf"), "--out", str(out)]) == 0
    calibrated = load_robot(tmp_path / "cal.urdf")
    kinematics = ur_kinematics_from_robot(calibrated)
    assert out.read_text() == ur_kinematics_text(kinematics)
    assert np.degrees(kinematics.axis_tilts_rad[:5]).max() > 0.01  # the exporter tilted them
    robot = _yaml_robot(out.read_text(), tmp_path)
    qs = np.random.default_rng(0).uniform(-np.pi, np.pi, (50, 6))
    base = calibrated.frame_poses(np.zeros(6), "base_link", JOINTS)
    truth = np.linalg.inv(base) @ calibrated.frame_poses(qs, "tool0", JOINTS)
    fk = robot.frame_poses(qs, "tool0", JOINTS) @ kinematics.tool0_T_calibrated_tool0
    np.testing.assert_allclose(fk, truth, atol=1e-9)
