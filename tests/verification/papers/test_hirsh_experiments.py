"""Tests of kinfw.verification.papers: Hirsh, DeSouza & Kak (2001) Figs. 3 and 4."""

from __future__ import annotations

import json
import logging

import numpy as np
import pinocchio as pin
import pytest

from kinfw.identification.handeye import AXYBError, solve_axyb
from kinfw.verification.papers import (
    CONVERGED_DEG,
    HirshResult,
    format_hirsh,
    hirsh_study,
    load_hirsh,
    plot_hirsh,
    quaternion_angle,
    random_problem,
    rotate_about_random_axes,
    rotations_about_random_axes,
    run_hirsh,
)
from kinfw.verification.papers import _hirsh_experiments as hirsh_experiments
from kinfw.verification.papers._hirsh_figures import hirsh_figures_main as main

VIEWS = (3, 5, 10)


@pytest.fixture(autouse=True)
def _quiet_solver(caplog):
    # Slow trials end unconverged at the solver's cap by design; its warning is expected.
    caplog.set_level(logging.ERROR, logger="kinfw.identification.handeye")


@pytest.fixture(scope="module")
def noise_free():
    # 300 recorded iterations: 3 random views shrink the error by ~0.8 per iteration
    # (median), so 100 are not always enough for 1e-6 deg in a small sample.
    return hirsh_study(views=VIEWS, noise_deg=0.0, trials=20, iterations=300, seed=1)


@pytest.fixture(scope="module")
def noisy():
    return hirsh_study(views=VIEWS, noise_deg=1.0, trials=20, iterations=150, seed=1)


def _angle_deg(R_a, R_b):
    """Independent truth: angle of R_a^T R_b by Pinocchio's log3, degrees."""
    return np.degrees(np.linalg.norm(pin.log3(np.asarray(R_a).T @ np.asarray(R_b))))


# -- noise generator, error measure, simulated problem -----------------------------------


def test_noise_rotations_have_exactly_the_angle_and_isotropic_axes():
    rng = np.random.default_rng(5)
    angle = np.radians(1.0)
    Rs = rotations_about_random_axes(rng, 20000, angle)
    logs = np.array([pin.log3(R) for R in Rs])
    np.testing.assert_allclose(np.linalg.norm(logs, axis=1), angle, rtol=0, atol=1e-13)
    axes = logs / angle
    # isotropic: mean ~ 0 (std of each component ~ 1/sqrt(3 * 20000) = 0.004) and
    # second moment ~ I / 3
    assert np.all(np.abs(axes.mean(axis=0)) < 0.02)
    np.testing.assert_allclose(axes.T @ axes / len(axes), np.eye(3) / 3.0, atol=0.02)


def test_noise_is_applied_to_the_rotation_only_each_pose_off_by_the_angle():
    rng = np.random.default_rng(6)
    _, _, _, A = random_problem(rng, 50)
    noisy = rotate_about_random_axes(A, rng, np.radians(1.0))
    np.testing.assert_array_equal(noisy[:, :3, 3], A[:, :3, 3])
    np.testing.assert_array_equal(noisy[:, 3], A[:, 3])
    angles = [_angle_deg(a[:3, :3], b[:3, :3]) for a, b in zip(A, noisy, strict=True)]
    np.testing.assert_allclose(angles, 1.0, atol=1e-10)


def test_noise_angle_is_checked():
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="angle_rad"):
        rotations_about_random_axes(rng, 3, -0.1)
    with pytest.raises(ValueError, match="a_T_bs"):
        rotate_about_random_axes(np.eye(4), rng, 0.1)


def test_quaternion_angle_is_the_rotation_angle_and_accurate_near_zero():
    rng = np.random.default_rng(7)
    Rs = rotations_about_random_axes(rng, 200, 1.0) @ rotations_about_random_axes(rng, 200, 2.5)
    R_true = pin.exp3(np.array([0.3, -1.2, 0.4]))
    expected = [_angle_deg(R_true, R) for R in Rs]
    # (both lose ~1e-10 deg close to 180 deg)
    np.testing.assert_allclose(
        np.degrees(quaternion_angle(Rs, R_true)), expected, rtol=0, atol=1e-9
    )
    # the paper's form: 2 acos(|<q, q_true>|), quaternions from Pinocchio
    q_true = pin.Quaternion(R_true).coeffs()
    dots = np.abs([pin.Quaternion(R).coeffs() @ q_true for R in Rs])
    np.testing.assert_allclose(quaternion_angle(Rs, R_true), 2.0 * np.arccos(dots), atol=1e-7)
    # where acos fails: tiny angles (the dot product rounds to 1 below ~1e-8 rad)
    for tiny in (1e-9, 1e-12):
        R = R_true @ pin.exp3(np.array([0.0, tiny, 0.0]))
        np.testing.assert_allclose(quaternion_angle(R, R_true), tiny, rtol=1e-3)
    assert quaternion_angle(R_true, R_true) == 0.0


def test_random_problem_follows_a_equals_x_b_y_with_hand_rotations_in_range():
    rng = np.random.default_rng(8)
    X, Y, B, A = random_problem(rng, 40, hand_rotation_deg=90.0, hand_translation_m=0.5)
    for a, b in zip(A, B, strict=True):
        np.testing.assert_allclose(a, X @ b @ Y, atol=1e-12)
    hand_poses = np.linalg.inv(B)  # b_T_e
    angles = [np.degrees(np.linalg.norm(pin.log3(T[:3, :3]))) for T in hand_poses]
    assert max(angles) <= 90.0 + 1e-9
    assert max(angles) > 60.0  # spread up to the limit
    assert np.all(np.abs(hand_poses[:, :3, 3]) <= 0.5)
    for T in (X, Y, *B):
        np.testing.assert_allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), atol=1e-12)


def test_random_problem_checks_its_arguments():
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="views"):
        random_problem(rng, 2)
    with pytest.raises(ValueError, match="hand_rotation_deg"):
        random_problem(rng, 3, hand_rotation_deg=200.0)
    with pytest.raises(ValueError, match="noise_deg"):
        hirsh_study(noise_deg=-1.0, trials=1)
    with pytest.raises(ValueError, match="views"):
        hirsh_study(views=(2,), trials=1)


# -- the study ---------------------------------------------------------------------------


def test_study_records_the_solver_history_against_the_truth():
    # Rebuild trial 2 of 5 views at 1 deg from the documented seed and draw order, solve
    # it here, and measure the errors with Pinocchio.
    result = hirsh_study(views=(5,), noise_deg=1.0, trials=3, iterations=40, seed=4)
    rng = np.random.default_rng([4, 1_000_000, 5, 2])
    X, Y, B, A = random_problem(rng, 5)
    A = rotate_about_random_axes(A, rng, np.radians(1.0))
    res = solve_axyb(
        camera_T_targets=A,
        hand_T_bases=B,
        base_T_target_guess=np.eye(4),
        refine=False,
        record_history=True,
        rng=rng,
    )
    k = min(40, len(res.base_T_target_history))
    y_err = [_angle_deg(Y[:3, :3], T[:3, :3]) for T in res.base_T_target_history[:k]]
    x_err = [_angle_deg(X[:3, :3], T[:3, :3]) for T in res.camera_T_hand_history[:k]]
    np.testing.assert_allclose(result.y_error_deg[0, 2, :k], y_err, atol=1e-9)
    np.testing.assert_allclose(result.x_error_deg[0, 2, :k], x_err, atol=1e-9)
    np.testing.assert_allclose(result.initial_y_error_deg[0, 2], _angle_deg(np.eye(3), Y[:3, :3]))
    np.testing.assert_allclose(
        result.solved_y_error_deg[0, 2], _angle_deg(Y[:3, :3], res.base_T_target[:3, :3])
    )


@pytest.mark.slow
def test_noise_free_error_falls_below_1e_6_deg_for_every_view_count(noise_free):
    assert noise_free.y_error_deg.shape == (3, 20, 300)
    assert np.all(noise_free.y_median_deg[:, -1] < CONVERGED_DEG)
    assert not noise_free.failed.any()


@pytest.mark.slow
def test_noise_free_median_error_never_increases(noise_free):
    median = noise_free.y_median_deg  # (V, K + 1), iteration 0 = identity guess
    assert np.all(np.diff(median[:, 1:], axis=1) <= 1e-12 * median[:, 1:-1])
    assert np.all(median[:, -1] < 1e-6 * median[:, 1])


@pytest.mark.slow
def test_runs_that_stop_early_repeat_their_last_value(noise_free):
    its = noise_free.iterations_to_reach(1e-9)
    v, t = np.argwhere(its < 100)[0]  # an early one
    tail = noise_free.y_error_deg[v, t, 150:]
    assert np.all(tail == tail[-1])


@pytest.mark.slow
def test_shrink_factor_is_the_observed_ratio_of_successive_errors(noise_free):
    # Independent of N: the solver's own iterates. The paper's error s-component grows as
    # tan(error / 2) shrinks by (sigma_2 / sigma_1)^2 once the slower modes have died out.
    tan_half = np.tan(np.radians(noise_free.y_error_deg) / 2.0)
    rel = []
    for v, t in np.ndindex(tan_half.shape[:2]):
        deg = noise_free.y_error_deg[v, t, :-1]
        mid = np.flatnonzero((deg < 1e-3) & (deg > 1e-8))
        if mid.size:
            k = mid[len(mid) // 2]
            ratio = tan_half[v, t, k + 1] / tan_half[v, t, k]
            rel.append(abs(ratio / noise_free.convergence_factors[v, t] - 1.0))
    assert len(rel) > 30
    assert np.median(rel) < 1e-3
    assert max(rel) < 0.15


@pytest.mark.slow
def test_more_views_converge_faster(noise_free):
    its = noise_free.median_iterations_to_reach(CONVERGED_DEG)  # views 3, 5, 10
    assert its[0] > its[1] > its[2]
    assert np.all(np.diff(np.median(noise_free.convergence_factors, axis=1)) < 0)


@pytest.mark.slow
def test_noisy_error_ends_below_the_noise_line_for_10_views_and_below_3_views(noisy):
    final = noisy.y_median_deg[:, -1]
    assert final[2] < noisy.noise_deg
    assert final[2] < final[0]
    assert np.all(final > 0.05)  # noise does not vanish: a floor well above rounding


def test_a_failing_solve_is_recorded_not_raised(monkeypatch):
    calls = []

    def flaky(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise AXYBError("no consistent X, Y")
        return solve_axyb(*args, **kwargs)

    monkeypatch.setattr(hirsh_experiments, "solve_axyb", flaky)
    result = hirsh_study(views=(4,), trials=3, iterations=10)
    assert result.failed.tolist() == [[False, True, False]]
    assert np.isnan(result.y_error_deg[0, 1]).all()
    assert np.isfinite(result.y_median_deg).all()
    assert "failed in 1 of 3 trials" in format_hirsh(result, result)


# -- outputs -----------------------------------------------------------------------------


@pytest.mark.slow
def test_json_round_trip(noise_free, noisy, tmp_path):
    for result in (noise_free, noisy):
        doc = json.loads(json.dumps(result.to_dict(), allow_nan=False))
        back = HirshResult.from_dict(doc)
        for field in HirshResult.__slots__:
            a, b = getattr(result, field), getattr(back, field)
            if isinstance(a, np.ndarray):
                assert a.dtype.kind == b.dtype.kind, field
                np.testing.assert_array_equal(a, b, err_msg=field)
            else:
                assert a == b, field


@pytest.mark.slow
def test_format_reports_the_papers_claims(noise_free, noisy):
    text = format_hirsh(noise_free, noisy)
    for claim in (
        "converges very quickly",
        "improves the speed of convergence",
        "any initial guess",
        "below the noise line",
    ):
        assert claim in text
    assert "| 10 |" in text


@pytest.mark.slow
def test_plot_writes_a_png(noise_free, noisy, tmp_path):
    path = plot_hirsh(noise_free, noisy, tmp_path / "fig.png")
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(data) > 30_000


@pytest.mark.slow
def test_run_and_main_write_png_and_json(tmp_path, capsys):
    _, noisy = run_hirsh(tmp_path / "a", trials=2, iterations=15, views=(3, 6))
    assert (tmp_path / "a" / "hirsh_fig3_fig4.png").stat().st_size > 30_000
    back_free, back_noisy = load_hirsh(tmp_path / "a" / "hirsh.json")
    np.testing.assert_array_equal(back_noisy.y_error_deg, noisy.y_error_deg)
    assert back_free.noise_deg == 0.0 and back_noisy.noise_deg == 1.0

    assert (
        main(["--out", str(tmp_path / "b"), "--trials", "2", "--seed", "3", "--iterations", "12"])
        == 0
    )
    out = capsys.readouterr().out
    assert "Fig. 3" in out and "Fig. 4" in out and "hirsh_fig3_fig4.png" in out
    doc = json.loads((tmp_path / "b" / "hirsh.json").read_text())
    assert doc["noise_free"]["trials"] == 2 and doc["noisy"]["seed"] == 3
    assert len(doc["noisy"]["y_error_deg"][0][0]) == 12
