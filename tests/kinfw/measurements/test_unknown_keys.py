"""Keys a measurement file holds that the reader does not know: one warning per key and
place (the top level, samples, payloads, an observation kind), naming the key, the first
place it is at, how many have it and the keys that place knows; the same from the bulk
path and the one-at-a-time path; a kind added by a plugin knows the keys it reads."""

from __future__ import annotations

import copy
import warnings
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import pytest
from numpy.typing import NDArray

from kinfw.measurements import _file as file_module
from kinfw.measurements import measurements_from_dict
from kinfw.observations import (
    NoiseComponent,
    ObservationKind,
    data_array,
    register_kind,
    sample_array,
    unregister_kind,
)
from tests.kinfw.measurements.test_measurements import document, point, pose, sample


def _read(doc: dict, *, bulk: bool, monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The warnings of reading ``doc`` with or without the bulk path."""
    original = file_module._read_samples_in_bulk

    def spy(*args):
        return original(*args) if bulk else None

    with monkeypatch.context() as m:
        m.setattr(file_module, "_read_samples_in_bulk", spy)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            measurements_from_dict(copy.deepcopy(doc), source="data.json")
    return [str(w.message) for w in caught]


def _poses(n: int) -> dict:
    return document(
        *(sample([0.01 * i, 0.0], pose("head", xyz=[float(i), 0.0, 0.0])) for i in range(n))
    )


@pytest.mark.parametrize("bulk", [True, False])
def test_a_typo_in_every_sample_warns_once_with_the_count(bulk, monkeypatch):
    doc = _poses(300)
    for s in doc["samples"][3:]:
        s["paylaod"] = {"frame": "head", "mass_kg": 1.0}
    assert _read(doc, bulk=bulk, monkeypatch=monkeypatch) == [
        "data.json: samples[3]: unknown key 'paylaod' (ignored, in 297 samples); known keys: "
        "q, observations, payload"
    ]


@pytest.mark.parametrize("bulk", [True, False])
def test_each_place_warns_of_its_own_unknown_keys(bulk, monkeypatch):
    doc = _poses(40)
    doc["gravty"] = [0, 0, -9.81]
    doc["comment"] = "lab 3, tracker 2"  # free text for people: known
    doc["samples"][5]["payload"] = {"frame": "head", "mass_kg": 1.0, "comm": [0, 0, 1]}
    for s in doc["samples"][7:]:
        s["observations"][0]["sigma_mm"] = 0.02
    doc["samples"][9]["observations"].append(point("head", marker="m", sigma_mm=0.02))
    doc["samples"][9]["observations"].append(point("camera", marker="m2", weight=None))
    messages = _read(doc, bulk=bulk, monkeypatch=monkeypatch)
    assert messages == [
        "data.json: unknown top-level key 'gravty' (ignored); known keys: format, version, "
        "units, joint_names, joint_units, measured_in, gravity, cameras, mounts, samples, "
        "comment",
        "data.json: samples[5].payload: unknown key 'comm' (ignored); known keys: frame, "
        "mass_kg, com, inertia",
        "data.json: samples[7].observations[0]: unknown key 'sigma_mm' on a 'pose' observation "
        "(ignored, in 33 observations); known keys: kind, frame, xyz, quat_xyzw, marker, "
        "measured_in",
        "data.json: samples[9].observations[1]: unknown key 'sigma_mm' on a 'point' "
        "observation (ignored); known keys: kind, frame, xyz, offset, marker, measured_in",
    ]
    assert all(len(m) < 200 for m in messages)


# -- a kind from a plugin, which does not list its keys: it knows those it reads ---------
@dataclass(frozen=True, slots=True, eq=False)
class Readings:
    """A gauge on ``frame`` read at each sample (``value`` (m,), m)."""

    kind: ClassVar[str] = "gauge"
    frame: str
    sample: NDArray[np.int64]
    value: NDArray[np.float64]
    gauge: str = "gauge"

    def __post_init__(self) -> None:
        sample = sample_array(self.sample, "Readings.sample")
        object.__setattr__(self, "sample", sample)
        object.__setattr__(self, "value", data_array(self.value, (len(sample),), "value"))


class GaugeKind(ObservationKind):
    """``{"frame": f, "kind": "gauge", "value": v}``, optional ``"gauge"`` (its name)."""

    name = "gauge"
    group_type = Readings
    row_fields = ("value",)
    components = (NoiseComponent("reading", 1, "m"),)

    def parse(self, reader, obs, at, frame):
        value = reader.number(obs, "value", at, "the gauge's reading (a length)")
        gauge = reader.optional_string(obs, "gauge", at) or "gauge"
        return (("frame", frame), ("gauge", gauge)), reader.lengths([value])

    def group_from_rows(self, key, sample, rows):
        return Readings(sample=sample, value=rows[:, 0], **dict(key))

    def frames(self, group):
        return (group.frame,)


@pytest.fixture
def gauge_kind():
    kind = register_kind(GaugeKind())
    yield kind
    unregister_kind(kind.name)


@pytest.mark.parametrize("bulk", [True, False])
def test_a_plugin_kind_knows_the_keys_it_reads(gauge_kind, bulk, monkeypatch):
    doc = _poses(12)
    for i, s in enumerate(doc["samples"]):
        reading = {"frame": "head", "kind": "gauge", "value": 0.1 * i}
        if i >= 4:
            reading["gague"] = "left"
        s["observations"].append(reading)
    doc["samples"][2]["observations"][1]["gauge"] = "right"  # read: known
    assert _read(doc, bulk=bulk, monkeypatch=monkeypatch) == [
        "data.json: samples[4].observations[1]: unknown key 'gague' on a 'gauge' observation "
        "(ignored, in 8 observations); known keys: kind, frame, gauge, value"
    ]
