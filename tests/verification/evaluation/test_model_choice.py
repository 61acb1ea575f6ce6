"""Model choice by default: small data does not get the full set, plentiful data does."""

import json

import numpy as np
import pytest

import kinfw.verification.evaluation._model_choice as model_choice
from kinfw.cli._main import main
from kinfw.files import sidecar_path
from kinfw.identification import identify
from kinfw.measurements import write_measurements
from kinfw.model import cpc_from_robot, load_robot
from kinfw.records import read_sidecar
from kinfw.simulation import perturb_robot, random_configurations, simulate_at
from kinfw.verification.evaluation import ROWS_PER_PARAMETER, choose_parameters, rows_per_parameter
from tests.paths import DATA
from tests.paths import HEAD_URDF as HEAD

PLATES = ("left_plate", "right_plate")


def _data(truth, n, seed, noise_m, noise_rad):
    rng = np.random.default_rng(seed)
    names = truth.topology(PLATES).joint_names
    qs = random_configurations(*truth.joint_limits(names), n, rng, fraction=0.8)
    return simulate_at(
        truth, qs, names, frames=PLATES, rng=rng, noise_m=noise_m, noise_rad=noise_rad
    )


@pytest.fixture(scope="module")
def mounts_only(head):
    """Truth differs from the nominal only in the plates' mounts (the case 'full' overfits
    with 12 samples, tests/verification/evaluation/test_crossval.py)."""
    truth = load_robot(
        perturb_robot(
            head,
            np.random.default_rng(2),
            origin_mm=5.0,
            origin_deg=1.0,
            axis_deg=0.0,
            joints=("left_plate_joint", "right_plate_joint"),
        )
    )
    return truth, _data(truth, 12, 3, noise_m=1e-3, noise_rad=0.01)


def _held_out_vs_truth(nominal, truth, data, parameters, prior):
    """Position RMS (mm) and rotation RMS (deg) of the plates at 200 fresh configurations,
    the model calibrated with ``parameters``/``prior`` against the noise-free truth."""
    result = identify(nominal, data, parameters=parameters, prior=prior)
    model = cpc_from_robot(load_robot(result.urdf_xml), PLATES)
    qs = random_configurations(
        *nominal.joint_limits(data.joint_names), 200, np.random.default_rng(6), fraction=0.8
    )
    T_model = model.frame_poses(qs)
    T_true = cpc_from_robot(truth, PLATES).frame_poses(qs)
    d = T_model[..., :3, 3] - T_true[..., :3, 3]
    R = np.swapaxes(T_true[..., :3, :3], -1, -2) @ T_model[..., :3, :3]
    angle = np.arccos(np.clip((np.trace(R, axis1=-2, axis2=-1) - 1) / 2, -1, 1))
    return 1e3 * np.sqrt(np.mean(np.sum(d**2, axis=-1))), np.degrees(np.sqrt(np.mean(angle**2)))


@pytest.mark.slow
def test_small_data_is_not_given_the_full_set_and_predicts_the_truth_better(head, mounts_only):
    truth, data = mounts_only
    choice = choose_parameters(head, data)
    assert choice.rows_per_parameter < ROWS_PER_PARAMETER and choice.k == data.n_samples
    assert (choice.parameters, choice.prior) != ("full", None)
    labels = [c.label for c in choice.candidates]
    assert labels[:3] == ["frames", "offsets", "full"] and len(labels) == 4
    assert choice.candidates[3].prior.how == "leave-one-out"  # full under the chosen prior
    assert "cross-validation" in choice.reason
    (chosen,) = [
        c for c in choice.candidates if (c.parameters, c.prior) == (choice.parameters, choice.prior)
    ]
    assert chosen.whitened <= 1.01 * min(c.whitened for c in choice.candidates)
    assert chosen.whitened < choice.candidates[2].whitened  # full alone scores worse
    # against the truth (not the held-out measurements): the chosen model is no worse
    pos, rot = _held_out_vs_truth(head, truth, data, choice.parameters, choice.prior)
    pos_full, rot_full = _held_out_vs_truth(head, truth, data, "full", None)
    assert pos <= pos_full and rot <= rot_full


def test_plentiful_data_gets_the_full_set_without_cross_validation(head, monkeypatch):
    truth = load_robot(
        perturb_robot(head, np.random.default_rng(4), origin_mm=5.0, origin_deg=1.0, axis_deg=1.0)
    )
    small = _data(truth, 12, 5, noise_m=0.5e-3, noise_rad=0.005)
    big = _data(truth, 85, 5, noise_m=0.5e-3, noise_rad=0.005)
    # residual rows grow with the samples; the parameters (no per-sample unknowns) do not
    assert rows_per_parameter(head, big) == pytest.approx(85 / 12 * rows_per_parameter(head, small))

    def no_crossval(*args, **kwargs):
        raise AssertionError("cross-validation ran on plentiful data")

    monkeypatch.setattr(model_choice, "leave_one_out", no_crossval)
    # the head's links have inertias: full is fitted once (the calibration itself) for the
    # compliance's score test, which these rigid data fail: nothing more is fitted
    fitted = []
    real_identify = model_choice.identify
    monkeypatch.setattr(
        model_choice,
        "identify",
        lambda *a, **k: fitted.append(k["parameters"]) or real_identify(*a, **k),
    )
    choice = choose_parameters(head, big)
    assert (choice.parameters, choice.prior, choice.candidates, choice.k) == ("full", None, (), 0)
    assert fitted == ["full"] and not choice.spec and choice.fit is not None
    assert choice.rows_per_parameter >= ROWS_PER_PARAMETER
    assert "enough to estimate every parameter" in choice.reason
    monkeypatch.setattr(model_choice, "identify", no_crossval)
    with pytest.raises(AssertionError, match="cross-validation ran"):
        choose_parameters(head, small)  # the small set does go to cross-validation


@pytest.mark.slow
def test_the_cli_default_chooses_and_records_and_params_forces(tmp_path, capsys, mounts_only):
    _, data = mounts_only
    path = tmp_path / "data.json"
    write_measurements(path, data)
    base = ["calibrate", "--urdf", str(HEAD), "--out", str(tmp_path / "c.urdf"), str(path)]
    assert main([*base, "--report", str(tmp_path / "r.json")]) == 0
    out = capsys.readouterr().out
    assert "held-out error of each candidate" in out and "<- chosen" in out
    notes = json.loads((tmp_path / "r.json").read_text())["notes"]
    (note,) = [n for n in notes if n.startswith("parameters: ")]
    assert not note.startswith("parameters: full (") and "cross-validation" in note
    # the sidecar beside the URDF records the same choice, read back typed
    model = read_sidecar(sidecar_path(tmp_path / "c.urdf")).model
    label = note.removeprefix("parameters: ").split(" (")[0]
    assert label.split(",")[0] == model.parameters[0] and model.reason in note
    assert (model.prior is None) == ("prior" not in label)
    assert main([*base, "--params", "full", "--report", str(tmp_path / "f.json")]) == 0
    out = capsys.readouterr().out
    assert "candidate" not in out
    notes = json.loads((tmp_path / "f.json").read_text())["notes"]
    assert not any(n.startswith("parameters: ") for n in notes)
    model = read_sidecar(sidecar_path(tmp_path / "c.urdf")).model
    assert (model.parameters, model.prior, model.reason) == (("full",), None, "given")
    args = [*base, "--params", "frames", "--prior-mm", "2", "--prior-deg", "0.5"]
    assert main(args) == 0
    model = read_sidecar(sidecar_path(tmp_path / "c.urdf")).model
    assert model.parameters == ("frames",) and model.reason == "given"
    assert model.prior.is_uniform and model.prior.how == "given"
    assert model.prior.sigma_m == pytest.approx(2e-3)
    assert model.prior.sigma_rad == pytest.approx(np.radians(0.5))
    # one group's sigma over the uniform ones, through the shell into the sidecar
    args = [*base, "--params", "full", "--prior-mm", "2", "--prior-deg", "0.5"]
    assert main([*args, "--prior", "offsets=3deg", "--prior", "tools=5mm"]) == 0
    prior = read_sidecar(sidecar_path(tmp_path / "c.urdf")).model.prior
    assert prior.sigma("offsets", "rad") == pytest.approx(np.radians(3.0))
    assert prior.sigma("tools", "m") == pytest.approx(5e-3)
    assert prior.sigma("axes", "rad") == pytest.approx(np.radians(0.5))


@pytest.mark.slow
def test_a_gross_error_is_left_out_of_every_score_and_named(head, mounts_only):
    """A 60 mm error planted in one plate pose: the full-data fit rejects it and the
    choice names it; scored without it, the fold that holds it scores like the others
    (unscored it dominates that fold: > 10 mm on 1 mm noise)."""
    from dataclasses import replace

    from kinfw.verification.evaluation import crossvalidate

    _, clean = mounts_only
    poses = list(clean.poses)
    T = poses[0].meas_T_frame.copy()
    T[7, :3, 3] += [0.0, 0.06, 0.0]
    poses[0] = replace(poses[0], meas_T_frame=T)
    bad = replace(clean, poses=tuple(poses))
    choice = choose_parameters(head, bad)
    sample = int(clean.poses[0].sample[7])
    assert choice.excluded == ((sample, "pose", PLATES[0], None),)
    assert f"not scored (sample(s) {sample})" in choice.reason
    order = np.random.default_rng(0).permutation(bad.n_samples)
    (fold,) = [f for f, idx in enumerate(np.array_split(order, 4)) if sample in idx]
    for exclude in (False, True):
        cv = crossvalidate(head, bad, k=4, sets=("frames",), exclude_flagged=exclude)
        hit = next(s.of("position") for s in cv.scores if s.fold == fold)
        others = [s.of("position") for s in cv.scores if s.fold != fold]
        if exclude:
            assert hit < 2.0 * max(others)
        else:
            assert hit > 10.0 > 2.0 * max(others)


@pytest.mark.slow
def test_a_prior_too_strong_for_the_robot_is_scored_not_refused(head):
    """A truth 30 mm / 3 deg from the nominal: with a 0.1 mm / 0.001 rad prior the fit
    stays near the nominal and leaves residuals the unrestricted check would refuse
    ("the data does not describe this robot"); a prior is a deliberate restriction, so
    it is fitted, and predicts worse than the free fit at the truth."""
    truth = load_robot(
        perturb_robot(head, np.random.default_rng(8), origin_mm=30.0, origin_deg=3.0, axis_deg=1.0)
    )
    data = _data(truth, 20, 4, noise_m=0.5e-3, noise_rad=0.005)
    strong = (1e-4, 1e-3)
    pos_strong, _ = _held_out_vs_truth(head, truth, data, "full", strong)
    pos_free, _ = _held_out_vs_truth(head, truth, data, "full", None)
    assert pos_strong > 20.0 > 1.0 > pos_free  # mm


@pytest.mark.slow
def test_a_candidate_the_data_cannot_fit_is_skipped_not_fatal():
    """The real TIAGo Vicon session cut to its first 14 samples: 42 residual rows are too
    few for "full" (33 free parameters and the frames), which used to fail the whole
    choice (`kinfw calibrate` exited 2). Now that candidate is listed as not fitted and
    the others compete; the chosen model predicts the 7 unseen samples better than the
    nominal joints do."""
    from kinfw.identification.problem import Unknown
    from kinfw.measurements import read_measurements
    from kinfw.verification.evaluation import held_out_errors
    from tests.erd import urdf_path

    tiago = load_robot(urdf_path("tiago_description/robots/tiago_no_hand.urdf"))
    data = read_measurements(DATA / "tiago_figaroh" / "vicon_gripper3_base1.json")
    train, test = data.subset(np.arange(14)), data.subset(np.arange(14, 21))
    choice = choose_parameters(tiago, train)
    full = choice.candidates[2]
    assert (full.parameters, full.prior) == ("full", None) and "too little data" in full.failed
    assert choice.parameters != "full" or choice.prior is not None
    assert "full alone cannot be fitted" in choice.reason

    def unseen_rms_mm(parameters, prior):
        result = identify(tiago, train, parameters=parameters, prior=prior)
        frame = Unknown("frame", result.refined.model_frame, result.w_T_root)
        held = held_out_errors(tiago, result.urdf_xml, (*result.refined.unknowns, frame), test)
        pos = held.values("position")[0]
        return 1e3 * np.sqrt(np.mean(pos**2))

    assert unseen_rms_mm(choice.parameters, choice.prior) < 0.7 * unseen_rms_mm("frames", None)


def test_an_image_counts_as_the_pose_it_determines(head):
    """Rows per parameter: an image of the board (2 rows per corner, tens of corners)
    counts as much as the board's pose seen in it (6 rows): 6 x the images the file
    holds (counted here from the observations' samples) per parameter of the full set;
    poses still count 6 each."""
    from kinfw.identification.problem import build_problem
    from kinfw.simulation import simulate_measurements

    sim = simulate_measurements(head, stages=(1, 2), pixels=True, stage2_samples=12, seed=3)
    data = sim.data
    corners = sum(len(g.sample) for g in data.groups("pixels"))
    n_images = sum(len(set(g.sample.tolist())) for g in data.groups("pixels"))
    n_poses = sum(len(g.sample) for g in data.groups("pose"))
    assert corners >= 4 * n_images and n_poses > 0  # many corners per image
    n_parameters = build_problem(head, data, parameters="full").n_parameters
    expected = 6 * (n_images + n_poses) / n_parameters
    assert rows_per_parameter(head, data) == pytest.approx(expected, rel=1e-12)


def test_a_candidates_warnings_name_the_candidate(head, caplog):
    """Poses of a head 2 mm / 0.5 deg off everywhere, the noise stated right (0.1 mm,
    1 mrad of angle): the restricted candidates' fits cannot follow the data, and their
    rejection notes (more observations beyond the threshold than gross errors make) are
    logged; each says which candidate it is about, never reading as the calibration's."""
    from kinfw.identification.problem import NoiseModel

    truth = load_robot(perturb_robot(head, np.random.default_rng(4)))
    data = _data(truth, 20, 5, noise_m=1e-4, noise_rad=1e-3)
    noise = NoiseModel(1e-4, 1e-3 / np.sqrt(3.0))
    with caplog.at_level("WARNING", logger="kinfw"):
        choose_parameters(head, data, noise=noise)
    said = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert any(m.startswith("model choice, candidate frames: refine: ") for m in said), said
    assert all(m.startswith("model choice, candidate ") for m in said), said
