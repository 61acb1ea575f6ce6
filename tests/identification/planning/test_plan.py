"""Measurement planning (kinfw.identification.planning): against hand-derived optima, the empirical
held-out error of real calibrations, random designs, and the plan file round trip."""

import json

import numpy as np
import pytest

from kinfw.cli._main import main
from kinfw.identification import refine
from kinfw.identification.planning import (
    Setup,
    candidate_information,
    candidate_pool,
    exchange,
    greedy,
    held_out,
    mean_square,
    plan_configurations,
    plan_per_joint,
    predicted_error,
    read_plan,
    short_path,
)
from kinfw.identification.problem import NoiseModel
from kinfw.measurements import read_measurements
from kinfw.model import load_robot
from kinfw.simulation import random_configurations, simulate_at
from tests.paths import HEAD_URDF

# one prismatic joint along z of a tilted frame: the measured frame's origin moves on a
# line p(q) = p0 + q a, its orientation is constant
PRISMATIC = """<?xml version="1.0"?>
<robot name="p1"><link name="world"/>
<joint name="j1" type="prismatic"><parent link="world"/><child link="l1"/>
<origin xyz="0.1 0.2 0.3" rpy="0.3 0.2 0.1"/><axis xyz="0 0 1"/>
<limit lower="-0.5" upper="0.5" effort="1" velocity="1"/></joint>
<link name="l1"/></robot>"""

SIGMA_M = 1e-3


def _line_fit_ms(design_q, test_q, sigma):
    """Hand truth: the mean square 3D error of a line fit p0 + q a (a unit, 2 free
    directions) at test_q: along the axis only p0 (sigma^2/N), across it two ordinary
    straight-line fits (sigma^2 (1/N + (q - qbar)^2 / Sxx) each)."""
    n = len(design_q)
    qbar = design_q.mean()
    sxx = np.sum((design_q - qbar) ** 2)
    return sigma**2 * (3.0 / n + 2.0 * np.mean((test_q - qbar) ** 2) / sxx)


@pytest.fixture(scope="module")
def prismatic():
    robot = load_robot(PRISMATIC)
    setup = Setup(frames=("l1",), noise_m=SIGMA_M, noise_rad=np.radians(0.1))
    pool = np.linspace(-0.5, 0.5, 41)[:, None]
    test = np.linspace(-0.45, 0.45, 31)[:, None]  # symmetric about the middle
    return robot, setup, pool, test


def test_line_fit_optimum_is_the_extremes(prismatic):
    robot, setup, pool, test = prismatic
    plan = plan_configurations(robot, setup, pool, 6, joint_names=("j1",), test_qs=test)
    q = np.sort(plan.qs[:, 0])
    # I-optimal for a straight line, distinct points: the three lowest and highest
    np.testing.assert_allclose(q, [-0.5, -0.475, -0.45, 0.45, 0.475, 0.5], atol=1e-12)
    expected = _line_fit_ms(q, test[:, 0], SIGMA_M)
    assert plan.rms("position") == pytest.approx(np.sqrt(expected), rel=1e-6)
    # the same formula for an arbitrary design, through predicted_error
    design = np.array([[-0.3], [0.0], [0.1], [0.2], [0.4]])
    ((_, pos), *_) = predicted_error(robot, setup, design, test, joint_names=("j1",))
    assert pos == pytest.approx(np.sqrt(_line_fit_ms(design[:, 0], test[:, 0], SIGMA_M)), rel=1e-6)


def test_predicted_equals_empirical_held_out_error(prismatic):
    """Mean over 20 noisy calibrations of the held-out mean square position error
    against the prediction, within 3 standard errors of the mean."""
    robot, setup, pool, test = prismatic
    plan = plan_configurations(robot, setup, pool, 8, joint_names=("j1",), test_qs=test)
    true_p = robot.frame_poses(test, "l1", ("j1",))[:, :3, 3]
    ms = []
    for seed in range(20):
        rng = np.random.default_rng(seed)
        data = simulate_at(
            robot, plan.qs, ("j1",), frames=("l1",), rng=rng, noise_m=SIGMA_M, noise_rad=0.0
        )
        result = refine(robot, data, noise=NoiseModel(SIGMA_M, setup.noise_rad), reject=None)
        got = result.model.frame_poses(test, "l1")[:, :3, 3]
        ms.append(np.mean(np.sum((got - true_p) ** 2, axis=1)))
    ms = np.array(ms)
    se = ms.std(ddof=1) / np.sqrt(len(ms))
    assert abs(ms.mean() - plan.rms("position") ** 2) < 3 * se, (
        ms.mean(),
        plan.rms("position") ** 2,
    )


@pytest.fixture(scope="module")
def head():
    robot = load_robot(HEAD_URDF)
    setup = Setup(frames=robot.default_frames)
    names = robot.topology(setup.observed).joint_names
    lower, upper = robot.joint_limits(names)
    rng = np.random.default_rng(3)
    pool = random_configurations(lower, upper, 400, rng, fraction=0.8)
    test = random_configurations(lower, upper, 100, rng, fraction=0.8)
    return robot, setup, names, pool, test


@pytest.mark.slow
def test_planned_beats_random_and_exchange_never_worsens(head):
    robot, setup, names, pool, test = head
    plan = plan_configurations(
        robot, setup, pool, 30, joint_names=names, test_qs=test, random_draws=10
    )
    assert plan.rms("position") < 0.9 * plan.random_rms
    assert plan.exchanged_ms <= plan.greedy_ms
    # exchange from random designs: never worse than where it starts
    info = candidate_information(robot, setup, pool, names, None)
    A = held_out(robot, setup, test, names, None, info).of("position")
    rng = np.random.default_rng(0)
    for _ in range(3):
        start = rng.choice(len(pool), 30, replace=False)
        before = mean_square(info, A, start, ridge=1e-6)
        _, after, _ = exchange(info, A, start)
        assert after <= before * (1 + 1e-9)
    order, values = greedy(info, A, 30)
    assert len(set(order.tolist())) == 30 and np.all(np.diff(values) <= 0)


def test_per_joint_protocol(head):
    robot, setup, names, _, test = head
    out = plan_per_joint(robot, setup, 5, joint_names=names, test_qs=test, grid=21)
    moved = np.sum(out["qs"] != out["qs"][0], axis=1)
    assert np.all(moved <= 1)  # one joint at a time
    assert out["n_planned"] == 5 * len(names) + 1
    assert out["planned_position_rms_m"] <= out["even_position_rms_m"]


@pytest.mark.slow
def test_visibility_of_planned_camera_configurations():
    robot = load_robot(HEAD_URDF)
    setup = Setup(cameras=robot.default_cameras, pixels=True)
    names = robot.topology(setup.observed).joint_names
    lower, upper = robot.joint_limits(names)
    w_T = setup.target_pose(robot, names, 0.5 * (lower + upper))
    rng = np.random.default_rng(1)
    pool = candidate_pool(robot, setup, names, w_T, within_limits=0.9, n=400, rng=rng)
    assert pool.dropped.get("board not seen", 0) > 0
    test = candidate_pool(
        robot, setup, names, w_T, qs=random_configurations(lower, upper, 100, rng, fraction=0.9)
    ).qs
    plan = plan_configurations(
        robot, setup, pool.qs, 15, joint_names=names, test_qs=test, w_T_target=w_T
    )
    # every planned configuration: in some camera, at least 4 of the board's corners
    # project (hand pinhole, no distortion) into the image, in front of the camera
    board = setup.board_points()
    w_p = board @ w_T[:3, :3].T + w_T[:3, 3]
    any_seen = np.zeros(len(plan.qs), bool)
    for cam, intr in setup.camera_intrinsics().items():
        T = robot.frame_poses(plan.qs, cam, names)
        c_p = np.einsum("nji,nkj->nki", T[:, :3, :3], w_p[None] - T[:, None, :3, 3])
        u = intr.fx * c_p[..., 0] / c_p[..., 2] + intr.cx
        v = intr.fy * c_p[..., 1] / c_p[..., 2] + intr.cy
        inside = (c_p[..., 2] > 0) & (u >= 0) & (u < intr.width) & (v >= 0) & (v < intr.height)
        any_seen |= inside.sum(axis=1) >= 4
    assert any_seen.all()


def test_short_path_is_shorter_than_the_input_order():
    rng = np.random.default_rng(0)
    qs = rng.uniform(-1, 1, (30, 3))
    order = short_path(qs, -np.ones(3), np.ones(3))
    assert sorted(order.tolist()) == list(range(30))

    def length(x):
        return np.sum(np.linalg.norm(np.diff(x, axis=0), axis=1))

    assert length(qs[order]) < 0.6 * length(qs)


def test_plan_file_round_trip_and_simulate_plan(tmp_path, capsys):
    plan_file = tmp_path / "plan.json"
    assert main(["plan", "--n", "12", "--candidates", "200", "--out", str(plan_file)]) == 0
    names, qs = read_plan(plan_file)
    doc = json.loads(plan_file.read_text())
    assert doc["format"] == "kinfw-plan" and doc["version"] == 1 and len(qs) == 12
    out = tmp_path / "m.json"
    args = ["simulate", "--plan", str(plan_file), "--out", str(out)]
    assert main([*args, "--truth-out", str(tmp_path / "t.urdf")]) == 0
    data = read_measurements(out)
    np.testing.assert_array_equal(data.q_of(names), qs)
    # never over an input; bad plan files: exit 2, one line naming the file and key
    capsys.readouterr()
    assert main(["plan", "--n", "5", "--candidates", "50", "--out", str(HEAD_URDF)]) == 2
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({**doc, "configurations": [[0.0]]}))
    assert (
        main(
            [
                *args[:1],
                "--plan",
                str(bad),
                "--out",
                str(out),
                "--truth-out",
                str(tmp_path / "t.urdf"),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert "bad.json" in err and '"configurations"' in err


def test_plan_errors(capsys):
    assert main(["plan", "--frames", "nope"]) == 2
    assert "no frame 'nope'" in capsys.readouterr().err
    assert main(["plan", "--within-limits", "0"]) == 2
    assert main(["plan", "--n", "50", "--candidates", "20"]) == 2
    assert "only 20 candidates" in capsys.readouterr().err


@pytest.mark.slow
def test_target_gives_the_smallest_greedy_n(head):
    robot, setup, names, pool, test = head
    info = candidate_information(robot, setup, pool, names, None)
    A = held_out(robot, setup, test, names, None, info).of("position")
    _, values = greedy(info, A, 40)
    target = float(np.sqrt(values[24]))  # reached by the 25th greedy pick
    plan = plan_configurations(
        robot, setup, pool, 1, joint_names=names, test_qs=test, target_m=target * (1 + 1e-9)
    )
    assert len(plan.qs) == 25 and plan.rms("position") <= target * (1 + 1e-6)


_BOX = '<collision><origin xyz="{} 0 0"/><geometry><box size="{}"/></geometry></collision>'
_JOINT = (
    '<joint name="{}" type="revolute"><parent link="{}"/><child link="{}"/>'
    '<origin xyz="{} 0 0"/><axis xyz="0 0 1"/>'
    '<limit lower="-3" upper="3" effort="1" velocity="1"/></joint>'
)
FOLDING_ARM = (
    '<?xml version="1.0"?><robot name="fold">'
    f'<link name="base">{_BOX.format(0.15, "0.3 0.1 0.1")}</link>'
    f'<link name="l1">{_BOX.format(0.25, "0.5 0.05 0.05")}</link>'
    f'<link name="l2">{_BOX.format(0.25, "0.5 0.05 0.05")}</link>'
    + _JOINT.format("j1", "base", "l1", 0.3)
    + _JOINT.format("j2", "l1", "l2", 0.5)
    + "</robot>"
)


@pytest.mark.slow
def test_self_collision_by_hand_geometry():
    """A planar 2-link arm on a base box (x in [0, 0.3] m, |y| <= 0.05 m): links touching
    at their joint are not collisions; the second link folded back onto the base is. By
    hand: q = (1.5, 2.9) puts l2's tip at (0.18, 0.03) m, inside the base box; the others
    keep l2 clear of it (its tip at x = 0.315 m for q = (0, 2.9))."""
    from kinfw.identification.planning import collision_free
    from kinfw.model import Robot

    robot = Robot(FOLDING_ARM)
    qs = np.array([[0.0, 0.0], [2.9, 0.0], [0.0, 2.9], [1.5, 2.9], [-1.5, -2.9]])
    free = collision_free(robot, qs, ("j1", "j2"))
    assert free.tolist() == [True, True, True, False, False]
    tip = np.array(
        [0.3 + 0.5 * np.cos(1.5) + 0.5 * np.cos(4.4), 0.5 * np.sin(1.5) + 0.5 * np.sin(4.4)]
    )
    assert 0.0 < tip[0] < 0.3 and abs(tip[1]) < 0.05  # the hand check of the docstring
