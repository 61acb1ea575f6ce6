"""Tests of kinfw.measurements: hand-written files with known numbers, round trips,
sample-order invariance, every error path, and the checks against a small URDF."""

from __future__ import annotations

import copy
import json
import math
import re
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose, assert_array_equal

from kinfw.geometry import transform_from_xyz_quat_xyzw
from kinfw.measurements import (
    Measurements,
    check_against_robot,
    check_joint_motion,
    concatenate_measurements,
    measurements_from_dict,
    measurements_to_dict,
    read_measurements,
    write_measurements,
)
from kinfw.model import load_robot
from kinfw.observations import (
    DatasetError,
    PointObservations,
    PoseObservations,
    TargetObservations,
    kind_of,
)
from tests.paths import REPO

S = math.sqrt(0.5)  # cos(45 deg) = sin(45 deg): quaternions of 90-degree rotations

# Rotation matrices written out by hand.
ROT_Z_90 = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
ROT_Y_90 = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
ROT_X_180 = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])

# A toy robot: world -(fixed)- base -(slide, prismatic)- slider -(pan, revolute)- head
# -(fixed)- camera; base -(spin, continuous)- wheel; world -(floating)- puck.
URDF = """<robot name="toy">
  <link name="world"/><link name="base"/><link name="slider"/><link name="head"/>
  <link name="camera"/><link name="wheel"/><link name="puck"/>
  <joint name="mount" type="fixed">
    <parent link="world"/><child link="base"/><origin xyz="0 0 1"/></joint>
  <joint name="slide" type="prismatic">
    <parent link="base"/><child link="slider"/><axis xyz="1 0 0"/>
    <limit lower="-0.5" upper="0.5" effort="1" velocity="1"/></joint>
  <joint name="pan" type="revolute">
    <parent link="slider"/><child link="head"/><axis xyz="0 0 1"/>
    <limit lower="-1.5" upper="1.5" effort="1" velocity="1"/></joint>
  <joint name="cam_mount" type="fixed">
    <parent link="head"/><child link="camera"/><origin xyz="0.1 0 0"/></joint>
  <joint name="spin" type="continuous">
    <parent link="base"/><child link="wheel"/><axis xyz="0 1 0"/></joint>
  <joint name="loose" type="floating"><parent link="world"/><child link="puck"/></joint>
</robot>"""


@pytest.fixture(scope="module")
def robot():
    return load_robot(URDF)


# -- document builders -----------------------------------------------------------------


def pose(frame: str, xyz=(0.0, 0.0, 0.0), quat=(0.0, 0.0, 0.0, 1.0), **extra: Any) -> dict:
    return {"frame": frame, "kind": "pose", "xyz": list(xyz), "quat_xyzw": list(quat), **extra}


def target(frame: str, xyz=(0.0, 0.0, 0.0), quat=(0.0, 0.0, 0.0, 1.0), **extra: Any) -> dict:
    return {"frame": frame, "kind": "target", "xyz": list(xyz), "quat_xyzw": list(quat), **extra}


def point(frame: str, xyz=(0.0, 0.0, 0.0), **extra: Any) -> dict:
    return {"frame": frame, "kind": "point", "xyz": list(xyz), **extra}


def sample(q, *observations: dict) -> dict:
    return {"q": list(q), "observations": list(observations)}


def document(
    *samples: dict, joint_names=("slide", "pan"), length="m", angle="rad", **top: Any
) -> dict:
    return {
        "format": "kinfw-measurements",
        "version": 1,
        "units": {"length": length, "angle": angle},
        "joint_names": list(joint_names),
        **top,
        "samples": list(samples),
    }


def write_doc(directory: Path, doc: Any, name: str = "data.json") -> Path:
    path = directory / name
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path


def groups_by_key(m: Measurements) -> dict[tuple, Any]:
    return {g._key: g for g in (*m.poses, *m.targets, *m.points)}


def data_of(group) -> np.ndarray:
    if isinstance(group, PoseObservations):
        return group.meas_T_frame
    if isinstance(group, TargetObservations):
        return group.camera_T_target
    return group.meas_p_point


# -- parsing with known numbers --------------------------------------------------------


def test_pose_quaternions_give_hand_written_matrices_and_mm_become_m(tmp_path):
    doc = document(
        sample([0, 0], pose("head", xyz=[100, -250, 1500], quat=[0, 0, S, S])),
        sample([0, 0], pose("camera", xyz=[1, 2, 3], quat=[0, S, 0, S])),
        sample([0, 0], pose("slider", xyz=[-0.5, 0, 2000], quat=[1, 0, 0, 0])),
        length="mm",
    )
    m = read_measurements(write_doc(tmp_path, doc))
    assert [g.frame for g in m.poses] == ["head", "camera", "slider"]
    expected = [
        (ROT_Z_90, [0.1, -0.25, 1.5]),
        (ROT_Y_90, [0.001, 0.002, 0.003]),
        (ROT_X_180, [-0.0005, 0.0, 2.0]),
    ]
    for g, (rotation, translation), i in zip(m.poses, expected, range(3), strict=True):
        assert_array_equal(g.sample, [i])
        assert g.meas_T_frame.shape == (1, 4, 4)
        assert_allclose(g.meas_T_frame[0, :3, :3], rotation, rtol=0, atol=1e-15)
        assert_array_equal(g.meas_T_frame[0, :3, 3], translation)  # exact: x / 1000
        assert_array_equal(g.meas_T_frame[0, 3], [0, 0, 0, 1])


def test_joint_values_in_degrees_become_radians():
    m = measurements_from_dict(
        document(sample([90, -45], pose("head")), sample([180, 0], pose("head")), angle="deg")
    )
    assert_allclose(m.qs, [[math.pi / 2, -math.pi / 4], [math.pi, 0.0]], rtol=0, atol=1e-15)


def test_joint_values_in_a_rad_file_are_read_unchanged():
    m = measurements_from_dict(document(sample([0.25, -1.125], pose("head")), length="mm"))
    assert_array_equal(m.qs, [[0.25, -1.125]])
    assert m.qs.dtype == np.float64
    assert m.joint_names == ("slide", "pan")


def test_joint_units_win_over_the_angle_unit():
    doc = document(
        sample([250, 90, 0.5, 0.125], pose("head")),
        joint_names=["slide", "pan", "tilt", "lift"],
        length="mm",
        angle="deg",
        joint_units=["mm", "deg", "rad", "m"],
    )
    m = measurements_from_dict(doc)
    assert_allclose(m.qs, [[0.25, math.pi / 2, 0.5, 0.125]], rtol=0, atol=1e-15)
    assert m.qs[0, 0] == 0.25


def test_target_observations_are_grouped_by_camera_and_target():
    doc = document(
        sample(
            [0, 0],
            target("camera", xyz=[0, 0, 800], quat=[0, 0, S, S]),
            target("camera", xyz=[10, 0, 500], target="board"),
        ),
        sample([0, 0], target("head", xyz=[0, 50, 0]), target("camera", xyz=[0, 0, 900])),
        length="mm",
    )
    m = measurements_from_dict(doc)
    assert [(g.camera, g.target) for g in m.targets] == [
        ("camera", "target"),
        ("camera", "board"),
        ("head", "target"),
    ]
    first = m.targets[0]
    assert_array_equal(first.sample, [0, 1])
    assert_allclose(first.camera_T_target[0, :3, :3], ROT_Z_90, rtol=0, atol=1e-15)
    assert_array_equal(first.camera_T_target[:, :3, 3], [[0, 0, 0.8], [0, 0, 0.9]])
    assert_array_equal(m.targets[1].camera_T_target[0, :3, 3], [0.01, 0, 0.5])
    assert_array_equal(m.targets[2].sample, [1])
    assert m.poses == () and m.points == ()


def test_point_observations_offsets_markers_and_groups():
    doc = document(
        sample(
            [0, 0],
            point("head", xyz=[310, 5, 920], offset=[0, 0, 25]),
            point("head", xyz=[1, 2, 3]),
            point("camera", xyz=[4, 5, 6], marker="m1"),
        ),
        sample(
            [0, 0],
            point("head", xyz=[300, 0, 900], offset=[0, 0, 25]),
            point("head", xyz=[7, 8, 9], offset=[0, 0, 30]),
        ),
        length="mm",
    )
    m = measurements_from_dict(doc)
    keys = [(g.frame, None if g.offset is None else g.offset.tolist(), g.marker) for g in m.points]
    assert keys == [
        ("head", [0, 0, 0.025], None),
        ("head", None, None),
        ("camera", None, "m1"),
        ("head", [0, 0, 0.03], None),
    ]
    assert_array_equal(m.points[0].sample, [0, 1])
    assert_array_equal(m.points[0].meas_p_point, [[0.31, 0.005, 0.92], [0.3, 0.0, 0.9]])
    assert_array_equal(m.points[1].meas_p_point, [[0.001, 0.002, 0.003]])
    assert m.points[0].offset.shape == (3,)


def test_measured_in_top_level_default_and_override():
    doc = document(
        sample(
            [0, 0],
            pose("head"),
            pose("head", measured_in="tracker"),
            pose("head", measured_in="world"),
            point("camera"),
            target("camera"),
        ),
        measured_in="mocap",
    )
    m = measurements_from_dict(doc)
    assert [g.measured_in for g in m.poses] == ["mocap", "tracker", "world"]
    assert m.points[0].measured_in == "mocap"
    assert (m.targets[0].camera, m.targets[0].target) == ("camera", "target")
    assert (
        measurements_from_dict(document(sample([0, 0], pose("head")))).poses[0].measured_in is None
    )


def test_groups_in_first_seen_order_with_their_sample_indices():
    doc = document(
        sample([0.1, 0.2], pose("head")),
        sample([0.3, 0.4], point("camera"), pose("slider"), pose("head")),
        sample([0.5, 0.6], pose("slider"), pose("head", marker="plate"), point("camera")),
    )
    m = measurements_from_dict(doc)
    assert [(g.frame, g.marker) for g in m.poses] == [
        ("head", None),
        ("slider", None),
        ("head", "plate"),
    ]
    assert [g.sample.tolist() for g in m.poses] == [[0, 1], [1, 2], [2]]
    assert_array_equal(m.points[0].sample, [1, 2])
    assert m.n_samples == 3
    assert m.observed_frames == ("head", "slider", "camera")
    assert all(g.sample.dtype == np.int64 for g in (*m.poses, *m.points))


def test_unknown_keys_are_ignored_with_a_warning_and_null_optional_keys_are_absent():
    obs = pose("head", quat=[0, 0, S, S], note="left plate", marker=None, measured_in=None)
    doc = document(
        sample([0, 0], obs, point("camera", offset=None, sigma=None)),
        comment="lab 3",
        measured_in=None,
        joint_units=None,
    )
    doc["samples"][0]["timestamp"] = 12.5
    doc["units"]["temperature"] = "C"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        m = measurements_from_dict(doc)
    # a top-level "comment" is known, a null "sigma" absent, the units' keys not checked
    assert sorted(str(w.message) for w in caught) == [
        "<memory>: samples[0].observations[0]: unknown key 'note' on a 'pose' observation "
        "(ignored); known keys: kind, frame, xyz, quat_xyzw, marker, measured_in",
        "<memory>: samples[0]: unknown key 'timestamp' (ignored); known keys: q, "
        "observations, payload",
    ]
    assert (m.poses[0].marker, m.poses[0].measured_in) == (None, None)
    assert m.points[0].offset is None
    assert_allclose(m.poses[0].meas_T_frame[0, :3, :3], ROT_Z_90, rtol=0, atol=1e-15)


def test_quaternion_norm_within_1e6_is_accepted_and_renormalised_silently():
    k = 1.0 + 1e-7
    doc = document(
        sample([0, 0], pose("head", quat=[0, 0, 0, k]), pose("camera", quat=[0, 0, S * k, S * k]))
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = measurements_from_dict(doc)
    assert_array_equal(m.poses[0].meas_T_frame[0], np.eye(4))
    assert_allclose(m.poses[1].meas_T_frame[0, :3, :3], ROT_Z_90, rtol=0, atol=1e-15)


@pytest.mark.parametrize("decimals", [4, 5])
def test_quaternions_rounded_to_few_decimals_are_renormalised_with_one_warning(decimals, tmp_path):
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(decimals)
    quats = rng.normal(size=(30, 4))
    quats = np.round(quats / np.linalg.norm(quats, axis=1, keepdims=True), decimals)
    off = np.abs(np.linalg.norm(quats, axis=1) - 1.0)
    assert off.max() > 1e-6  # the rounding does break the old 1e-6 rule
    doc = document(
        *[sample([0, 0], pose("head", quat=q.tolist()), target("camera")) for q in quats]
    )
    path = write_doc(tmp_path, doc)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        m = read_measurements(path)
    messages = [str(w.message) for w in caught if issubclass(w.category, UserWarning)]
    n_off = int(np.sum(off > 1e-6))
    assert messages == [
        f"{path}: {n_off} of 60 quaternions had norms off by up to "
        f"{off.max():.2g} (rounded?); renormalised"
    ]
    # scipy normalises the quaternion itself: an independent conversion
    assert_allclose(
        m.poses[0].meas_T_frame[:, :3, :3],
        Rotation.from_quat(quats).as_matrix(),
        rtol=0,
        atol=1e-12,
    )


def test_quaternion_norm_1_002_is_rejected_naming_sample_and_observation(tmp_path):
    doc = document(
        sample([0, 0], pose("head")),
        sample([0, 0], pose("head"), pose("camera", quat=[0, 0, 0.6 * 1.002, 0.8 * 1.002])),
    )
    norm = math.hypot(0.6 * 1.002, 0.8 * 1.002)  # 1.002 (a 3-4-5 triangle, scaled)
    assert norm == pytest.approx(1.002, abs=1e-12)
    with pytest.raises(
        DatasetError,
        match=re.escape(
            f"data.json: samples[1].observations[1].quat_xyzw: quaternion norm is {norm:.9g}; "
            "expected a unit quaternion [x, y, z, w] (norm within 0.001 of 1)"
        ),
    ):
        read_measurements(write_doc(tmp_path, doc))


def test_quaternion_norm_1_01_is_rejected_with_the_norm(tmp_path):
    doc = document(
        sample([0, 0], pose("head")),
        sample([0, 0], pose("head"), pose("camera", quat=[0, 0, 0, 1.01])),
    )
    with pytest.raises(
        DatasetError,
        match=re.escape(
            "data.json: samples[1].observations[1].quat_xyzw: quaternion norm is 1.01; "
            "expected a unit quaternion [x, y, z, w] (norm within 0.001 of 1)"
        ),
    ):
        read_measurements(write_doc(tmp_path, doc))


def test_first_bad_quaternion_in_file_order_is_reported():
    doc = document(
        sample([0, 0], pose("head"), pose("camera", quat=[0, 0, 0, 2])),
        sample([0, 0], pose("head", quat=[0, 0, 0, 0.5])),
    )
    with pytest.raises(DatasetError, match=re.escape("samples[0].observations[1].quat_xyzw")):
        measurements_from_dict(doc)


# -- errors ----------------------------------------------------------------------------

DELETE = object()


def valid_document() -> dict:
    return document(
        sample([0.0, 0.1], pose("slider", marker="m1"), target("camera"), point("head")),
        sample([0.2, 0.3], pose("head", xyz=[1, 2, 3], quat=[0, 0, S, S]), point("head")),
    )


def mutated(doc: dict, path: tuple, value: Any) -> dict:
    doc = copy.deepcopy(doc)
    *parents, last = path
    node = doc
    for key in parents:
        node = node[key]
    if value is DELETE:
        del node[last]
    else:
        node[last] = value
    return doc


OBS = ("samples", 1, "observations", 0)
ERROR_CASES = [
    pytest.param(
        ("format",),
        "kinfw-dataset",
        "format: expected 'kinfw-measurements', got 'kinfw-dataset'",
        id="format",
    ),
    pytest.param(
        ("format",), DELETE, "format: missing; expected 'kinfw-measurements'", id="format-missing"
    ),
    pytest.param(
        ("version",),
        2,
        "version: unsupported version 2; this reader supports version 1",
        id="version",
    ),
    pytest.param(("version",), DELETE, "version: missing; expected 1", id="version-missing"),
    pytest.param(("units",), DELETE, "units: missing; expected {", id="units-missing"),
    pytest.param(("units",), "SI", "units: expected an object, got 'SI'", id="units-type"),
    pytest.param(
        ("units", "length"),
        "cm",
        "units.length: expected one of 'm', 'mm', got 'cm'",
        id="length-unit",
    ),
    pytest.param(
        ("units", "angle"),
        DELETE,
        'units.angle: missing; expected "rad" or "deg"',
        id="angle-missing",
    ),
    pytest.param(
        ("units", "angle"),
        "grad",
        "units.angle: expected one of 'rad', 'deg', got 'grad'",
        id="angle-unit",
    ),
    pytest.param(
        ("joint_names",),
        [],
        "joint_names: expected a non-empty list of joint names, got a list of 0 items",
        id="joint-names-empty",
    ),
    pytest.param(
        ("joint_names",),
        DELETE,
        "joint_names: missing; expected a list of joint names",
        id="joint-names-missing",
    ),
    pytest.param(
        ("joint_names",),
        ["slide", 3],
        "joint_names[1]: expected a non-empty string, got 3",
        id="joint-name-type",
    ),
    pytest.param(
        ("joint_names",),
        ["pan", "pan"],
        "joint_names[1]: joint 'pan' is already joint_names[0]; names must be distinct",
        id="joint-names-duplicate",
    ),
    pytest.param(
        ("joint_units",),
        ["m"],
        "joint_units: expected a list of 2 units (one per joint_names entry), got 1",
        id="joint-units-length",
    ),
    pytest.param(
        ("joint_units",),
        ["m", "grad"],
        "joint_units[1]: expected one of 'm', 'mm', 'rad', 'deg', got 'grad'",
        id="joint-units-value",
    ),
    pytest.param(
        ("measured_in",),
        5,
        "measured_in: expected a non-empty string, got 5",
        id="measured-in-type",
    ),
    pytest.param(
        ("samples",),
        [],
        "samples: expected a non-empty list of samples, got a list of 0 items",
        id="samples-empty",
    ),
    pytest.param(
        ("samples",),
        {"q": []},
        "samples: expected a non-empty list of samples, got an object",
        id="samples-type",
    ),
    pytest.param(
        ("samples", 1),
        [0, 1],
        "samples[1]: expected an object, got a list of 2 items",
        id="sample-type",
    ),
    pytest.param(
        ("samples", 1, "q"),
        DELETE,
        "samples[1].q: missing; expected a list of 2 joint values",
        id="q-missing",
    ),
    pytest.param(
        ("samples", 1, "q"),
        None,
        "samples[1].q: null; expected a list of 2 joint values",
        id="q-null",
    ),
    pytest.param(
        ("samples", 1, "q"),
        [0, 1, 2],
        "samples[1].q: expected 2 numbers (one per joint_names entry), got 3",
        id="q-length",
    ),
    pytest.param(
        ("samples", 1, "q"),
        0.5,
        "samples[1].q: expected a list of 2 numbers (one per joint_names entry), got 0.5",
        id="q-type",
    ),
    pytest.param(
        ("samples", 1, "q", 1),
        "0.5",
        "samples[1].q[1]: expected a finite number, got '0.5'",
        id="q-string",
    ),
    pytest.param(
        ("samples", 1, "q", 0),
        True,
        "samples[1].q[0]: expected a finite number, got true",
        id="q-bool",
    ),
    pytest.param(
        ("samples", 1, "q", 0),
        float("nan"),
        "samples[1].q[0]: expected a finite number, got nan",
        id="q-nan",
    ),
    pytest.param(
        ("samples", 1, "observations"),
        DELETE,
        "samples[1].observations: missing; expected a non-empty list of observations",
        id="observations-missing",
    ),
    pytest.param(
        ("samples", 1, "observations"),
        [],
        "samples[1].observations: expected a non-empty list of observations, got a list of 0 items",
        id="observations-empty",
    ),
    pytest.param(
        OBS,
        "head",
        "samples[1].observations[0]: expected an object, got 'head'",
        id="observation-type",
    ),
    pytest.param(
        (*OBS, "frame"),
        DELETE,
        "samples[1].observations[0].frame: missing; expected the name of a URDF frame",
        id="frame-missing",
    ),
    pytest.param(
        (*OBS, "frame"),
        "",
        "samples[1].observations[0].frame: expected a non-empty string, got ''",
        id="frame-empty",
    ),
    pytest.param(
        (*OBS, "kind"),
        "posture",
        "samples[1].observations[0].kind: expected one of 'pose', 'target', 'point', "
        "'plane', 'sphere', 'divot', 'pixels', got 'posture'",
        id="kind",
    ),
    pytest.param(
        (*OBS, "kind"),
        DELETE,
        "samples[1].observations[0].kind: missing; expected 'pose', 'target', 'point', "
        "'plane', 'sphere', 'divot' or 'pixels'",
        id="kind-missing",
    ),
    pytest.param(
        (*OBS, "xyz"),
        [1, 2],
        "samples[1].observations[0].xyz: expected 3 numbers, got 2",
        id="xyz-length",
    ),
    pytest.param(
        (*OBS, "xyz"),
        DELETE,
        "samples[1].observations[0].xyz: missing; expected 3 numbers [x, y, z]",
        id="xyz-missing",
    ),
    pytest.param(
        (*OBS, "xyz", 2),
        float("inf"),
        "samples[1].observations[0].xyz[2]: expected a finite number, got inf",
        id="xyz-inf",
    ),
    pytest.param(
        (*OBS, "xyz", 0),
        None,
        "samples[1].observations[0].xyz[0]: expected a finite number, got null",
        id="xyz-null-element",
    ),
    pytest.param(
        (*OBS, "quat_xyzw"),
        [0, 0, 1],
        "samples[1].observations[0].quat_xyzw: "
        "expected 4 numbers ([x, y, z, w], scalar last), got 3",
        id="quat-length",
    ),
    pytest.param(
        (*OBS, "quat_xyzw"),
        DELETE,
        "samples[1].observations[0].quat_xyzw: "
        "missing; expected 4 numbers [x, y, z, w] (scalar last)",
        id="quat-missing",
    ),
    pytest.param(
        (*OBS, "quat_xyzw"),
        [0, 0, 0, 0],
        "samples[1].observations[0].quat_xyzw: quaternion norm is 0; expected a unit quaternion",
        id="quat-zero",
    ),
    pytest.param(
        (*OBS, "offset"),
        [0, 0, 1],
        "samples[1].observations[0].offset: not allowed on a 'pose' observation",
        id="offset-on-pose",
    ),
    pytest.param(
        (*OBS, "target"),
        "board",
        "samples[1].observations[0].target: not allowed on a 'pose' observation",
        id="target-on-pose",
    ),
    pytest.param(
        (*OBS, "marker"),
        7,
        "samples[1].observations[0].marker: expected a non-empty string, got 7",
        id="marker-type",
    ),
    pytest.param(
        (*OBS, "marker"),
        "m1",
        "samples[1].observations[0].marker: marker 'm1' is "
        "on frame 'head' here but on frame 'slider' in samples[0].observations[0]",
        id="marker-on-two-frames",
    ),
    pytest.param(
        (*OBS, "measured_in"),
        "",
        "samples[1].observations[0].measured_in: expected a non-empty string, got ''",
        id="measured-in-empty",
    ),
    pytest.param(
        ("samples", 0, "observations", 1, "marker"),
        "m2",
        "samples[0].observations[1].marker: not allowed on a 'target' observation",
        id="marker-on-target",
    ),
    pytest.param(
        ("samples", 0, "observations", 1, "measured_in"),
        "mocap",
        "samples[0].observations[1].measured_in: not allowed on a 'target' observation",
        id="measured-in-on-target",
    ),
    pytest.param(
        ("samples", 0, "observations", 1, "offset"),
        [0, 0, 0],
        "samples[0].observations[1].offset: not allowed on a 'target' observation",
        id="offset-on-target",
    ),
    pytest.param(
        ("samples", 1, "observations", 1, "quat_xyzw"),
        [0, 0, 0, 1],
        "samples[1].observations[1].quat_xyzw: not allowed on a 'point' observation",
        id="quat-on-point",
    ),
    pytest.param(
        ("samples", 1, "observations", 1, "offset"),
        [0, 0],
        "samples[1].observations[1].offset: expected 3 numbers, got 2",
        id="offset-length",
    ),
    pytest.param(
        ("samples", 1, "observations", 1),
        point("head", offset=[0, 0, 1], marker="m3"),
        "samples[1].observations[1].offset: an offset and a marker ('m3') exclude each other",
        id="offset-and-marker",
    ),
]


@pytest.mark.parametrize(("path", "value", "message"), ERROR_CASES)
def test_every_error_names_file_sample_key_and_expectation(tmp_path, path, value, message):
    file = write_doc(tmp_path, mutated(valid_document(), path, value))
    with pytest.raises(DatasetError, match=re.escape(f"{file}: {message}")):
        read_measurements(file)


def test_valid_document_used_by_the_error_cases_reads():
    m = measurements_from_dict(valid_document())
    assert (len(m.poses), len(m.targets), len(m.points)) == (2, 1, 1)


def test_missing_file(tmp_path):
    with pytest.raises(DatasetError, match=r"nothere\.json: measurement file not found"):
        read_measurements(tmp_path / "nothere.json")


def test_invalid_json_gives_line_and_column(tmp_path):
    path = tmp_path / "broken.json"
    path.write_text('{\n  "format": "kinfw-measurements",\n  "version": 1,\n}')
    with pytest.raises(DatasetError, match=r"broken\.json: invalid JSON at line 4, column 1"):
        read_measurements(path)


def test_top_level_must_be_an_object(tmp_path):
    path = write_doc(tmp_path, [1, 2])
    with pytest.raises(
        DatasetError,
        match=r"data\.json: expected a JSON object at the top "
        r"level, got a list of 2 items",
    ):
        read_measurements(path)


def test_errors_from_a_dict_name_the_given_source():
    with pytest.raises(DatasetError, match=r"^lab3\.json: version: unsupported version 2"):
        measurements_from_dict(mutated(valid_document(), ("version",), 2), source="lab3.json")
    with pytest.raises(DatasetError, match=r"^<memory>: version"):
        measurements_from_dict(mutated(valid_document(), ("version",), 2))


# -- round trips and invariance (Hypothesis) -------------------------------------------

finite = st.floats(-10.0, 10.0, allow_nan=False, allow_infinity=False)
quaternions = st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4).filter(
    lambda q: np.linalg.norm(q) > 0.1
)
observation_docs = st.one_of(
    st.builds(
        lambda f, x, q, mk, mi: pose(
            f,
            x,
            (q / np.linalg.norm(q)).tolist(),
            **({"marker": f"{f}_{mk}"} if mk else {}),
            **({"measured_in": mi} if mi else {}),
        ),
        st.sampled_from(["head", "slider"]),
        st.lists(finite, min_size=3, max_size=3),
        quaternions.map(np.array),
        st.sampled_from([None, "plate"]),
        st.sampled_from([None, "mocap"]),
    ),
    st.builds(
        lambda f, x, q, t: target(
            f, x, (q / np.linalg.norm(q)).tolist(), **({"target": t} if t else {})
        ),
        st.sampled_from(["camera", "head"]),
        st.lists(finite, min_size=3, max_size=3),
        quaternions.map(np.array),
        st.sampled_from([None, "board"]),
    ),
    st.builds(
        lambda f, x, off, mi: point(
            f, x, **({"offset": off} if off else {}), **({"measured_in": mi} if mi else {})
        ),
        st.sampled_from(["head", "camera"]),
        st.lists(finite, min_size=3, max_size=3),
        st.sampled_from([None, [0.0, 0.0, 0.025], [0.1, -0.2, 0.3]]),
        st.sampled_from([None, "tracker"]),
    ),
)
sample_docs = st.builds(
    lambda q, observations: sample(q, *observations),
    st.lists(finite, min_size=2, max_size=2),
    st.lists(observation_docs, min_size=1, max_size=4),
)
datasets = st.lists(sample_docs, min_size=1, max_size=6).map(lambda ss: document(*ss))


def assert_same_groups(a: Measurements, b: Measurements, b_to_a=None, *, atol=0.0) -> None:
    """Groups equal by key; b's sample indices mapped through b_to_a first."""
    ga, gb = groups_by_key(a), groups_by_key(b)
    assert set(ga) == set(gb)
    for key, group_a in ga.items():
        group_b = gb[key]
        mapped = group_b.sample if b_to_a is None else b_to_a[group_b.sample]
        order = np.argsort(mapped, kind="stable")
        assert_array_equal(mapped[order], group_a.sample)
        assert_allclose(data_of(group_b)[order], data_of(group_a), rtol=0, atol=atol)


# Writing a pose stores its quaternion, and matrix -> quaternion -> matrix loses up to ~7 ulp
# (1.6e-15 measured over 1e6 random rotations; 0.3% exceed 1e-15), so rotations compare
# within 4e-15. Joint values, positions and offsets are written with repr and come back exact.
ROT_ATOL = 4e-15


@pytest.mark.slow
@settings(max_examples=60, deadline=None)
@given(datasets)
def test_write_read_round_trip(tmp_path_factory, doc):
    m = measurements_from_dict(doc, source="orig")
    path = tmp_path_factory.mktemp("rt") / "rt.json"
    write_measurements(path, m)
    back = read_measurements(path)
    assert back.source == str(path)
    assert back.joint_names == m.joint_names
    assert_array_equal(back.qs, m.qs)
    assert_same_groups(m, back, atol=ROT_ATOL)
    for key, g in groups_by_key(m).items():
        g_back = groups_by_key(back)[key]
        if isinstance(g, PointObservations):
            assert_array_equal(g_back.meas_p_point, g.meas_p_point)
        else:
            assert_array_equal(data_of(g_back)[:, :3, 3], data_of(g)[:, :3, 3])
    assert set(back.observed_frames) == set(m.observed_frames)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(st.lists(finite, min_size=3, max_size=3), quaternions), min_size=1, max_size=8
    ),
    st.sampled_from([None, "mocap"]),
)
def test_round_trip_of_constructed_poses(tmp_path_factory, poses, measured_in):
    xyzs = np.array([p for p, _ in poses])
    quats = np.array([q for _, q in poses])
    n = len(poses)
    meas_T_frames = transform_from_xyz_quat_xyzw(xyzs, quats)
    m = Measurements(
        ("pan",),
        np.linspace(-1, 1, n)[:, None],
        poses=(PoseObservations("head", np.arange(n), meas_T_frames, measured_in=measured_in),),
        targets=(TargetObservations("camera", np.arange(n)[::-1], meas_T_frames, target="board"),),
        points=(
            PointObservations(
                "head", np.arange(n), xyzs, offset=[0.0, 0.0, 0.1], measured_in=measured_in
            ),
        ),
    )
    path = tmp_path_factory.mktemp("rt") / "rt.json"
    write_measurements(path, m)
    back = read_measurements(path)
    assert_array_equal(back.qs, m.qs)
    assert_allclose(back.poses[0].meas_T_frame, meas_T_frames, rtol=0, atol=ROT_ATOL)
    assert_array_equal(back.poses[0].meas_T_frame[:, :3, 3], xyzs)
    assert back.poses[0].measured_in == measured_in
    assert back.points[0].measured_in == measured_in
    assert_allclose(back.targets[0].camera_T_target, meas_T_frames[::-1], rtol=0, atol=ROT_ATOL)
    assert back.targets[0].target == "board"
    assert_array_equal(back.points[0].meas_p_point, xyzs)
    assert_array_equal(back.points[0].offset, [0.0, 0.0, 0.1])


@pytest.mark.slow
@settings(max_examples=80, deadline=None)
@given(datasets.flatmap(lambda d: st.tuples(st.just(d), st.permutations(range(len(d["samples"]))))))
def test_groups_do_not_depend_on_sample_order(doc_and_perm):
    doc, perm = doc_and_perm
    permuted = dict(doc, samples=[doc["samples"][i] for i in perm])
    m = measurements_from_dict(doc)
    m_perm = measurements_from_dict(permuted)
    new_to_old = np.array(perm)
    assert_array_equal(m_perm.qs, m.qs[new_to_old])
    assert_same_groups(m, m_perm, new_to_old)  # exact: the same numbers, the same arithmetic
    assert set(m_perm.observed_frames) == set(m.observed_frames)


def test_length_unit_mm_file_equals_m_file():
    in_m = document(
        sample(
            [0.1, 0.2],
            pose("head", [0.1, 0.25, 1.5], [0, 0, S, S]),
            point("camera", [0.3, 0.0, 0.002], offset=[0, 0, 0.025]),
        )
    )
    in_mm = document(
        sample(
            [0.1, 0.2],
            pose("head", [100, 250, 1500], [0, 0, S, S]),
            point("camera", [300, 0, 2], offset=[0, 0, 25]),
        ),
        length="mm",
    )
    assert_same_groups(measurements_from_dict(in_m), measurements_from_dict(in_mm))


def test_writer_writes_si_units_and_a_common_measured_in_once(tmp_path):
    doc = document(
        sample([90, 0], pose("head", [100, 0, 0])), length="mm", angle="deg", measured_in="mocap"
    )
    path = tmp_path / "out.json"
    write_measurements(path, measurements_from_dict(doc))
    written = json.loads(path.read_text())
    assert written["units"] == {"length": "m", "angle": "rad"}
    assert "joint_units" not in written
    assert written["measured_in"] == "mocap"
    obs = written["samples"][0]["observations"][0]
    assert "measured_in" not in obs
    assert obs["xyz"] == [0.1, 0.0, 0.0]
    assert written["samples"][0]["q"] == [math.pi / 2, 0.0]


def test_writer_rejects_a_sample_without_observations():
    m = Measurements(
        ("pan",),
        [[0.0], [1.0]],
        poses=(PoseObservations("head", [0], np.eye(4)[None]),),
        source="s.json",
    )
    with pytest.raises(DatasetError, match=re.escape("s.json: samples[1]: has no observations")):
        measurements_to_dict(m)


# -- the dataclasses -------------------------------------------------------------------


def test_arrays_are_read_only():
    m = measurements_from_dict(valid_document())
    with pytest.raises(ValueError, match="read-only"):
        m.qs[0, 0] = 1.0
    with pytest.raises(ValueError, match="read-only"):
        m.poses[0].meas_T_frame[0, 0, 3] = 1.0


def test_constructor_validation():
    with pytest.raises(DatasetError, match=re.escape("x.json: qs: expected shape (n, 2)")):
        Measurements(("a", "b"), np.zeros((3, 3)), source="x.json")
    with pytest.raises(DatasetError, match="refers to sample 3, but there are 3 samples"):
        Measurements(
            ("a",), np.zeros((3, 1)), poses=(PoseObservations("head", [3], np.eye(4)[None]),)
        )
    with pytest.raises(DatasetError, match="joint 'a' is listed twice"):
        Measurements(("a", "a"), np.zeros((1, 2)))
    with pytest.raises(ValueError, match=re.escape("meas_T_frame: expected shape (2, 4, 4)")):
        PoseObservations("head", [0, 1], np.eye(4)[None])
    with pytest.raises(ValueError, match="not a rotation matrix"):
        PoseObservations("head", [0], np.diag([2.0, 1.0, 1.0, 1.0])[None])
    with pytest.raises(ValueError, match=re.escape("offset: expected shape (3,)")):
        PointObservations("head", [0], np.zeros((1, 3)), offset=[0, 0])


def test_subset_renumbers_filters_and_drops_empty_groups():
    doc = document(
        sample([0.0, 0.0], pose("head", [0, 0, 0])),
        sample([1.0, 0.0], pose("head", [1, 0, 0]), point("camera", [1, 1, 1])),
        sample([2.0, 0.0], pose("head", [2, 0, 0]), target("camera")),
        sample([3.0, 0.0], pose("head", [3, 0, 0])),
    )
    m = measurements_from_dict(doc)
    sub = m.subset([3, 1])
    assert_array_equal(sub.qs[:, 0], [3.0, 1.0])
    assert_array_equal(sub.poses[0].sample, [0, 1])
    assert_array_equal(sub.poses[0].meas_T_frame[:, 0, 3], [3.0, 1.0])
    assert_array_equal(sub.points[0].sample, [1])
    assert sub.targets == ()  # its only sample (2) was dropped
    assert sub.observed_frames == ("head", "camera")

    boot = m.subset([1, 1, 0])  # a bootstrap draw repeats samples
    assert_array_equal(boot.poses[0].sample, [0, 1, 2])
    assert_array_equal(boot.poses[0].meas_T_frame[:, 0, 3], [1.0, 1.0, 0.0])
    assert_array_equal(boot.points[0].sample, [0, 1])

    masked = m.subset(np.array([False, True, True, False]))
    assert_array_equal(masked.qs[:, 0], [1.0, 2.0])
    assert_array_equal(masked.targets[0].sample, [1])
    assert m.subset([]).n_samples == 0
    with pytest.raises(IndexError, match="sample index 4 is out of range for 4 samples"):
        m.subset([0, 4])
    with pytest.raises(ValueError, match="boolean mask needs shape"):
        m.subset([True, False])


def test_q_of_reorders_columns_and_holds_other_joints_at_zero():
    m = Measurements(("pan", "tilt"), [[0.1, 0.2], [0.3, 0.4]])
    assert_array_equal(m.q_of(["tilt", "slide", "pan"]), [[0.2, 0.0, 0.1], [0.4, 0.0, 0.3]])
    assert m.q_of([]).shape == (2, 0)


def test_observed_frames_in_first_seen_order_without_duplicates():
    doc = document(
        sample([0, 0], point("camera"), pose("head")),
        sample([0, 0], target("camera"), pose("slider"), pose("head", marker="p")),
    )
    m = measurements_from_dict(doc)
    # Sample 0: poses before points at the same sample; then sample 1 adds slider.
    assert m.observed_frames == ("head", "camera", "slider")


# -- check_against_robot ---------------------------------------------------------------


def robot_doc(*samples: dict, **top: Any) -> Measurements:
    return measurements_from_dict(document(*samples, **top), source="data.json")


def test_check_against_robot_accepts_a_good_dataset(robot):
    m = robot_doc(sample([0.1, 0.2], pose("camera"), point("head", measured_in="mocap")))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert check_against_robot(m, robot) is m


def test_check_against_robot_unknown_joint(robot):
    m = robot_doc(sample([0, 0], pose("head")), joint_names=["slide", "elbow"])
    with pytest.raises(
        DatasetError,
        match=re.escape(
            "data.json: joint_names[1]: joint 'elbow' is not in <urdf string>; its movable "
            "joints are ['slide', 'pan', 'spin']"
        ),
    ):
        check_against_robot(m, robot)


def test_check_against_robot_fixed_joint(robot):
    m = robot_doc(sample([0], pose("head")), joint_names=["cam_mount"])
    with pytest.raises(
        DatasetError,
        match=re.escape(
            "data.json: joint_names[0]: joint 'cam_mount' is a fixed joint in <urdf string>; "
            "only movable joints can be listed: ['slide', 'pan', 'spin']"
        ),
    ):
        check_against_robot(m, robot)


def test_check_against_robot_unknown_frame_names_first_sample(robot):
    m = robot_doc(
        sample([0, 0], pose("head")),
        sample([0, 0], pose("head")),
        sample([0, 0], pose("head"), point("gripper")),
        sample([0, 0], point("gripper")),
    )
    with pytest.raises(
        DatasetError,
        match=re.escape(
            "data.json: samples[2]: frame 'gripper' (point observation) is not a link or joint "
            "of <urdf string>"
        ),
    ):
        check_against_robot(m, robot)


def test_check_against_robot_unsupported_joint_on_path(robot):
    m = robot_doc(sample([0, 0], pose("puck")))
    with pytest.raises(
        DatasetError,
        match=r"samples\[0\]: frame 'puck' cannot be calibrated.*"
        r"joint 'loose'.*floating",
    ):
        check_against_robot(m, robot)


def test_check_against_robot_root_measured_in_becomes_none_and_groups_merge(robot):
    m = robot_doc(
        sample([0, 0], pose("head", [0, 0, 0], measured_in="world")),
        sample([0, 0], pose("head", [1, 0, 0])),
        sample(
            [0, 0],
            pose("head", [2, 0, 0], measured_in="world"),
            point("camera", measured_in="world"),
        ),
    )
    assert len(m.poses) == 2
    checked = check_against_robot(m, robot)
    assert checked is not m
    assert len(checked.poses) == 1
    assert checked.poses[0].measured_in is None
    assert_array_equal(checked.poses[0].sample, [0, 1, 2])
    assert_array_equal(checked.poses[0].meas_T_frame[:, 0, 3], [0.0, 1.0, 2.0])
    assert checked.points[0].measured_in is None
    assert m.poses[0].measured_in == "world"  # the input is unchanged


def test_check_against_robot_external_measured_in_is_kept(robot):
    m = robot_doc(sample([0, 0], pose("head")), measured_in="mocap")
    assert check_against_robot(m, robot).poses[0].measured_in == "mocap"


def test_check_against_robot_keeps_a_robot_frame_as_measured_in_but_not_the_frame_itself(robot):
    # a frame of the URDF other than the root is a measurement frame that moves with the
    # robot (tests/kinfw/observations/test_measured_in_robot.py); an observation in its own
    # frame is refused
    m = robot_doc(sample([0, 0], pose("head")), sample([0, 0], pose("head", measured_in="base")))
    assert {g.measured_in for g in check_against_robot(m, robot).poses} == {None, "base"}
    m = robot_doc(sample([0, 0], pose("head")), sample([0, 0], pose("head", measured_in="head")))
    with pytest.raises(
        DatasetError,
        match=re.escape(
            "data.json: samples[1]: a pose observation of frame 'head' is measured in 'head' itself"
        ),
    ):
        check_against_robot(m, robot)


def test_check_against_robot_warns_once_per_joint_outside_limits(robot):
    m = robot_doc(
        sample([0.1, 0.0, 100.0], pose("head")),
        sample([0.7, 1.4, -100.0], pose("head")),
        sample([0.9, 1.6, 0.0], pose("head")),
        sample([-0.6, 0.0, 0.0], pose("head")),
        joint_names=["slide", "pan", "spin"],
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_against_robot(m, robot)
    messages = [str(w.message) for w in caught]
    assert all(w.category is UserWarning for w in caught)
    assert messages == [
        "data.json: joint 'slide' is outside its URDF limits [-0.5, 0.5] m in 3 of 4 samples "
        "(first: samples[1], value 0.7 m)",
        "data.json: joint 'pan' is outside its URDF limits [-1.5, 1.5] rad in 1 of 4 samples "
        "(first: samples[2], value 1.6 rad)",
    ]  # 'spin' is continuous: no limits
    with pytest.warns(UserWarning, match=r"joint '(slide|pan)' is outside its URDF limits"):
        check_against_robot(m, robot)


# -- check_joint_motion ----------------------------------------------------------------


def motion_data(tilt: np.ndarray) -> Measurements:
    pan = np.linspace(-1.0, 1.0, len(tilt))
    return Measurements(("pan", "tilt"), np.column_stack([pan, tilt]), source="DATA.json")


def test_check_joint_motion_names_a_joint_that_does_not_move():
    m = motion_data(np.full(90, 0.3))
    with pytest.raises(
        DatasetError,
        match=re.escape(
            "DATA.json: joint 'tilt' moves through 1 distinct value (0.3) in 90 samples; at "
            "least 2 are needed to identify it"
        ),
    ):
        check_joint_motion(m, ["pan", "tilt"])


def test_check_joint_motion_a_joint_not_in_the_data_is_held_at_zero():
    m = motion_data(np.linspace(0, 1, 90))
    with pytest.raises(
        DatasetError,
        match=re.escape(
            "DATA.json: joint 'vergence' (not in joint_names, so held at zero) moves through 1 "
            "distinct value (0) in 90 samples; at least 2 are needed"
        ),
    ):
        check_joint_motion(m, ["pan", "vergence"])


def test_check_joint_motion_treats_values_closer_than_1e9_as_equal():
    m = motion_data(np.array([0.3, 0.3 + 1e-10, 0.3 - 1e-10]))
    with pytest.raises(DatasetError, match=r"joint 'tilt' moves through 1 distinct value"):
        check_joint_motion(m, ["tilt"])
    check_joint_motion(motion_data(np.array([0.3, 0.3 + 1e-6, 0.3])), ["tilt"])


def test_check_joint_motion_min_distinct_and_all_joints_reported():
    m = motion_data(np.array([0.2, -0.1, 0.2, -0.1]))
    check_joint_motion(m, ["pan", "tilt"])
    with pytest.raises(
        DatasetError,
        match=re.escape(
            "DATA.json: joint 'tilt' moves through 2 distinct values (-0.1, 0.2) in 4 samples; "
            "at least 3 are needed to identify it; joint 'lift' (not in joint_names"
        ),
    ):
        check_joint_motion(m, ["pan", "tilt", "lift"], min_distinct=3)
    with pytest.raises(ValueError, match="min_distinct must be >= 1"):
        check_joint_motion(m, ["pan"], min_distinct=0)
    with pytest.raises(TypeError, match="not a string"):
        check_joint_motion(m, "pan")


def test_concatenate_shifts_samples_unites_joints_and_merges_groups():
    a = Measurements(
        joint_names=("j1",),
        qs=np.array([[0.1], [0.2]]),
        poses=(PoseObservations("f", np.array([0, 1]), np.stack([np.eye(4)] * 2)),),
    )
    T = np.eye(4)
    T[0, 3] = 5.0
    b = Measurements(
        joint_names=("j2", "j1"),
        qs=np.array([[1.0, 0.3]]),
        poses=(PoseObservations("f", np.array([0]), T[None]),),
        points=(PointObservations("g", np.array([0]), np.array([[1.0, 2.0, 3.0]])),),
    )
    c = concatenate_measurements(a, b)
    assert c.joint_names == ("j1", "j2")
    np.testing.assert_array_equal(c.qs, [[0.1, 0.0], [0.2, 0.0], [0.3, 1.0]])
    assert len(c.poses) == 1
    np.testing.assert_array_equal(c.poses[0].sample, [0, 1, 2])
    assert c.poses[0].meas_T_frame[2, 0, 3] == 5.0
    np.testing.assert_array_equal(c.points[0].sample, [2])
    with pytest.raises(ValueError, match="at least one"):
        concatenate_measurements()


def test_the_documentation_examples_parse():
    """Every JSON example in docs/measurements.md is a valid file or observation, with no
    key the reader does not know (no warning at all)."""
    import re

    doc = (REPO / "docs" / "measurements.md").read_text()
    blocks = [json.loads(b) for b in re.findall(r"```json\n(.*?)```", doc, re.S)]
    assert len(blocks) >= 5
    for block in blocks:
        if "samples" not in block:  # a single observation: wrap it
            block = {
                "format": "kinfw-measurements",
                "version": 1,
                "units": {"length": "m", "angle": "rad"},
                "joint_names": ["a"],
                "samples": [{"q": [0.0], "observations": [block]}],
            }
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            assert measurements_from_dict(block, "docs").n_samples >= 1


def test_a_misspelled_plane_is_refused_naming_its_sample_and_the_likely_name():
    """One contact of 60 names plane 'tabel': read as written it is a plane of its own,
    which one contact cannot place (the model choice then refused every set, naming the
    sample as if it were the problem). Refused before any fit, naming the sample and
    'table'; a plane of a different name with one contact ('wall') is not a misspelling
    and passes this check."""
    from dataclasses import replace

    from kinfw.measurements import check_against_robot
    from kinfw.simulation import simulate_measurements
    from tests.robots import ARM_6R

    arm = load_robot(ARM_6R)
    data = simulate_measurements(
        arm, contacts=[("flange", None)], contact_samples=20, noise_m=1e-4, seed=3
    ).data
    (table,) = data.others

    def renamed(name):
        take = kind_of(table).take
        rest = np.setdiff1d(np.arange(len(table.sample)), [7])
        one = take(table, np.array([7]), table.sample[[7]])
        return data.with_groups([take(table, rest, table.sample[rest]), replace(one, plane=name)])

    with pytest.raises(DatasetError) as refused:
        check_against_robot(renamed("tabel"), arm)
    said = str(refused.value)
    assert f"plane 'tabel' is observed 1 time(s) (samples[{table.sample[7]}])" in said
    assert "fewer than 3 observations cannot place" in said
    assert "plane 'table' 19 times: a misspelling of 'table'?" in said
    assert check_against_robot(renamed("wall"), arm).n_samples == data.n_samples
