"""Payloads and gravity in measurement files and datasets: hand-written files with known
numbers (a com in mm is the com in m / 1000, the URDF-order inertia is the symmetric
matrix), exact round trips, the key path of every error, the bulk path reading them, and
subsets, merges and the robot check carrying them."""

from __future__ import annotations

import copy
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_array_equal

from kinfw.measurements import _file as file_module
from kinfw.measurements import (
    check_against_robot,
    concatenate_measurements,
    measurements_from_dict,
    measurements_to_dict,
    read_measurements,
    write_measurements,
)
from kinfw.model import STANDARD_GRAVITY, Payloads, load_robot
from kinfw.observations import DatasetError
from tests.kinfw.measurements.test_measurements import URDF, document, pose, sample

PAYLOAD = {"frame": "head", "mass_kg": 2.5, "com": [10.0, -20.0, 30.0]}
INERTIA = [0.4, 0.01, -0.02, 0.5, 0.03, 0.6]  # ixx, ixy, ixz, iyy, iyz, izz
INERTIA_MATRIX = np.array([[0.4, 0.01, -0.02], [0.01, 0.5, 0.03], [-0.02, 0.03, 0.6]])


def _document(n: int = 6, length: str = "mm", **top) -> dict:
    """``n`` samples with a pose each; even samples carry a payload (sample 2 with an
    inertia, sample 4 on another frame), odd ones none."""
    samples = []
    for i in range(n):
        s = sample([0.01 * i, -0.02 * i], pose("head", xyz=[1.0 * i, 2.0, 3.0]))
        if i % 2 == 0:
            s["payload"] = {**PAYLOAD, "mass_kg": 2.5 + i}
        if i == 2:
            s["payload"]["inertia"] = list(INERTIA)
        if i == 4:
            s["payload"] = {"frame": "camera", "mass_kg": 0.0}
        samples.append(s)
    return document(*samples, length=length, **top)


def _read(doc: dict, *, bulk: bool, monkeypatch: pytest.MonkeyPatch):
    """The dataset read with or without the bulk path, and whether the bulk path read its
    observations and its payloads."""
    used = []

    def spy(name):
        original = getattr(file_module, name)

        def call(*args):
            out = original(*args) if bulk else None
            used.append(out is not None)
            return out

        return call

    with monkeypatch.context() as m:
        m.setattr(file_module, "_read_samples_in_bulk", spy("_read_samples_in_bulk"))
        m.setattr(file_module, "_payloads_in_bulk", spy("_payloads_in_bulk"))
        return measurements_from_dict(copy.deepcopy(doc), source="data.json"), used


@pytest.mark.parametrize("bulk", [True, False])
def test_payloads_are_read_in_si_with_the_file_length_unit(bulk, monkeypatch):
    data, used = _read(_document(), bulk=bulk, monkeypatch=monkeypatch)
    assert used == ([True, True] if bulk else [False])
    p = data.payloads
    assert p.frames == ("head", "camera")
    assert_array_equal(p.frame_index, [0, -1, 0, -1, 1, -1])
    assert_array_equal(p.mass_kg, [2.5, 0.0, 4.5, 0.0, 0.0, 0.0])
    assert_array_equal(p.com_m[0], [0.01, -0.02, 0.03])  # mm / 1000
    assert_array_equal(p.com_m[4], [0.0, 0.0, 0.0])  # default com: the frame's origin
    assert_array_equal(p.inertia_kg_m2[2], INERTIA_MATRIX)
    assert_array_equal(p.inertia_kg_m2[0], np.zeros((3, 3)))
    assert_array_equal(data.gravity, STANDARD_GRAVITY)


def test_a_file_without_payloads_has_none_and_the_standard_gravity():
    doc = document(sample([0, 0], pose("head")))
    data = measurements_from_dict(doc)
    assert data.payloads is None
    assert data.sample_payloads().equals(Payloads.none(1))
    assert_array_equal(data.gravity, [0.0, 0.0, -9.81])
    assert not data.gravity.flags.writeable


def test_gravity_is_read_from_the_top_level():
    data = measurements_from_dict(_document(gravity=[0.0, 9.81, 0.0]))  # a wall-mounted arm
    assert_array_equal(data.gravity, [0.0, 9.81, 0.0])


def test_write_then_read_gives_the_same_payloads_and_gravity(tmp_path):
    data = measurements_from_dict(_document(gravity=[0.1, -0.2, -9.8]))
    write_measurements(tmp_path / "out.json", data)
    back = read_measurements(tmp_path / "out.json")
    assert back.payloads.equals(data.payloads)
    assert_array_equal(back.gravity, data.gravity)
    doc = measurements_to_dict(data)
    assert ["payload" in s for s in doc["samples"]] == [True, False, True, False, True, False]
    assert doc["samples"][4]["payload"] == {"frame": "camera", "mass_kg": 0.0}
    assert doc["samples"][2]["payload"]["inertia"] == INERTIA
    assert doc["gravity"] == [0.1, -0.2, -9.8]
    plain = measurements_to_dict(measurements_from_dict(document(sample([0, 0], pose("head")))))
    assert "gravity" not in plain
    assert "payload" not in plain["samples"][0]


def _with(change) -> dict:
    doc = _document()
    change(doc)
    return doc


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (
            lambda d: d["samples"][2]["payload"].__setitem__("mass_kg", -1),
            r"^data\.json: samples\[2\]\.payload\.mass_kg: expected a number >= 0 \(kg\), got -1$",
        ),
        (
            lambda d: d["samples"][0]["payload"].pop("frame"),
            r"samples\[0\]\.payload\.frame: missing; expected the name of a URDF link",
        ),
        (
            lambda d: d["samples"][0]["payload"].__setitem__("mass_kg", "2"),
            r"samples\[0\]\.payload\.mass_kg: expected a number >= 0 \(kg\), got '2'",
        ),
        (
            lambda d: d["samples"][0]["payload"].__setitem__("com", [1.0, 2.0]),
            r"samples\[0\]\.payload\.com: expected 3 numbers \(\[x, y, z\] in 'head'\), got 2",
        ),
        (
            lambda d: d["samples"][2]["payload"]["inertia"].__setitem__(3, True),
            r"samples\[2\]\.payload\.inertia\[3\]: expected a finite number, got true",
        ),
        (
            lambda d: d["samples"][2]["payload"].__setitem__("inertia", [-1, 0, 0, 1, 0, 1]),
            r"samples\[2\]\.payload\.inertia: \[-1\.0, .*no rotational inertia",
        ),
        (
            lambda d: d["samples"][4].__setitem__("payload", "camera"),
            r"samples\[4\]\.payload: expected an object, got 'camera'",
        ),
        (lambda d: d.__setitem__("gravity", [0, -9.81]), r"^data\.json: gravity: expected 3"),
        (lambda d: d.__setitem__("gravity", [0, 0, -9810]), r"gravity: its norm is 9810 m/s\^2"),
        (lambda d: d.__setitem__("gravity", [0, 0, 0]), r"gravity: its norm is 0 m/s\^2"),
    ],
)
@pytest.mark.parametrize("bulk", [True, False])
def test_a_broken_payload_or_gravity_is_an_error_naming_its_key_path(
    change, match, bulk, monkeypatch
):
    with pytest.raises(DatasetError, match=match):
        _read(_with(change), bulk=bulk, monkeypatch=monkeypatch)


def test_a_subset_keeps_the_payloads_of_its_samples():
    data = measurements_from_dict(_document())
    part = data.subset([4, 2, 2, 1])
    assert part.payloads.equals(data.payloads.subset([4, 2, 2, 1]))
    assert_array_equal(part.payloads.mass_kg, [0.0, 4.5, 4.5, 0.0])
    assert [part.payloads.frames[i] if i >= 0 else None for i in part.payloads.frame_index] == [
        "camera",
        "head",
        "head",
        None,
    ]
    mask = data.subset(np.arange(6) % 2 == 0)
    assert_array_equal(mask.payloads.mass_kg, [2.5, 4.5, 0.0])
    assert_array_equal(data.subset([1, 3]).gravity, data.gravity)


def test_a_merge_keeps_each_sample_s_payload_and_refuses_two_gravities():
    with_payloads = measurements_from_dict(_document(4))
    without = measurements_from_dict(document(sample([0, 0], pose("head"))))
    both = concatenate_measurements(without, with_payloads)
    assert both.payloads.equals(Payloads.none(1).concatenate(with_payloads.payloads))
    assert concatenate_measurements(without, without).payloads is None
    tilted = measurements_from_dict(document(sample([0, 0], pose("head")), gravity=[0, 9.81, 0]))
    with pytest.raises(DatasetError, match=r"gravity \[0\.0, 9\.81, 0\.0\] m/s\^2 differs"):
        concatenate_measurements(without, tilted)


def test_a_dataset_refuses_payloads_of_another_length_and_absurd_gravity():
    data = measurements_from_dict(_document())
    with pytest.raises(DatasetError, match=r"data\.json: payloads: expected one entry per sample"):
        data.__class__(data.joint_names, data.qs, source="data.json", payloads=Payloads.none(5))
    with pytest.raises(DatasetError, match=r"^data\.json: gravity: its norm is 0\.0981"):
        data.__class__(data.joint_names, data.qs, source="data.json", gravity=(0, 0, -0.0981))
    with pytest.raises(DatasetError, match=r"gravity: expected 3 finite numbers"):
        data.__class__(data.joint_names, data.qs, gravity=(0, np.nan, -9.81))


def test_the_robot_check_names_a_payload_frame_the_robot_lacks():
    robot = load_robot(URDF)
    doc = _document()
    doc["samples"][2]["payload"]["frame"] = "haed"
    data = measurements_from_dict(doc, source="data.json")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # joint limits
        check_against_robot(measurements_from_dict(_document()), robot)
        with pytest.raises(DatasetError) as err:
            check_against_robot(data, robot)
    assert str(err.value).startswith(
        "data.json: samples[2].payload.frame: 'haed' is not a frame of "
    )
    assert str(err.value).endswith("closest links: 'head'")


_payload = st.one_of(
    st.none(),
    st.tuples(
        st.sampled_from(["head", "camera", "slider"]),
        st.floats(0.0, 50.0),
        st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3),
        st.lists(st.floats(0.0, 2.0), min_size=3, max_size=3),  # principal moments
        st.floats(-3.0, 3.0),  # a rotation of the principal axes about z
    ),
)


@settings(max_examples=40, deadline=None)
@given(st.lists(_payload, min_size=1, max_size=12))
def test_any_payloads_write_and_read_back_equal(tmp_path_factory, payloads):
    samples = []
    for i, p in enumerate(payloads):
        s = sample([0.01 * i, 0.0], pose("head"))
        if p is not None:
            frame, mass, com, moments, angle = p
            c, s_ = np.cos(angle), np.sin(angle)
            R = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
            inertia = R @ np.diag(moments) @ R.T
            six = inertia[[0, 0, 0, 1, 1, 2], [0, 1, 2, 1, 2, 2]].tolist()  # URDF order
            s["payload"] = {"frame": frame, "mass_kg": mass, "com": com, "inertia": six}
        samples.append(s)
    data = measurements_from_dict(document(*samples))
    path = tmp_path_factory.mktemp("round") / "out.json"
    write_measurements(path, data)
    back = read_measurements(path)
    if data.payloads is None:
        assert back.payloads is None and all(p is None for p in payloads)
    else:
        assert back.payloads.equals(data.payloads)
        assert_array_equal(back.payloads.mass_kg, [0.0 if p is None else p[1] for p in payloads])
