"""The calibration sidecar and report as typed dataclasses: files written by older kinfw
read unchanged, write -> read round trips, errors naming file and key, and the
consumers (verify's known frames, the view's targets) reading the typed fields."""

import json
import re
from dataclasses import replace

import numpy as np
import pytest

from kinfw.records import (
    CalibratedUnknown,
    CalibrationFileError,
    CalibrationReport,
    CalibrationSidecar,
    read_report,
    read_sidecar,
    write_report,
    write_sidecar,
)
from kinfw.verification.evaluation import known_frames
from kinfw.view import targets_from_sidecar
from tests.paths import DATA, HEAD_URDF

LEGACY = DATA / "calibration_v1"
SIDECAR = LEGACY / "calibrated.kinfw.json"
REPORT = LEGACY / "report.json"


@pytest.fixture(scope="module")
def legacy_doc():
    return json.loads(SIDECAR.read_text())


def test_a_sidecar_written_before_the_typed_reader_reads_field_by_field(legacy_doc):
    s = read_sidecar(SIDECAR)
    # against the JSON document itself, key by key
    assert (s.created, s.kinfw_version, s.method, s.calibrated_urdf) == (
        legacy_doc["created"],
        legacy_doc["kinfw_version"],
        legacy_doc["method"],
        legacy_doc["calibrated_urdf"],
    )
    assert s.nominal_urdf_sha256 == legacy_doc["nominal_urdf"]["sha256"]
    assert s.data.n_samples == legacy_doc["data"]["n_samples"] == 85
    np.testing.assert_array_equal(s.w_T_root, legacy_doc["w_T_root"])
    assert s.measurement_frame is None
    assert s.noise.of("position") == legacy_doc["noise"]["sigma_per_component"]["position"]
    assert s.noise.position_sigma_mm == pytest.approx(
        legacy_doc["noise"]["position_sigma_mm"], rel=1e-15
    )
    (u,) = s.unknowns
    assert (u.kind, u.name) == ("target", "target")
    np.testing.assert_array_equal(u.value, legacy_doc["unknowns"][0]["value"])
    np.testing.assert_array_equal(
        s.hand_eye_targets[0][1], legacy_doc["targets"][0]["root_T_target"]
    )
    assert [r.group for r in s.errors_held_out] == [
        r["group"] for r in legacy_doc["errors_held_out"]
    ]
    assert (
        s.errors_held_out[2].of("position")[1]
        == legacy_doc["errors_held_out"][2]["after_position_rms_mm"]
    )
    assert s.errors_held_out[2].of("rotation") == (
        legacy_doc["errors_held_out"][2]["before_rotation_rms_deg"],
        legacy_doc["errors_held_out"][2]["after_rotation_rms_deg"],
    )


def test_the_writer_writes_the_legacy_sidecar_back_byte_for_byte(tmp_path):
    path = write_sidecar(tmp_path / "c.kinfw.json", read_sidecar(SIDECAR))
    assert path.read_text() == SIDECAR.read_text()


def test_the_report_written_before_the_typed_reader_round_trips_byte_for_byte(tmp_path):
    report = read_report(REPORT)
    doc = json.loads(REPORT.read_text())
    assert report.refine.noise.estimated is doc["refine"]["noise"]["estimated"]
    assert report.refine.identifiability.rank == doc["refine"]["identifiability"]["rank"]
    assert len(report.refine.parameters) == len(doc["refine"]["parameters"])
    assert [c.camera for c in report.hand_eye.cameras] == [
        c["camera"] for c in doc["hand_eye"]["cameras"]
    ]
    np.testing.assert_array_equal(
        report.hand_eye.cameras[0].hand_T_camera,
        doc["hand_eye"]["cameras"][0]["hand_T_camera"]["matrix"],
    )
    assert [s.stage for s in report.rms_vs_truth_held_out_by_stage] == list(
        doc["position_rms_mm_vs_truth_held_out_by_stage"]
    )
    assert write_report(tmp_path / "r.json", report).read_text() == REPORT.read_text()
    assert CalibrationReport.from_dict(report.to_dict()).to_dict() == report.to_dict()


def test_known_frames_give_the_refined_target_over_the_hand_eye_one():
    s = read_sidecar(SIDECAR)
    known = known_frames(s)
    assert set(known) == {("target", "target")}
    np.testing.assert_array_equal(known[("target", "target")], s.unknowns[0].value)
    assert not np.allclose(s.unknowns[0].value, s.hand_eye_targets[0][1])  # they differ
    ((name, T),) = targets_from_sidecar(SIDECAR)
    assert name == "target"
    np.testing.assert_array_equal(T, s.unknowns[0].value)
    assert known_frames(None) == {}


def test_an_external_measurement_frame_is_known_as_w_T_root():
    w_T_root = np.eye(4)
    w_T_root[:3, 3] = (0.1, -0.2, 0.3)
    s = replace(
        read_sidecar(SIDECAR),
        measurement_frame="tracker",
        w_T_root=w_T_root,
        unknowns=(CalibratedUnknown("offset", "left_plate:m1", [0.01, 0.0, 0.02]),),
    )
    again = CalibrationSidecar.from_dict(json.loads(json.dumps(s.to_dict())))
    known = again.known_frames()
    np.testing.assert_array_equal(known[("frame", "tracker")], w_T_root)
    np.testing.assert_array_equal(known[("offset", "left_plate:m1")], [0.01, 0.0, 0.02])
    # the hand-eye target stays known when the refinement did not estimate it
    np.testing.assert_array_equal(known[("target", "target")], s.hand_eye_targets[0][1])


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d.update(format="kinfw-measurements"), "format: expected 'kinfw-calibration'"),
        (lambda d: d.update(version=2), "version: expected 1"),
        (lambda d: d.pop("w_T_root"), "w_T_root: expected a value (the key is missing)"),
        (
            lambda d: d.update(w_T_root=[[1, 0, 0], [0, 1, 0]]),
            "w_T_root: expected an array of shape (4, 4)",
        ),
        (
            lambda d: d["targets"][0].update(root_T_target="eye"),
            "targets[0].root_T_target: expected an array of shape (4, 4)",
        ),
        (lambda d: d["unknowns"][0].pop("kind"), "unknowns[0].kind: expected a value"),
        (lambda d: d["unknowns"][0].update(name=3), "unknowns[0].name: expected a string, got 3"),
        (lambda d: d["noise"].update(estimated="yes"), "noise.estimated: expected true or false"),
        (
            lambda d: d["errors_held_out"][1].update(n=1.5),
            "errors_held_out[1].n: expected an integer, got 1.5",
        ),
        (lambda d: d["data"].update(n_samples=None), "data.n_samples: expected an integer"),
        (
            lambda d: d.update(model={"parameters": ["full"], "prior_mm": 1.0, "reason": "x"}),
            "model.prior_mm: expected prior_mm and prior_deg both or neither",
        ),
        (
            lambda d: d.update(model={"parameters": "full", "reason": "given"}),
            "model.parameters: expected",
        ),
    ],
)
def test_a_bad_sidecar_names_the_file_and_the_key(tmp_path, legacy_doc, edit, message):
    doc = json.loads(json.dumps(legacy_doc))
    edit(doc)
    path = tmp_path / "bad.kinfw.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(CalibrationFileError, match=re.escape(f"{path}: {message}")):
        read_sidecar(path)


def test_a_sidecar_that_is_not_json_is_refused(tmp_path):
    path = tmp_path / "c.kinfw.json"
    path.write_text("{not json")
    with pytest.raises(CalibrationFileError, match=re.escape(f"{path}: not JSON (line 1")):
        read_sidecar(path)


def test_a_bad_report_names_the_file_and_the_key(tmp_path):
    doc = json.loads(REPORT.read_text())
    doc["refine"]["parameters"][3]["fixed"] = "no"
    path = tmp_path / "r.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(
        CalibrationFileError,
        match=re.escape(f"{path}: refine.parameters[3].fixed: expected true or false"),
    ):
        read_report(path)


def test_verify_with_a_bad_sidecar_is_a_one_line_user_error(tmp_path, capsys):
    from kinfw.cli._main import main

    bad = tmp_path / "c.kinfw.json"
    bad.write_text(json.dumps({"format": "kinfw-calibration", "version": 1}))
    head = HEAD_URDF
    from kinfw.measurements import write_measurements
    from kinfw.model import load_robot
    from kinfw.simulation import random_configurations, simulate_at

    robot = load_robot(head)
    names = robot.topology(("left_plate",)).joint_names
    lower, upper = robot.joint_limits(names)
    qs = random_configurations(lower, upper, 4, np.random.default_rng(0))
    write_measurements(
        tmp_path / "d.json",
        simulate_at(robot, qs, names, frames=("left_plate",), rng=np.random.default_rng(1)),
    )
    code = main(["-q", "verify", str(head), str(tmp_path / "d.json"), "--sidecar", str(bad)])
    err = capsys.readouterr().err
    assert code == 2
    assert (
        err.strip() == f"kinfw verify: error: {bad}: nominal_urdf: expected a value (the key "
        "is missing)"
    )


def test_a_prior_by_group_round_trips_through_the_sidecar_exactly():
    """The chosen group sigmas, and how they were chosen, come back from the sidecar's
    JSON exactly; a bad sigma is refused naming its place."""
    import json

    from kinfw.model import PriorScales
    from kinfw.records import CalibrationFileError, DocReader, ModelSummary

    prior = PriorScales.uniform(1e-3, 5e-3).with_sigmas(
        {("offsets", "rad"): 0.02, ("tools", "m"): 0.01, ("compliance", "rad/Nm"): 1e-5},
        "leave-one-out",
    )
    model = ModelSummary(("full",), prior, "leave-one-out cross-validation")
    doc = json.loads(json.dumps(model.to_dict()))
    back = ModelSummary.from_dict(doc, DocReader("<test>"), "model")
    assert back == model and back.prior.how == "leave-one-out"
    assert back.prior.sigma("offsets", "rad") == 0.02 and back.prior.sigma("axes", "m") == float(
        "inf"
    )
    doc["prior"]["scales"][0]["sigma"] = -1.0
    with pytest.raises(CalibrationFileError, match=r"model\.prior\.scales\[0\]\.sigma"):
        ModelSummary.from_dict(doc, DocReader("<test>"), "model")


def test_the_model_summary_and_robot_blocks_round_trip():
    """A calibration with a compliance: the model's label names it, the sidecar's
    robot_blocks give back the calibrated spec, values and sigmas exactly."""
    import numpy as np

    from kinfw.model import PriorScales
    from kinfw.records import DocReader, ModelSummary, RobotBlockRecord

    model = ModelSummary(("full",), PriorScales.uniform(3e-3, 0.01), "given", ("compliance",))
    assert model.label == "full, prior 3 mm / 0.573 deg + compliance"
    again = ModelSummary.from_dict(model.to_dict(), DocReader("<test>"), "model")
    assert again == model
    plain = ModelSummary(("full",), None, "given")
    assert "blocks" not in plain.to_dict()
    assert ModelSummary.from_dict(plain.to_dict(), DocReader("<test>"), "model") == plain
    # a sidecar of an earlier kinfw: one length and one angle sigma
    old = {"parameters": ["full"], "prior_mm": 3.0, "prior_deg": 0.5, "reason": "given"}
    read = ModelSummary.from_dict(old, DocReader("<test>"), "model")
    assert read.prior == PriorScales.uniform(3e-3, np.radians(0.5))
    record = RobotBlockRecord(
        "compliance:j1,j2",
        ("j1:compliance", "j2:compliance"),
        ("rad/Nm",) * 2,
        [0.0, 5e-6],
        [0.0, 2e-8],
    )
    back = RobotBlockRecord.from_dict(record.to_dict(), DocReader("<test>"), "robot_blocks[0]")
    assert back.spec == record.spec and back.names == record.names
    np.testing.assert_array_equal(back.values, record.values)
    np.testing.assert_array_equal(back.std, record.std)
