"""Start values of an external frame seen only through markers of unknown offset (issue 12):
one marker in an unknown mocap frame, a marker pose (camera on a flange), and the errors
that name what the data leave undetermined."""

from dataclasses import replace

import numpy as np
import pytest

from kinfw.geometry import inverse_transform, matrix_from_rotation_vector
from kinfw.identification import refine
from kinfw.identification.problem import NoiseModel, build_problem
from kinfw.measurements import Measurements
from kinfw.model import geometry_from_cpc, load_robot
from kinfw.observations import DatasetError
from kinfw.simulation import perturb_robot, random_configurations, simulate_at
from kinfw.urdf import export_urdf
from kinfw.verification.evaluation import random_joint_values
from tests.paths import HEAD_URDF
from tests.robots import ARM_6R

SIGMA = NoiseModel(0.5e-3, np.radians(0.5))
MOCAP_T_ROOT = np.eye(4)
MOCAP_T_ROOT[:3, :3] = matrix_from_rotation_vector([0.3, -0.2, 1.0])
MOCAP_T_ROOT[:3, 3] = [1.0, -0.5, 0.2]
# the 6R arm's flange; the head's left plate (table x, y, pan, tilt, left vergence)
CASES = {"arm": (ARM_6R, "flange"), "head": (HEAD_URDF, "left_plate")}
OFFSET = np.array([0.05, 0.02, 0.03])


def _robots(case, seed=7):
    urdf, frame = CASES[case]
    nominal = load_robot(urdf)
    truth = load_robot(perturb_robot(nominal, np.random.default_rng(seed)))
    names = nominal.topology((frame,)).joint_names
    return nominal, truth, frame, names


def _in_mocap(data):
    """Every point moved into the unknown frame 'mocap'."""
    R, p = MOCAP_T_ROOT[:3, :3], MOCAP_T_ROOT[:3, 3]
    moved = tuple(
        replace(g, meas_p_point=g.meas_p_point @ R.T + p, measured_in="mocap") for g in data.points
    )
    return Measurements(data.joint_names, data.qs, points=moved)


def _one_marker(robot, frame, names, n, seed=1, noise_m=0.0, qs=None):
    rng = np.random.default_rng(seed)
    if qs is None:
        qs = random_configurations(*robot.joint_limits(names), n, rng, fraction=0.7)
    data = simulate_at(robot, qs, names, markers=[(frame, OFFSET, "m1")], rng=rng, noise_m=noise_m)
    return _in_mocap(data)


def _held_out_error(nominal, truth, frame, names, result):
    """Largest distance (m) between the calibration's and the truth's marker positions in
    'mocap' at 50 new configurations."""
    export = export_urdf(nominal, geometry_from_cpc(result.model), root_is_measurement_frame=False)
    calibrated = load_robot(export.urdf_xml)
    (u,) = [u for u in result.unknowns if u.name == f"{frame}:m1"]
    q = random_joint_values(nominal, names, 50, np.random.default_rng(99))
    pred = export.w_T_root @ calibrated.frame_poses(q, frame, names)
    true = MOCAP_T_ROOT @ truth.frame_poses(q, frame, names)
    err = (pred[:, :3, :3] @ u.value + pred[:, :3, 3]) - (true[:, :3, :3] @ OFFSET + true[:, :3, 3])
    return float(np.abs(err).max())


@pytest.mark.parametrize("case", ["arm", "head"])
def test_one_marker_in_an_unknown_frame_recovers_the_truth(case):
    """Used to be refused ('give at least one point offset'); now the frame and the offset
    start from the lifted least squares and the refinement reaches the truth."""
    nominal, truth, frame, names = _robots(case)
    data = _one_marker(truth, frame, names, 60)
    result = refine(nominal, data, noise=SIGMA)
    assert result.converged
    assert result.model_frame == "mocap"
    assert _held_out_error(nominal, truth, frame, names, result) < 1e-8


@pytest.mark.parametrize("case", ["arm", "head"])
def test_the_start_alone_is_exact_when_the_nominal_is_the_truth(case):
    nominal, _, frame, names = _robots(case)
    data = _one_marker(nominal, frame, names, 30)
    problem = build_problem(nominal, data, parameters="none")
    residuals = problem.raw_residuals(np.zeros(problem.n_parameters), with_jacobian=False)
    assert max(np.abs(r).max() for r, _ in residuals) < 1e-9
    (offset,) = [u.value for u in problem.unknowns_at(np.zeros(problem.n_parameters))]
    np.testing.assert_allclose(offset, OFFSET, atol=1e-9)


def test_the_noise_estimate_is_right_with_one_marker():
    nominal, truth, frame, names = _robots("arm")
    sigmas = []
    for seed in range(3):
        data = _one_marker(truth, frame, names, 150, seed=seed, noise_m=0.2e-3)
        sigmas.append(refine(nominal, data, loss="linear").noise.position_m)
    assert abs(np.mean(sigmas) / 0.2e-3 - 1.0) < 0.10


def test_a_marker_in_a_second_unknown_frame_beside_root_poses():
    """Flange poses in the root and one marker in 'mocap': the frame 'mocap' (not the model
    frame) is placed from the marker alone."""
    nominal, truth, frame, names = _robots("arm")
    rng = np.random.default_rng(3)
    qs = random_configurations(*truth.joint_limits(names), 40, rng, fraction=0.7)
    poses = simulate_at(truth, qs, names, frames=(frame,), rng=rng)
    marker = _one_marker(truth, frame, names, 40, qs=qs)
    data = Measurements(names, qs, poses=poses.poses, points=marker.points)
    result = refine(nominal, data, noise=SIGMA)
    (W,) = [u.value for u in result.unknowns if u.kind == "frame"]
    np.testing.assert_allclose(W, MOCAP_T_ROOT, atol=1e-9)


def test_a_camera_marker_pose_in_an_unknown_frame():
    """A = X B Y: 6D poses of a marker (a camera, hand-eye unknown) on the flange measured
    in an unknown frame; both unknowns start from Hirsh's solver, the fit reaches the
    truth."""
    nominal, truth, frame, names = _robots("arm")
    rng = np.random.default_rng(4)
    qs = random_configurations(*truth.joint_limits(names), 30, rng, fraction=0.7)
    flange_T_cam = np.eye(4)
    flange_T_cam[:3, :3] = matrix_from_rotation_vector([0.1, 1.2, -0.4])
    flange_T_cam[:3, 3] = [0.03, -0.06, 0.08]
    (g,) = simulate_at(truth, qs, names, frames=(frame,), rng=rng).poses
    g = replace(g, meas_T_frame=MOCAP_T_ROOT @ g.meas_T_frame @ flange_T_cam)
    data = Measurements(names, qs, poses=(replace(g, marker="cam", measured_in="mocap"),))
    result = refine(nominal, data, noise=SIGMA)
    export = export_urdf(nominal, geometry_from_cpc(result.model), root_is_measurement_frame=False)
    calibrated = load_robot(export.urdf_xml)
    (X,) = [u.value for u in result.unknowns if u.kind == "marker"]
    q = random_joint_values(nominal, names, 50, np.random.default_rng(5))
    pred = export.w_T_root @ calibrated.frame_poses(q, frame, names) @ X
    true = MOCAP_T_ROOT @ truth.frame_poses(q, frame, names) @ flange_T_cam
    np.testing.assert_allclose(pred, true, atol=1e-8)
    assert inverse_transform(X).shape == (4, 4)


def test_a_single_configuration_names_the_undetermined_frame():
    nominal, _, frame, names = _robots("arm")
    q = random_configurations(*nominal.joint_limits(names), 1, np.random.default_rng(0))
    data = _one_marker(nominal, frame, names, 0, qs=np.repeat(q, 10, axis=0))
    with pytest.raises(DatasetError, match=r"do not determine .*'mocap'.*(offset|rotation)"):
        build_problem(nominal, data)


def test_too_few_samples_name_the_undetermined_quantities():
    nominal, _, frame, names = _robots("arm")
    data = _one_marker(nominal, frame, names, 2)
    with pytest.raises(DatasetError, match=r"frame 'mocap' is seen only through markers"):
        build_problem(nominal, data)


def test_the_report_says_not_available_when_the_nominal_cannot_be_placed():
    """The report's "before" errors do not crash on data the nominal cannot be evaluated on
    (issue 12 bullet 3): NaN numbers and a note that names the reason."""
    from kinfw.verification.reporting import errors_by_group
    from kinfw.verification.reporting._report import _errors_or_unavailable

    nominal, _, frame, names = _robots("arm")
    good = errors_by_group(nominal, _one_marker(nominal, frame, names, 30))
    assert good[0].rms("position") < 1e-6
    notes = []
    (row,) = _errors_or_unavailable(nominal, _one_marker(nominal, frame, names, 2), good, notes)
    assert np.isnan(row.rms("position")) and row.group == good[0].group
    assert len(notes) == 1 and "not available" in notes[0] and "'mocap'" in notes[0]


def _undetermined_both_ways(J, monkeypatch):
    """``_undetermined`` on J (columns: mocap rotation, position, offset of 'm') as it is
    and with every SVD forced to full matrices (the previous code), name -> answer."""
    from kinfw.identification.problem import _start

    args = ({"m": 6}, {}, "mocap", {"m": "the offset of 'm'"})
    thin = _start._undetermined(J, *args)
    svd = np.linalg.svd
    with monkeypatch.context() as m:
        m.setattr(_start.np.linalg, "svd", lambda a, **kw: svd(a, full_matrices=True))
        full = _start._undetermined(J, *args)
    return thin, full


def test_undetermined_on_a_tall_jacobian_names_its_hand_built_null_direction(monkeypatch):
    """40 x 9 with the offset's x column equal to the rotation's x column: the one null
    direction is e_0 - e_6 (up to sign), as the full SVD gives."""
    J = np.random.default_rng(3).normal(size=(40, 9))
    J[:, 6] = J[:, 0]
    thin, full = _undetermined_both_ways(J, monkeypatch)
    assert thin == full
    zeros = [n.replace("-0.00", "0.00") for n in thin]
    assert zeros in [
        [
            f"the rotation of 'mocap' along [{a}1.00, 0.00, 0.00]",
            f"the offset of 'm' along [{b}1.00, 0.00, 0.00]",
        ]
        for a, b in (("", "-"), ("-", ""))
    ], thin


def test_undetermined_on_a_wide_jacobian_keeps_every_null_direction(monkeypatch):
    """5 x 9 with only the first five columns (rotation, position x, y) nonzero: the null
    space is spanned by e_5 ... e_8 (position z, the offset), which a thin SVD would drop."""
    J = np.zeros((5, 9))
    J[:, :5] = np.random.default_rng(4).normal(size=(5, 5))
    thin, full = _undetermined_both_ways(J, monkeypatch)
    assert thin == full
    assert sorted(n.replace("-", "") for n in thin) == [
        "the offset of 'm' (3 directions)",
        "the position of 'mocap' along [0.00, 0.00, 1.00]",
    ]
