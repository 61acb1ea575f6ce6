"""Cross-validation, parameter sets and the outlier that must not bend the model."""

from dataclasses import replace
from pathlib import Path

import numpy as np

from identification.pipeline import calibrate
from kinfw.cpc import cpc_from_robot
from kinfw.robot import load_robot
from verification.crossval import crossvalidate
from verification.report import calibration_report
from verification.simulate import perturb_robot, random_configurations, simulate

HEAD = Path(__file__).resolve().parents[1] / "urdf" / "iis_head.urdf"
PLATES = ("left_plate", "right_plate")


def _data(truth, n, seed, noise_m=0.5e-3, noise_rad=0.005):
    rng = np.random.default_rng(seed)
    names = truth.topology(PLATES).joint_names
    qs = random_configurations(*truth.joint_limits(names), n, rng, fraction=0.8)
    return simulate(truth, qs, names, frames=PLATES, rng=rng, noise_m=noise_m,
                    noise_rad=noise_rad)


def test_calibration_beats_both_baselines_when_the_joints_are_off():
    nominal = load_robot(HEAD)
    truth = load_robot(perturb_robot(nominal, np.random.default_rng(0), origin_mm=5.0,
                                     origin_deg=1.0, axis_deg=1.0))
    cv = crossvalidate(nominal, _data(truth, 60, 1), k=4, select=True,
                       sets=("none", "frames", "offsets", "full"))
    means = [cv.mean(p) for p in ("none", "frames", "offsets", "full")]
    assert means[0] > means[1] > means[2] > means[3]
    assert cv.selected == "full" and not cv.warnings
    assert means[3] < 1.5  # mm, noise 0.5 mm per axis


def test_overfitting_on_small_data_is_warned_about():
    """Only the plates' mounts are off: 'frames' is the right model, 'full' overfits."""
    nominal = load_robot(HEAD)
    truth = load_robot(perturb_robot(nominal, np.random.default_rng(2), origin_mm=5.0,
                                     origin_deg=1.0, axis_deg=0.0,
                                     joints=("left_plate_joint", "right_plate_joint")))
    cv = crossvalidate(nominal, _data(truth, 12, 3, noise_m=1e-3, noise_rad=0.01), k=4,
                       select=True, sets=("frames", "full"))
    assert cv.mean("full") > cv.mean("frames")
    assert cv.selected == "frames"
    assert "worse held-out than frames only" in cv.warnings[0]
    assert "likely cause" in cv.warnings[0]


def test_a_70_mm_outlier_is_listed_and_does_not_bend_the_model():
    nominal = load_robot(HEAD)
    truth = load_robot(perturb_robot(nominal, np.random.default_rng(4), origin_mm=5.0,
                                     origin_deg=1.0, axis_deg=1.0))
    clean = _data(truth, 60, 5)
    pose = clean.poses[0]
    T = pose.meas_T_frame.copy()
    T[17, :3, 3] += np.array([0.07, 0.0, 0.0])  # 70 mm on one sample
    bad = replace(clean, poses=(replace(pose, meas_T_frame=T), *clean.poses[1:]))
    qs = random_configurations(*nominal.joint_limits(clean.joint_names), 200,
                               np.random.default_rng(6), fraction=0.8)
    true_model = cpc_from_robot(truth, PLATES)

    def held_out_mm(result):
        model = load_robot(result.urdf_xml)
        model_cpc = cpc_from_robot(model, PLATES)
        d = model_cpc.frame_poses(qs)[..., :3, 3] - true_model.frame_poses(qs)[..., :3, 3]
        return 1e3 * float(np.sqrt(np.mean(np.sum(d**2, axis=-1))))

    reference = held_out_mm(calibrate(nominal, clean, loss="linear"))
    bent = held_out_mm(calibrate(nominal, bad, loss="linear"))
    robust = calibrate(nominal, bad)  # the default: Huber
    assert bent > 1.5 * reference
    assert held_out_mm(robust) < 1.15 * reference
    report = calibration_report(nominal, load_robot(robust.urdf_xml), bad, robust,
                                method="refine")
    flagged = {(d["frame"], d["sample"]): d for d in report["refine"]["downweighted"]}
    entry = flagged[(pose.frame, int(pose.sample[17]))]
    assert 60.0 < entry["position_residual_mm"] < 80.0
    assert entry["weight"] < 0.2


def test_parameter_masks_by_joint_and_field():
    nominal = load_robot(HEAD)
    truth = load_robot(perturb_robot(nominal, np.random.default_rng(7), origin_mm=3.0,
                                     origin_deg=0.5, axis_deg=0.5))
    data = _data(truth, 40, 8)
    from identification.refine import refine

    masked = refine(nominal, data, parameters=("pan", "tilt:l_x"))
    free = {name for name, f in zip(masked.parameter_names,
                                    np.abs(np.diag(masked.covariance)) > 0, strict=True) if f}
    assert ("pan", "b_tilt_1") in free and ("tilt", "l_x") in free
    assert ("tilt", "l_y") not in free and ("vergence_left", "l_x") not in free
    import pytest

    with pytest.raises(ValueError, match="got 'nose'"):
        refine(nominal, data, parameters=("pan", "nose"))
    with pytest.raises(ValueError, match="got 'tilt:l_z'"):
        refine(nominal, data, parameters=("tilt:l_z",))
