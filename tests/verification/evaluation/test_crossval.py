"""Cross-validation, parameter sets and the outlier that must not bend the model."""

from dataclasses import replace

import numpy as np
import pytest

from kinfw.identification import identify
from kinfw.model import cpc_from_robot, load_robot
from kinfw.progress import reporting
from kinfw.simulation import perturb_robot, random_configurations
from kinfw.verification.evaluation import crossvalidate
from kinfw.verification.reporting import calibration_report
from tests.head_data import PLATES, plate_data
from tests.paths import HEAD_URDF as HEAD
from tests.recorder import Recorder


@pytest.mark.slow
def test_calibration_beats_both_baselines_when_the_joints_are_off(head):
    nominal = head
    truth = load_robot(
        perturb_robot(
            nominal, np.random.default_rng(0), origin_mm=5.0, origin_deg=1.0, axis_deg=1.0
        )
    )
    cv = crossvalidate(
        nominal,
        plate_data(truth, 60, 1),
        k=4,
        select=True,
        sets=("none", "frames", "offsets", "full"),
    )
    means = [cv.mean(p) for p in ("none", "frames", "offsets", "full")]
    assert means[0] > means[1] > means[2] > means[3]
    assert cv.selected == "full" and not cv.warnings
    assert means[3] < 1.5  # mm, noise 0.5 mm per axis


@pytest.mark.slow
def test_overfitting_on_small_data_is_warned_about(head):
    """Only the plates' mounts are off: 'frames' is the right model, 'full' overfits."""
    nominal = head
    truth = load_robot(
        perturb_robot(
            nominal,
            np.random.default_rng(2),
            origin_mm=5.0,
            origin_deg=1.0,
            axis_deg=0.0,
            joints=("left_plate_joint", "right_plate_joint"),
        )
    )
    cv = crossvalidate(
        nominal,
        plate_data(truth, 12, 3, noise_m=1e-3, noise_rad=0.01),
        k=4,
        select=True,
        sets=("frames", "full"),
    )
    assert cv.mean("full") > cv.mean("frames")
    assert cv.selected == "frames"
    assert "worse held-out than frames only" in cv.warnings[0]
    assert "likely cause" in cv.warnings[0]


@pytest.mark.slow
def test_a_70_mm_outlier_is_listed_and_does_not_bend_the_model(head):
    nominal = head
    truth = load_robot(
        perturb_robot(
            nominal, np.random.default_rng(4), origin_mm=5.0, origin_deg=1.0, axis_deg=1.0
        )
    )
    clean = plate_data(truth, 60, 5)
    pose = clean.poses[0]
    T = pose.meas_T_frame.copy()
    T[17, :3, 3] += np.array([0.07, 0.0, 0.0])  # 70 mm on one sample
    bad = replace(clean, poses=(replace(pose, meas_T_frame=T), *clean.poses[1:]))
    qs = random_configurations(
        *nominal.joint_limits(clean.joint_names), 200, np.random.default_rng(6), fraction=0.8
    )
    true_model = cpc_from_robot(truth, PLATES)

    def held_out_mm(result):
        model = load_robot(result.urdf_xml)
        model_cpc = cpc_from_robot(model, PLATES)
        d = model_cpc.frame_poses(qs)[..., :3, 3] - true_model.frame_poses(qs)[..., :3, 3]
        return 1e3 * float(np.sqrt(np.mean(np.sum(d**2, axis=-1))))

    reference = held_out_mm(identify(nominal, clean, loss="linear"))
    bent = held_out_mm(identify(nominal, bad, loss="linear"))
    robust = identify(nominal, bad)  # the default: Huber
    assert bent > 1.5 * reference
    assert held_out_mm(robust) < 1.15 * reference
    report = calibration_report(nominal, load_robot(robust.urdf_xml), bad, robust, method="refine")
    (entry,) = report.refine.rejected  # rejected, not merely down-weighted
    assert (entry.kind, entry.frame, entry.sample) == ("pose", pose.frame, int(pose.sample[17]))
    assert 60.0 < entry.residual("position") < 80.0 and entry.excess > 10
    assert (pose.frame, int(pose.sample[17])) not in {
        (d.frame, d.sample) for d in report.refine.downweighted
    }


@pytest.mark.slow
def test_parameter_masks_by_joint_and_field(head):
    nominal = head
    truth = load_robot(
        perturb_robot(
            nominal, np.random.default_rng(7), origin_mm=3.0, origin_deg=0.5, axis_deg=0.5
        )
    )
    data = plate_data(truth, 40, 8)
    from kinfw.identification import refine

    masked = refine(nominal, data, parameters=("pan", "tilt:l_x"))
    free = {
        name
        for name, f in zip(
            masked.parameter_names, np.abs(np.diag(masked.covariance)) > 0, strict=True
        )
        if f
    }
    assert ("pan", "b_tilt_1") in free and ("tilt", "l_x") in free
    assert ("tilt", "l_y") not in free and ("vergence_left", "l_x") not in free
    import pytest

    with pytest.raises(ValueError, match="got 'nose'"):
        refine(nominal, data, parameters=("pan", "nose"))
    with pytest.raises(ValueError, match="got 'tilt:l_z'"):
        refine(nominal, data, parameters=("tilt:l_z",))


# -- speed: executors and cached CasADi functions must not change a number ------------------


def _fold_numbers(cv):
    return np.array(
        [
            [s.of("position"), s.of("rotation")]
            + [
                getattr(s, f)
                for f in (
                    "worst",
                    "condition",
                    "worst_sample",
                    "n_parameters",
                    "n_residuals",
                    "n_train",
                )
            ]
            for s in cv.scores
        ],
        dtype=float,
    )


@pytest.mark.slow
def test_thread_and_process_executors_give_the_serial_scores(head):
    from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor

    nominal = head
    truth = load_robot(
        perturb_robot(
            nominal, np.random.default_rng(11), origin_mm=5.0, origin_deg=1.0, axis_deg=1.0
        )
    )
    data = plate_data(truth, 24, 12)
    kwargs = {"k": 3, "seed": 5, "sets": ("none", "frames", "full")}
    serial = crossvalidate(nominal, data, **kwargs)
    assert [(s.fold, s.parameters) for s in serial.scores] == [
        (f, p) for f in range(3) for p in ("none", "frames", "full")
    ]
    for pool in (ThreadPoolExecutor(max_workers=2), ProcessPoolExecutor(max_workers=2)):
        recorder = Recorder()
        with pool, reporting(recorder):
            cv = crossvalidate(nominal, data, executor=pool, **kwargs)
        assert [(s.fold, s.parameters) for s in cv.scores] == [
            (s.fold, s.parameters) for s in serial.scores
        ]
        np.testing.assert_allclose(_fold_numbers(cv), _fold_numbers(serial), rtol=1e-12, atol=1e-12)
        (fits,) = recorder.tasks  # a worker (thread or process) starts silent
        assert (fits.name, fits.total, fits.depth) == ("cross-validation fits", 9, 0)
        assert [d for d, _ in fits.steps] == list(range(1, 10))


def test_robot_pickles_as_its_urdf(head):
    import pickle

    nominal = head
    copy = pickle.loads(pickle.dumps(nominal))
    assert copy.urdf_xml == nominal.urdf_xml and copy.source == nominal.source
    q = np.linspace(-0.3, 0.3, len(nominal.joint_names))
    np.testing.assert_array_equal(
        copy.frame_poses(q[None], "left_plate"), nominal.frame_poses(q[None], "left_plate")
    )


def _noise_free_case():
    nominal = load_robot(HEAD)
    truth = load_robot(
        perturb_robot(
            nominal, np.random.default_rng(21), origin_mm=5.0, origin_deg=1.0, axis_deg=1.0
        )
    )
    return nominal, truth, plate_data(truth, 30, 22, noise_m=0.0, noise_rad=0.0)


def _held_out_error_m(model, truth):
    names = model.topology.joint_names
    qs = random_configurations(
        *truth.joint_limits(names), 50, np.random.default_rng(23), fraction=0.8
    )
    expected = cpc_from_robot(truth, PLATES).frame_poses(qs)
    return float(np.abs(model.frame_poses(qs) - expected).max())


def test_cached_functions_fit_like_fresh_ones_and_recover_the_truth():
    from kinfw.identification import refine
    from kinfw.identification.problem import NoiseModel, clear_function_cache

    nominal, truth, data = _noise_free_case()
    # a start that is neither the nominal nor the truth: its numbers must reach the
    # cached graph through the inputs, not stay baked in from the first build
    start = load_robot(
        perturb_robot(
            nominal, np.random.default_rng(24), origin_mm=2.0, origin_deg=0.5, axis_deg=0.5
        )
    )
    noise = NoiseModel(1e-3, 1e-2)
    clear_function_cache()
    fresh = refine(nominal, data, start=start, noise=noise)
    clear_function_cache()
    refine(nominal, plate_data(truth, 12, 25), noise=noise)  # same structure, other numbers
    cached = refine(nominal, data, start=start, noise=noise)
    np.testing.assert_allclose(cached.estimate, fresh.estimate, rtol=0, atol=1e-10)
    # noise-free data: both recover the true geometry (held-out FK, metres)
    assert _held_out_error_m(cached.model, truth) < 1e-9
    assert _held_out_error_m(fresh.model, truth) < 1e-9


def test_the_function_cache_is_keyed_by_structure_and_bounded(monkeypatch):
    import kinfw.identification.problem._functions as functions_module
    from kinfw.identification.problem import NoiseModel, build_problem, clear_function_cache

    nominal, _, data = _noise_free_case()
    noise = NoiseModel(1e-3, 1e-2)
    one_plate = replace(data, poses=data.poses[:1])  # another structure: one frame
    clear_function_cache()
    monkeypatch.setattr(functions_module, "_FUNCTION_CACHE_SIZE", 1)
    both = build_problem(nominal, data)
    single = build_problem(nominal, one_plate)  # evicts the first structure
    assert len(functions_module._FUNCTION_CACHE) == 1
    again = build_problem(nominal, data)  # rebuilt, not the one-plate functions
    x = np.random.default_rng(26).normal(size=both.n_parameters) * 1e-3
    r0, J0 = both.evaluate(x, noise)
    r1, J1 = again.evaluate(x, noise)
    np.testing.assert_array_equal(r1, r0)
    np.testing.assert_array_equal(J1, J0)
    assert single.n_parameters != both.n_parameters
    assert len(single.evaluate(np.zeros(single.n_parameters), noise)[0]) == 6 * len(
        data.poses[0].sample
    )


def test_free_column_jacobian_equals_the_full_one():
    from kinfw.identification.problem import NoiseModel, build_problem

    nominal, _, data = _noise_free_case()
    noise = NoiseModel(1e-3, 1e-2)
    for parameters in ("none", "frames", "full"):
        problem = build_problem(nominal, data, parameters=parameters)
        x = np.where(
            problem.free, np.random.default_rng(27).normal(size=problem.n_parameters) * 1e-3, 0.0
        )
        r, J = problem.evaluate(x, noise, True)
        r_free, J_free = problem.evaluate(x, noise, True, only_free=True)
        np.testing.assert_array_equal(r_free, r)
        np.testing.assert_allclose(
            J_free[:, problem.free], J[:, problem.free], rtol=0, atol=1e-9 * np.abs(J).max()
        )
        assert not np.any(J_free[:, ~problem.free])
        # and both equal the CasADi Jacobian in its original (rows, m * P) layout
        g = problem.groups[0]
        m, P = len(g.sample), problem.n_parameters
        legacy = np.array(g.jacobian(g.qs, g.data, x)) / g.row_sigma(noise)[:, None]
        np.testing.assert_allclose(
            legacy.reshape(g.rows, m, P).transpose(1, 0, 2).reshape(-1, P),
            J[: m * g.rows],
            rtol=0,
            atol=1e-12,
        )


# -- gross errors out of scoring, whitened selection, advice that fits the loss ---------------
@pytest.mark.slow
def test_exclude_flagged_leaves_the_rejected_observation_out_of_scoring(head):
    truth = load_robot(
        perturb_robot(head, np.random.default_rng(4), origin_mm=5.0, origin_deg=1.0, axis_deg=1.0)
    )
    clean = plate_data(truth, 40, 5)
    pose = clean.poses[0]
    T = pose.meas_T_frame.copy()
    T[11, :3, 3] += np.array([0.0, 0.07, 0.0])  # 70 mm on one observation
    bad = replace(clean, poses=(replace(pose, meas_T_frame=T), *clean.poses[1:]))
    sample = int(pose.sample[11])
    scored = crossvalidate(head, bad, k=4, sets=("full",))
    assert scored.excluded == ()
    fold = next(s for s in scored.scores if s.worst_sample == sample)
    assert 60.0 < fold.worst < 80.0  # the bad pose, held out, scored (mm)
    cv = crossvalidate(head, bad, k=4, sets=("full",), exclude_flagged=True)
    assert cv.excluded == ((sample, "pose", pose.frame, None),)
    assert cv.to_dict()["excluded"] == [
        {"sample": sample, "kind": "pose", "frame": pose.frame, "marker": None}
    ]
    assert max(s.worst for s in cv.scores) < 5.0  # noise 0.5 mm: nothing gross scored
    # the same folds and fits: only the bad observation's fold changes
    changed = [
        a.fold
        for a, b in zip(scored.scores, cv.scores, strict=True)
        if a.of("position") != b.of("position")
    ]
    assert changed == [fold.fold]


def test_selection_weighs_position_and_orientation_by_the_noise():
    """By hand: 'offsets' is 10 % better in position but 0.2 deg worse in orientation on
    0.1 deg noise; whitened, 'full' wins (position alone would pick 'offsets')."""
    from kinfw.observations import POSITION, ROTATION
    from kinfw.verification.evaluation import CrossValidation, FoldScore

    def score(fold, p, mm, deg):
        errors = ((POSITION.display, mm), (ROTATION.display, deg))
        return FoldScore(fold, p, 30, 10, errors, 0, mm, 10.0, 20, 300)

    scores = (
        score(0, "offsets", 0.9, 0.6),
        score(1, "offsets", 0.9, 0.6),
        score(0, "full", 1.0, 0.4),
        score(1, "full", 1.0, 0.4),
    )
    noise = ((POSITION, 1e-3), (ROTATION, np.radians(0.1)))
    cv = CrossValidation(2, 0, ("offsets", "full"), scores, (), None, noise)
    assert cv.whitened("offsets") == pytest.approx(0.9**2 + 6.0**2)
    assert cv.whitened("full") == pytest.approx(1.0**2 + 4.0**2)
    assert min(cv.sets, key=cv.whitened) == "full"
    assert min(cv.sets, key=cv.mean) == "offsets"


def test_the_outlier_advice_names_huber_only_when_it_is_not_in_use():
    from kinfw.observations import POSITION, ROTATION
    from kinfw.verification.evaluation import FoldScore
    from kinfw.verification.evaluation._crossval import _warnings

    def errors(mm):
        return ((POSITION.display, mm), (ROTATION.display, 0.1))

    scores = [
        FoldScore(0, "frames", 30, 10, errors(1.0), 3, 2.0, 10.0, 12, 300),
        FoldScore(1, "frames", 30, 10, errors(1.0), 4, 2.0, 10.0, 12, 300),
        FoldScore(0, "full", 30, 10, errors(1.5), 3, 2.0, 10.0, 20, 300),
        FoldScore(1, "full", 30, 10, errors(2.0), 4, 70.0, 10.0, 20, 300),
    ]
    (linear,) = _warnings(scores, ("frames", "full"), "linear")
    assert "sample 4: 70.0 mm" in linear and "try --loss huber" in linear
    (huber,) = _warnings(scores, ("frames", "full"), "huber")
    assert "sample 4: 70.0 mm" in huber and "try --loss huber" not in huber
    assert "--exclude-flagged" in huber


@pytest.mark.slow
def test_a_set_the_training_folds_refuse_is_left_out_and_said():
    """90 contacts of one plane (6R arm, 0.1 mm): forced full drifts along what contacts
    do not determine and is refused on the training folds; cross-validation scores the
    other sets, says which was left out and why, and selects among those scored; every
    set refused raises the refusal."""
    from kinfw.identification.checks import InsufficientDataError
    from kinfw.simulation import simulate_measurements
    from tests.robots import ARM_6R

    nominal = load_robot(ARM_6R)
    sim = simulate_measurements(
        nominal, contacts=[("flange", None)], contact_samples=90, noise_m=1e-4, seed=7
    )
    cv = crossvalidate(nominal, sim.data, k=3, sets=("frames", "offsets", "full"), select=True)
    assert cv.sets == ("frames", "offsets") and cv.selected in cv.sets
    assert {s.parameters for s in cv.scores} == {"frames", "offsets"} and len(cv.scores) == 6
    (said,) = [w for w in cv.warnings if "not scored" in w]
    assert said.startswith("--params full not scored: refused on the training samples of fold ")
    assert "too little data to refine --params full" in said
    assert cv.to_dict()["sets"] == ["frames", "offsets"]
    with pytest.raises(InsufficientDataError, match="too little data to refine --params full"):
        crossvalidate(nominal, sim.data, k=3, sets=("full",))
