"""Gross errors are rejected (excluded and the problem refitted), not only down-weighted.

Truths: the fit of the data with the bad observation deleted by hand (numpy, not the
rejection's own code), and the rejection rate of clean data against its noise model
(a binomial count at the chosen quantile).
"""

from dataclasses import replace
from math import erf, sqrt

import numpy as np
import pytest
from scipy.stats import binom

from kinfw.identification import refine
from kinfw.model import load_robot
from kinfw.simulation import perturb_robot, plant_outliers, random_configurations
from tests.head_data import PLATES, plate_data


@pytest.fixture(scope="module")
def truth(head):
    return load_robot(
        perturb_robot(head, np.random.default_rng(4), origin_mm=5.0, origin_deg=1.0, axis_deg=1.0)
    )


def _with_bad_pose(data, row, shift_m, group=0):
    """``data`` with the position of row ``row`` of pose group ``group`` moved (m)."""
    poses = list(data.poses)
    T = poses[group].meas_T_frame.copy()
    T[row, :3, 3] += shift_m
    poses[group] = replace(poses[group], meas_T_frame=T)
    return replace(data, poses=tuple(poses))


def _deleted(data, row):
    """``data`` without row ``row`` of its first pose group, by hand."""
    pose = data.poses[0]
    keep = np.delete(np.arange(len(pose.sample)), row)
    pose = replace(pose, sample=pose.sample[keep], meas_T_frame=pose.meas_T_frame[keep])
    return replace(data, poses=(pose, *data.poses[1:]))


def test_a_70_mm_pose_is_rejected_named_and_the_refit_is_the_fit_without_it(head, truth):
    clean = plate_data(truth, 60, 5)  # 60 samples x 2 plates = 120 pose observations
    row = 17
    bad = _with_bad_pose(clean, row, np.array([0.0, 0.07, 0.0]))
    fit = refine(head, bad, loss="huber")
    (rejected,) = fit.rejected
    pose = clean.poses[0]
    assert (rejected.kind, rejected.frame, rejected.marker, rejected.sample) == (
        "pose",
        pose.frame,
        None,
        int(pose.sample[row]),
    )
    assert rejected.residual("position") == pytest.approx(0.07, abs=0.003)  # m
    assert rejected.residual("rotation") < np.radians(1.0)  # rad: orientation untouched
    assert rejected.excess > 10 and fit.rejection_note is None
    assert (rejected.kind, rejected.frame, rejected.sample) not in {
        (k, f, s) for k, f, s, _ in fit.downweighted
    }
    # the refit is the fit of the data with that observation deleted
    without = refine(head, _deleted(bad, row), loss="huber")
    assert without.rejected == ()
    qs = random_configurations(
        *head.joint_limits(clean.joint_names), 50, np.random.default_rng(1), fraction=0.8
    )
    for frame_fit, frame_ref in zip(
        fit.model.frame_poses(qs), without.model.frame_poses(qs), strict=True
    ):
        np.testing.assert_allclose(frame_fit, frame_ref, rtol=0, atol=1e-9)
    assert fit.noise.position_m == pytest.approx(without.noise.position_m, rel=1e-9)
    assert fit.noise.rotation_rad == pytest.approx(without.noise.rotation_rad, rel=1e-9)
    # its residual is the one the final model gives it (measured minus predicted, by FK)
    names = fit.model.topology.joint_names
    q = bad.q_of(names)[pose.sample[row]][None]
    k = fit.model.topology.frames.index(pose.frame)
    predicted = fit.model.frame_poses(q)[0, k]
    measured = bad.poses[0].meas_T_frame[row]
    assert rejected.residual("position") == pytest.approx(
        np.linalg.norm(measured[:3, 3] - predicted[:3, 3]), abs=1e-9
    )
    # without rejection the bad pose is only down-weighted and the fit differs from it
    kept = refine(head, bad, loss="huber", reject=None)
    assert kept.rejected == ()
    assert (rejected.kind, rejected.frame, rejected.sample) in {
        (k, f, s) for k, f, s, _ in kept.downweighted
    }
    shift = np.abs(kept.model.frame_poses(qs) - without.model.frame_poses(qs))[..., :3, 3]
    assert shift.max() > 1e-6  # m: Huber leaves it an influence that rejection removes


@pytest.mark.slow
def test_clean_data_rejects_no_more_than_the_quantile_says(head, truth):
    """At the default 99.9 % quantile: a binomial count, with its slack."""
    n_obs = rejected = 0
    for seed in (11, 12, 13):
        data = plate_data(truth, 150, seed)  # 300 observations
        fit = refine(head, data, loss="huber")
        n_obs += sum(len(g.sample) for g in data.poses)
        rejected += len(fit.rejected)
        assert fit.rejection_note is None
    assert rejected <= binom.ppf(0.999, n_obs, 1e-3)  # 900 observations: at most 4


def test_the_threshold_is_the_clean_quantile_of_each_kind(head, truth):
    """At z = 1.2816 (the 90 % quantile) and one round, ~10 % of clean observations are
    beyond: the thresholds are the exact quantiles of the clean residual norm (positions
    and orientations together, the orientation error an angle about a random axis)."""
    data = plate_data(truth, 200, 21)  # 400 observations
    fit = refine(
        head, data, loss="huber", reject=1.2816, max_reject_rounds=1, max_reject_fraction=0.5
    )
    p = 1.0 - 0.5 * (1.0 + erf(1.2816 / sqrt(2.0)))
    lo, hi = binom.ppf([0.0005, 0.9995], 400, p)
    assert lo <= len(fit.rejected) <= hi


def test_more_than_the_allowed_fraction_is_capped_and_said(head, truth):
    clean = plate_data(truth, 60, 7)
    bad, planted = plant_outliers(
        clean, np.random.default_rng(3), fraction=0.2, distance_m=0.05, angle_rad=0.1
    )
    fit = refine(head, bad, loss="huber", max_reject_fraction=0.05)
    assert len(fit.rejected) == 6  # 5 % of 120
    assert {(o.kind, o.frame, o.sample) for o in fit.rejected} <= planted
    assert "inconsistent" in fit.rejection_note and "only the worst 6" in fit.rejection_note
    excess = [o.excess for o in fit.rejected]
    assert excess == sorted(excess, reverse=True)


def test_least_squares_rejects_nothing_and_bad_options_are_refused(head, truth):
    bad = _with_bad_pose(plate_data(truth, 30, 8), 3, np.array([0.07, 0.0, 0.0]))
    assert refine(head, bad, loss="linear").rejected == ()
    with pytest.raises(ValueError, match="reject: expected a positive z"):
        refine(head, bad, loss="huber", reject=-1.0)
    with pytest.raises(ValueError, match="max_reject_fraction"):
        refine(head, bad, loss="huber", max_reject_fraction=1.5)


def test_the_report_lists_rejected_apart_and_reads_back(head, truth, tmp_path):
    from kinfw.identification import identify
    from kinfw.records import read_report, write_report
    from kinfw.verification.reporting import calibration_report

    clean = plate_data(truth, 60, 9)
    bad = _with_bad_pose(clean, 4, np.array([0.0, 0.0, 0.07]))
    bad = _with_bad_pose(bad, 9, np.array([0.04, 0.0, 0.0]), group=1)
    result = identify(head, bad)
    report = calibration_report(head, load_robot(result.urdf_xml), bad, result, method="refine")
    rows = report.refine.rejected
    assert [(r.frame, r.sample) for r in rows] == [
        (PLATES[0], int(bad.poses[0].sample[4])),  # 70 mm first
        (PLATES[1], int(bad.poses[1].sample[9])),  # then 40 mm
    ]
    assert rows[0].residuals[0].key == "position_residual_mm"
    assert rows[0].residual("position") == pytest.approx(70.0, abs=3.0)
    assert rows[1].residual("position") == pytest.approx(40.0, abs=3.0)
    path = write_report(tmp_path / "report.json", report)
    assert read_report(path).refine.rejected == rows


def test_a_small_dataset_may_still_lose_its_one_gross_error(head, truth):
    """12 samples x 1 plate: 5 % of 12 observations rounds down to none, yet one gross
    error is what any dataset may hold (a cross-validation fold of a 15-sample session):
    it is rejected and the refit is the fit without it."""
    clean = plate_data(truth, 12, 10)
    one_plate = replace(clean, poses=clean.poses[:1])
    bad = _with_bad_pose(one_plate, 5, np.array([0.0, 0.0, 0.05]))
    fit = refine(head, bad, loss="huber", parameters="frames")
    (rejected,) = fit.rejected
    assert rejected.sample == int(one_plate.poses[0].sample[5])
    without = refine(head, _deleted(one_plate, 5), loss="huber", parameters="frames")
    assert without.rejected == ()
    q = one_plate.q_of(fit.model.topology.joint_names)
    np.testing.assert_allclose(
        fit.model.frame_poses(q), without.model.frame_poses(q), rtol=0, atol=1e-9
    )


@pytest.mark.slow
def test_a_refit_from_a_settled_fit_is_the_cold_fit_without_the_error_in_fewer_iterations(
    head, truth
):
    """300 samples x 2 plates: the first fit's noise estimate settles, so the refit starts
    from its estimate and noise (no first round from the default noise); it ends where a
    fit of the data with the bad pose deleted by hand ends, to 1 % of the standard
    errors and 1e-3 of the noise, in fewer Levenberg-Marquardt iterations."""
    clean = plate_data(truth, 300, 8)
    bad = _with_bad_pose(clean, 40, np.array([0.05, 0.0, 0.0]))
    fit = refine(head, bad, loss="huber")
    (rejected,) = fit.rejected
    assert rejected.sample == int(clean.poses[0].sample[40])
    without = refine(head, _deleted(bad, 40), loss="huber")
    assert without.rejected == () and without.noise_settled and fit.noise_settled
    free = without.std > 0
    moved = np.abs(fit.estimate - without.estimate)[free] / without.std[free]
    assert moved.max() < 1e-2, moved.max()
    assert dict(fit.noise.sigmas) == pytest.approx(dict(without.noise.sigmas), rel=1e-3)
    assert fit.iterations < without.iterations


@pytest.mark.slow
def test_the_clean_tail_is_told_apart_from_a_gross_error(head, truth, tmp_path, capsys):
    """300 clean pose observations (0.1 % beyond the 99.9 % quantile: 0.3 expected) and
    one moved by 70 mm: the fit rejects both the 70 mm one (23 times the threshold) and
    a clean one 1.05 times beyond it. Only the first is a gross error; kinfw calibrate
    says so, and says the other is "beyond the 99.9 % quantile (expected on clean
    data)"; the report records which is which and reads it back, and its in-sample
    table is shown with and without them."""
    from kinfw.measurements import write_measurements
    from kinfw.records import read_report
    from tests.cli_run import run_cli
    from tests.kinfw.cli.test_cli import DEMO_BOUND_ARGS
    from tests.paths import HEAD_URDF

    data = _with_bad_pose(plate_data(truth, 150, 13), 17, np.array([0.0, 0.07, 0.0]))
    fit = refine(head, data, loss="huber")
    gross, tail = fit.rejected
    assert (gross.sample, gross.clean_tail) == (int(data.poses[0].sample[17]), False)
    assert gross.excess > 20 and 1.0 < tail.excess < 1.1 and tail.clean_tail
    write_measurements(tmp_path / "data.json", data)
    argv = ["calibrate", tmp_path / "data.json", "--urdf", HEAD_URDF, "--params", "full"]
    argv += ["--out", tmp_path / "cal.urdf", "--report", tmp_path / "report.json"]
    argv += DEMO_BOUND_ARGS  # the guard's bound for the truth's 5 mm / 1 deg error
    code, out, _ = run_cli(argv, capsys)
    assert code == 0
    assert f"  rejected as a gross error: samples[{gross.sample}] " in out
    assert f"  beyond the 99.9 % quantile (expected on clean data): samples[{tail.sample}] " in out
    report = read_report(tmp_path / "report.json")
    rows = report.refine.rejected
    assert [(r.sample, r.clean_tail) for r in rows] == [(gross.sample, False), (tail.sample, True)]
    # the in-sample table with the rejected (the 70 mm: sqrt(70^2 / 150) = 5.7 mm on its
    # plate) and without them (the noise: 0.5 mm per axis, 0.87 mm of norm, less the fit's)
    assert "the same without the 2 rejected observations (what the fit was made on):" in out

    def refine_rms(stages, group):
        (stage,) = [s for s in stages if s.stage == "refine"]
        return next(v.value for g, v in stage.rms if g == group)

    plate = f"{data.poses[0].frame} (pose)"
    assert refine_rms(report.rms_by_stage, plate) > 5.0
    assert 0.6 < refine_rms(report.rms_by_stage_without_rejected, plate) < 1.0
