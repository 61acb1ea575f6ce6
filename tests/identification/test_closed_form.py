"""CPC closed form (Shih et al. section 4) on simulated data with a known truth."""

from dataclasses import replace

import numpy as np
import pytest

from kinfw.identification import ProtocolError, identify_closed_form, one_joint_groups
from kinfw.measurements import Measurements
from kinfw.model import cpc_from_robot, load_robot
from kinfw.progress import reporting
from kinfw.simulation import one_joint_at_a_time, perturb_robot, simulate_at
from kinfw.urdf import export_urdf
from kinfw.verification.evaluation import pose_discrepancy, random_joint_values
from tests.paths import HEAD_URDF as HEAD
from tests.recorder import Recorder
from tests.robots import ARM_6R, PRISMATIC_TREE

CASES = [
    pytest.param(HEAD, ("left_plate", "right_plate"), id="iis-head"),
    pytest.param(ARM_6R, ("flange",), id="arm6r"),
    pytest.param(PRISMATIC_TREE, ("tool_a", "cam", "tool_b"), id="prismatic-tree"),
]


def _experiment(
    urdf, frames, *, seed=0, per_joint=5, noise_mm=0.0, noise_deg=0.0, error_mm=20.0, error_deg=3.0
):
    """Nominal robot, a truth cm/degrees away from it, and one-joint-at-a-time data."""
    nominal = load_robot(urdf)
    rng = np.random.default_rng(seed)
    truth = load_robot(
        perturb_robot(nominal, rng, origin_mm=error_mm, origin_deg=error_deg, axis_deg=error_deg)
    )
    names = nominal.topology(frames).joint_names
    lower, upper = nominal.joint_limits(names)
    qs, _ = one_joint_at_a_time(lower, upper, per_joint=per_joint)
    data = simulate_at(
        truth,
        qs,
        names,
        frames=frames,
        rng=rng,
        noise_m=noise_mm * 1e-3,
        noise_rad=np.radians(noise_deg),
    )
    return nominal, truth, data


@pytest.mark.parametrize(("urdf", "frames"), CASES)
def test_noise_free_data_gives_the_true_robot_through_the_exported_urdf(urdf, frames):
    nominal, truth, data = _experiment(urdf, frames)
    result = identify_closed_form(nominal, data)
    calibrated = load_robot(export_urdf(nominal, result.geometry).urdf_xml)
    names = result.model.topology.joint_names
    qs = random_joint_values(nominal, names, 200, np.random.default_rng(9))
    for frame in frames:
        dp, dr = pose_discrepancy(
            calibrated.frame_poses(qs, frame, names), truth.frame_poses(qs, frame, names)
        )
        assert dp < 1e-9 and dr < 1e-9, (frame, dp, dr)  # 1e-6 mm
    # the nominal was far off: several mm / degrees
    dp, dr = pose_discrepancy(
        nominal.frame_poses(qs, frames[0], names), truth.frame_poses(qs, frames[0], names)
    )
    assert dp > 5e-3 and dr > np.radians(0.5)


def test_the_answer_does_not_depend_on_the_nominal_geometry():
    nominal, _, data = _experiment(HEAD, ("left_plate", "right_plate"), noise_mm=0.5, noise_deg=0.3)
    far = load_robot(
        perturb_robot(
            nominal, np.random.default_rng(5), origin_mm=50.0, origin_deg=10.0, axis_deg=10.0
        )
    )
    a = identify_closed_form(nominal, data).model
    b = identify_closed_form(far, data).model
    qs = random_joint_values(nominal, a.topology.joint_names, 100, np.random.default_rng(1))
    dp, dr = pose_discrepancy(a.frame_poses(qs), b.frame_poses(qs))
    assert dp < 1e-12 and dr < 1e-12


def test_the_answer_does_not_depend_on_sample_order():
    nominal, _, data = _experiment(HEAD, ("left_plate", "right_plate"), noise_mm=0.5, noise_deg=0.3)
    perm = np.random.default_rng(2).permutation(data.n_samples)
    shuffled = data.subset(perm)
    a = identify_closed_form(nominal, data).model
    b = identify_closed_form(nominal, shuffled).model
    qs = random_joint_values(nominal, a.topology.joint_names, 100, np.random.default_rng(1))
    dp, dr = pose_discrepancy(a.frame_poses(qs), b.frame_poses(qs))
    assert dp < 1e-12 and dr < 1e-12


@pytest.mark.filterwarnings("ignore:.*outside its URDF limits")
def test_the_answer_does_not_depend_on_the_length_unit():
    """Positions and prismatic joint values in mm give the same axes, lengths x 1000."""
    nominal, _, data = _experiment(
        PRISMATIC_TREE, ("tool_a", "cam", "tool_b"), noise_mm=0.3, noise_deg=0.2
    )
    prismatic = [not nominal.joint(n).is_revolute for n in data.joint_names]
    scaled_q = data.qs.copy()
    scaled_q[:, prismatic] *= 1000.0

    def mm(g):
        T = g.meas_T_frame.copy()
        T[:, :3, 3] *= 1000.0
        return replace(g, meas_T_frame=T)

    in_mm = Measurements(data.joint_names, scaled_q, tuple(mm(g) for g in data.poses))
    a = identify_closed_form(nominal, data).geometry
    b = identify_closed_form(nominal, in_mm).geometry
    np.testing.assert_allclose(b.axes, a.axes, atol=1e-12)
    revolute = np.array(a.topology.revolute)
    np.testing.assert_allclose(b.points[revolute], 1000.0 * a.points[revolute], atol=1e-9)
    np.testing.assert_allclose(b.w_T_frames[:, :3, :3], a.w_T_frames[:, :3, :3], atol=1e-12)
    np.testing.assert_allclose(b.w_T_frames[:, :3, 3], 1000.0 * a.w_T_frames[:, :3, 3], atol=1e-9)


def test_shared_joints_are_identified_from_either_branch():
    """Drop the left plate whenever pan or tilt moves: the right plate alone identifies them
    (and the left plate still carries its own vergence joint)."""
    nominal, truth, data = _experiment(HEAD, ("left_plate", "right_plate"))
    names = data.joint_names
    shared = np.isin(np.arange(len(names)), [names.index("pan"), names.index("tilt")])
    q0 = np.median(data.qs, axis=0)
    moved_shared = (np.abs(data.qs - q0) > 1e-9)[:, shared].any(axis=1)
    left = data.poses[0]
    keep = ~moved_shared[left.sample]
    thinned = replace(
        data,
        poses=(
            replace(left, sample=left.sample[keep], meas_T_frame=left.meas_T_frame[keep]),
            data.poses[1],
        ),
    )
    result = identify_closed_form(nominal, thinned)
    truth_model = cpc_from_robot(truth, ("left_plate", "right_plate"))
    qs = random_joint_values(nominal, names, 100, np.random.default_rng(3))
    dp, dr = pose_discrepancy(result.model.frame_poses(qs), truth_model.frame_poses(qs))
    assert dp < 1e-9 and dr < 1e-9


def test_paper_noise_gives_sub_millimetre_held_out_error():
    """sigma 0.5 mm, 9 per joint: the paper's Fig. 11 finds < 1 mm positioning error."""
    errors = []
    for seed in range(5):
        nominal, truth, data = _experiment(
            HEAD,
            ("left_plate", "right_plate"),
            seed=seed,
            per_joint=9,
            noise_mm=0.5,
            noise_deg=0.3,
            error_mm=5.0,
            error_deg=1.0,
        )
        model = identify_closed_form(nominal, data).model
        truth_model = cpc_from_robot(truth, ("left_plate", "right_plate"))
        qs = random_joint_values(nominal, data.joint_names, 200, np.random.default_rng(seed))
        d = model.frame_poses(qs)[..., :3, 3] - truth_model.frame_poses(qs)[..., :3, 3]
        errors.append(np.linalg.norm(d, axis=-1).mean())
    assert 1e-4 < np.mean(errors) < 1e-3


def test_group_detection_by_hand():
    qs = np.array([[0.0, 1.0], [0.5, 1.0], [0.0, 2.0], [0.0, 1.0], [0.7, 1.0]])
    q0, moved = one_joint_groups(qs, ("a", "b"), "x")
    np.testing.assert_array_equal(q0, [0.0, 1.0])
    np.testing.assert_array_equal(moved, [-1, 0, 1, -1, 0])


def _head_data(**kwargs):
    return _experiment(HEAD, ("left_plate", "right_plate"), **kwargs)


def test_two_joints_moved_at_once_is_refused_naming_sample_and_joints():
    nominal, _, data = _head_data()
    qs = data.qs.copy()
    qs[7, data.joint_names.index("tilt")] += 0.1  # samples 6-10 move y_table already
    with pytest.raises(
        ProtocolError,
        match=r"sample 7 differs from the common configuration q0 in joints "
        r"\['y_table', 'tilt'\]; the closed form needs one-joint-at-a-time",
    ):
        identify_closed_form(nominal, replace(data, qs=qs))


def test_a_joint_that_never_moved_is_named():
    nominal, _, data = _head_data()
    tilt = data.joint_names.index("tilt")
    q0 = np.median(data.qs, axis=0)
    still = np.abs(data.qs[:, tilt] - q0[tilt]) < 1e-9
    with pytest.raises(ProtocolError, match=r"joint 'tilt' moves through 1 distinct value"):
        identify_closed_form(nominal, data.subset(np.flatnonzero(still)))


def test_joints_not_in_the_file_are_held_at_zero_and_so_never_move():
    nominal, _, data = _head_data()
    keep = [n != "pan" for n in data.joint_names]
    q0 = np.median(data.qs, axis=0)
    pan_still = np.abs(data.qs[:, data.joint_names.index("pan")] - q0[2]) < 1e-9
    dropped = data.subset(np.flatnonzero(pan_still))
    dropped = replace(
        dropped,
        joint_names=tuple(n for n in data.joint_names if n != "pan"),
        qs=dropped.qs[:, keep],
    )
    with pytest.raises(ProtocolError, match="joint 'pan' moves through 1 distinct value"):
        identify_closed_form(nominal, dropped)


@pytest.mark.filterwarnings("ignore:.*outside its URDF limits")
def test_degrees_read_as_radians_are_caught():
    nominal, _, data = _head_data()
    qs = data.qs.copy()
    pan = data.joint_names.index("pan")
    qs[:, pan] = np.degrees(qs[:, pan])
    with pytest.raises(
        ProtocolError,
        match=r"joint 'pan' turns 0\.01745 rad per unit .*"
        r"degrees read as radians",
    ):
        identify_closed_form(nominal, replace(data, qs=qs))


@pytest.mark.filterwarnings("ignore:.*outside its URDF limits")
def test_millimetres_read_as_metres_are_caught():
    nominal, _, data = _head_data()
    qs = data.qs.copy()
    qs[:, data.joint_names.index("y_table")] *= 1000.0
    with pytest.raises(ProtocolError, match=r"joint 'y_table' moves 0\.001 m per unit"):
        identify_closed_form(nominal, replace(data, qs=qs))


def test_data_without_pose_observations_is_refused():
    nominal, _, data = _head_data()
    with pytest.raises(ProtocolError, match="needs 'pose' observations"):
        identify_closed_form(nominal, replace(data, poses=()))
    marker = replace(data, poses=tuple(replace(g, marker="m") for g in data.poses))
    with pytest.raises(ProtocolError, match="no marker, no measured_in"):
        identify_closed_form(nominal, marker)


def test_only_far_apart_values_leave_the_sense_ambiguous():
    """Values 0 and 3.0 rad only: a rotation of 3.0 rad looks like -3.28 rad."""
    nominal = load_robot(ARM_6R)
    names = nominal.topology(("flange",)).joint_names
    qs = np.zeros((13, 6))
    for j in range(6):
        qs[1 + 2 * j, j], qs[2 + 2 * j, j] = 0.4, 0.8
    qs[1, 0], qs[2, 0] = 3.0, 3.0  # j1 takes only the values 0 and 3.0
    data = simulate_at(nominal, qs, names, frames=("flange",), rng=np.random.default_rng(0))
    with pytest.raises(
        ProtocolError,
        match=r"joint 'j1': every pair of its values is at "
        r"least pi - 0.2 rad apart",
    ):
        identify_closed_form(nominal, data)
    qs[2, 0] = 1.0  # one more value closer to 0: fine
    data = simulate_at(nominal, qs, names, frames=("flange",), rng=np.random.default_rng(0))
    assert identify_closed_form(nominal, data).motion_scale[0] == pytest.approx(1.0, abs=1e-9)


def test_the_closed_form_reports_a_step_per_revolute_joint_axis():
    """Its pairs of poses grow with the square of each joint's samples: a step per
    revolute joint (the head's pan, tilt and vergences, not its X-Y table; the prismatic
    tree's pan, a1, a2 on the way to tool_a), and the same answer as unobserved."""
    cases = ((HEAD, ("left_plate", "right_plate"), 4), (PRISMATIC_TREE, ("tool_a",), 3))
    for urdf, frames, revolute in cases:
        nominal, _, data = _experiment(urdf, frames)
        recorder = Recorder()
        with reporting(recorder):
            result = identify_closed_form(nominal, data)
        (task,) = recorder.tasks
        assert (task.name, task.total, task.unit, task.closed) == (
            "closed form: joint axes",
            revolute,
            "joints",
            True,
        )
        assert [done for done, _ in task.steps] == list(range(1, revolute + 1))
        silent = identify_closed_form(nominal, data)
        np.testing.assert_array_equal(silent.model.b, result.model.b)
        np.testing.assert_array_equal(silent.model.l, result.model.l)
