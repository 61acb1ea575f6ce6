"""The bulk reader of measurement files (every ``q`` at once, ``pose`` and ``target``
observations by signature) against the one-at-a-time reader it replaces: the same
groups, rows, warnings and errors."""

from __future__ import annotations

import copy
import warnings

import numpy as np
import pytest

import kinfw.measurements._file as file_module
from kinfw.measurements import measurements_from_dict
from kinfw.observations import DatasetError


def _quat(rng: np.random.Generator, decimals: int | None = None) -> list[float]:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    return (np.round(q, decimals) if decimals else q).tolist()


def _document(n: int = 40, seed: int = 0) -> dict:
    """Poses (plain, with a marker, in another frame), targets (two cameras, a named
    target on a frame), integers among the numbers, rounded quaternions, mm and deg."""
    rng = np.random.default_rng(seed)
    samples = []
    for i in range(n):
        obs = [
            {
                "frame": "tool",
                "kind": "pose",
                "xyz": rng.normal(size=3).tolist(),
                "quat_xyzw": _quat(rng),
            },
            {
                "frame": "cam_a",
                "kind": "target",
                "xyz": [int(i), 2, -3],
                "quat_xyzw": _quat(rng, decimals=4),
            },
        ]
        if i % 3 == 0:
            obs.append(
                {
                    "kind": "pose",
                    "frame": "tool",
                    "marker": "m1",
                    "measured_in": "tracker",
                    "xyz": rng.normal(size=3).tolist(),
                    "quat_xyzw": _quat(rng),
                }
            )
        if i % 4 == 1:
            obs.append(
                {
                    "frame": "cam_b",
                    "kind": "target",
                    "target": "board",
                    "target_frame": "base",
                    "xyz": rng.normal(size=3).tolist(),
                    "quat_xyzw": _quat(rng),
                    "note": None,
                }
            )
        samples.append({"q": [float(rng.normal()), int(i)], "observations": obs})
    return {
        "format": "kinfw-measurements",
        "version": 1,
        "units": {"length": "mm", "angle": "deg"},
        "joint_names": ["a", "b"],
        "measured_in": "mocap",
        "samples": samples,
    }


def _read(doc: dict, bulk: bool, monkeypatch: pytest.MonkeyPatch):
    """``measurements_from_dict(doc)`` with or without the bulk path, and its warnings;
    asserts that the bulk path did (or was not asked to) read the document."""
    used = []
    original = file_module._read_samples_in_bulk

    def spy(*args):
        out = original(*args) if bulk else None
        used.append(out is not None)
        return out

    with monkeypatch.context() as m:
        m.setattr(file_module, "_read_samples_in_bulk", spy)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            data = measurements_from_dict(copy.deepcopy(doc), source="f.json")
    return data, [str(w.message) for w in caught], used


def _assert_same(a, b) -> None:
    np.testing.assert_array_equal(a.qs, b.qs)
    ga, gb = list(a.all_groups()), list(b.all_groups())
    assert [repr(g) for g in ga] == [repr(g) for g in gb]
    for x, y in zip(ga, gb, strict=True):
        np.testing.assert_array_equal(x.sample, y.sample)
        for field in ("meas_T_frame", "camera_T_target", "meas_p_point"):
            if hasattr(x, field):
                np.testing.assert_array_equal(getattr(x, field), getattr(y, field))


def test_bulk_reading_equals_reading_one_observation_at_a_time(monkeypatch):
    doc = _document()
    bulk, bulk_warnings, used = _read(doc, True, monkeypatch)
    one, one_warnings, _ = _read(doc, False, monkeypatch)
    assert used == [True]
    _assert_same(bulk, one)
    assert len(list(bulk.all_groups())) == 4
    assert len(bulk_warnings) == 1 and "quaternions had norms" in bulk_warnings[0]
    assert bulk_warnings == one_warnings


def test_a_file_with_a_kind_read_one_at_a_time_is_read_one_at_a_time(monkeypatch):
    doc = _document(12)
    doc["samples"][5]["observations"].append({"frame": "tool", "kind": "point", "xyz": [1, 2, 3]})
    bulk, _, used = _read(doc, True, monkeypatch)
    one, _, _ = _read(doc, False, monkeypatch)
    assert used == [False]
    _assert_same(bulk, one)
    assert len(bulk.points) == 1


def _broken(change) -> dict:
    doc = _document(12)
    change(doc["samples"])
    return doc


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (lambda s: s[7]["q"].__setitem__(1, True), r"samples\[7\]\.q\[1\]"),
        (lambda s: s[7]["q"].append(1.0), r"samples\[7\]\.q: expected 2 numbers"),
        (
            lambda s: s[9]["observations"][1]["xyz"].__setitem__(2, "3"),
            r"observations\[1\]\.xyz\[2\]",
        ),
        (lambda s: s[9]["observations"][0]["xyz"].__setitem__(0, float("nan")), r"xyz\[0\]"),
        (
            lambda s: s[10]["observations"][1].__setitem__("quat_xyzw", [0.0, 0.0, 0.0, 1.01]),
            r"samples\[10\]\.observations\[1\]\.quat_xyzw: quaternion norm is 1\.01",
        ),
        (
            lambda s: s[4]["observations"][0].pop("xyz"),
            r"samples\[4\]\.observations\[0\]\.xyz: missing",
        ),
        (
            lambda s: s[6]["observations"][0].__setitem__("marker", ["m"]),
            r"observations\[0\]\.marker",
        ),
        (
            lambda s: s[9]["observations"][2].__setitem__("frame", "other"),
            r"samples\[9\]\.observations\[2\]\.marker: marker 'm1' is on frame 'other'",
        ),
        (lambda s: s[8].__setitem__("observations", []), r"samples\[8\]\.observations"),
    ],
)
def test_a_broken_file_gives_the_one_at_a_time_error(change, match, monkeypatch):
    doc = _broken(change)
    with pytest.raises(DatasetError, match=match) as bulk:
        _read(doc, True, monkeypatch)
    with pytest.raises(DatasetError) as one:
        _read(doc, False, monkeypatch)
    assert str(bulk.value) == str(one.value)
