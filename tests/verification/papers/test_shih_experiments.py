"""Tests of kinfw.verification.papers: Shih et al. (1992) Fig. 11 and Table 4."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from kinfw.identification import identify_closed_form
from kinfw.measurements import Measurements
from kinfw.model import load_robot
from kinfw.observations import PoseObservations
from kinfw.simulation import one_joint_at_a_time, perturb_robot, random_configurations
from kinfw.verification.papers import (
    PAPER_TABLE4_MU_MM,
    PAPER_TABLE4_SIGMA_MM,
    Fig11Result,
    Table4Result,
    fig11_study,
    format_fig11,
    format_table4,
    plot_fig11,
    plot_table4,
    run_fig11,
    run_table4,
    table4_study,
)
from kinfw.verification.papers._shih_figures import shih_figures_main as main
from tests.paths import HEAD_URDF as IIS_HEAD

FRAMES = ("left_plate", "right_plate")


@pytest.fixture(scope="module")
def head():
    return load_robot(IIS_HEAD)


@pytest.fixture(scope="module")
def tiny(head):
    """A small Fig. 11 study: M in (3, 9, 12), two noise levels, four trials."""
    return fig11_study(head, per_joint=(3, 9, 12), sigmas_mm=(0.1, 0.5), trials=4, n_test=100)


@pytest.fixture(scope="module")
def small_table4(head):
    return table4_study(head, sigma_mm=0.05, trials=20)


# -- Fig. 11 -----------------------------------------------------------------------------


def test_noise_free_closed_form_recovers_the_truth_for_every_m(head):
    result = fig11_study(head, per_joint=range(2, 16), sigmas_mm=(0.0,), trials=2, n_test=50)
    assert result.errors_mm.shape == (1, 14, 2, 2)
    assert np.all(result.errors_mm < 1e-6)


def test_noise_free_identification_matches_pinocchio_fk_of_the_true_urdf(head):
    # Independent truth: Pinocchio FK of a perturbed URDF, data built here, not by the study.
    truth = load_robot(
        perturb_robot(head, np.random.default_rng(7), origin_mm=5.0, origin_deg=1.0, axis_deg=1.0)
    )
    names = head.topology(FRAMES).joint_names
    lower, upper = head.joint_limits(names)
    qs, _ = one_joint_at_a_time(lower, upper, per_joint=3, fraction=0.8)
    sample = np.arange(len(qs))
    data = Measurements(
        joint_names=names,
        qs=qs,
        poses=tuple(
            PoseObservations(frame=f, sample=sample, meas_T_frame=truth.frame_poses(qs, f, names))
            for f in FRAMES
        ),
    )
    model = identify_closed_form(head, data).model
    test_qs = random_configurations(lower, upper, 30, np.random.default_rng(1), fraction=0.8)
    for f in FRAMES:
        np.testing.assert_allclose(
            model.frame_poses(test_qs, f), truth.frame_poses(test_qs, f, names), atol=1e-10
        )


def test_error_decreases_with_m_and_grows_with_sigma(tiny):
    mean = tiny.mean_mm  # (sigma, M)
    assert np.all(mean[:, 0] > mean[:, -1])  # M = 3 worse than M = 12
    assert np.all(mean[1] > mean[0])  # sigma 0.5 mm worse than 0.1 mm, every M
    assert np.all(tiny.std_mm > 0.0)


def test_paper_requirement_met_at_half_a_millimetre_and_nine_per_joint(tiny):
    s = int(np.flatnonzero(tiny.sigmas_mm == 0.5)[0])
    k = int(np.flatnonzero(tiny.per_joint == 9)[0])
    assert tiny.mean_mm[s, k] < 1.0


def test_rotation_noise_is_tied_to_position_noise(tiny):
    np.testing.assert_allclose(tiny.sigmas_rad, [0.002, 0.01], atol=1e-15)
    assert tiny.to_dict()["sigmas_rad"] == pytest.approx([0.002, 0.01], abs=1e-15)


def test_a_cell_does_not_depend_on_the_other_cells(head, tiny):
    one = fig11_study(head, per_joint=(9,), sigmas_mm=(0.5,), trials=4, n_test=100)
    np.testing.assert_array_equal(one.errors_mm[0, 0], tiny.errors_mm[1, 1])


def test_progress_steps_once_per_trial(head):
    """The study's trials are one task of kinfw.progress, a step per trial (4 cells x
    trials); nothing inside a trial is a stage of its own."""
    from kinfw.progress import reporting
    from tests.recorder import Recorder

    recorder = Recorder()
    with reporting(recorder):
        fig11_study(head, per_joint=(2, 3), sigmas_mm=(0.5,), trials=2, n_test=5)
    trials = [t for t in recorder.tasks if t.depth == 0]
    assert [(t.name, t.total) for t in trials] == [("trials", 4)]
    assert [done for done, _ in trials[0].steps] == [1, 2, 3, 4] and trials[0].closed
    assert recorder.stages == []


def test_smallest_per_joint_meeting_a_requirement(tiny):
    assert np.all(tiny.smallest_per_joint(1e3) == 3)
    assert np.all(np.isnan(tiny.smallest_per_joint(0.0)))


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"per_joint": (0,)}, "per_joint"),
        ({"per_joint": ()}, "per_joint"),
        ({"sigmas_mm": (-0.1,)}, "sigmas_mm"),
        ({"trials": 0}, "trials"),
        ({"n_test": 0}, "n_test"),
        ({"fraction": 1.5}, "fraction"),
        ({"error_mm": float("nan")}, "error_mm"),
    ],
)
def test_fig11_rejects_bad_arguments(head, kwargs, match):
    with pytest.raises(ValueError, match=match):
        fig11_study(head, **{"per_joint": (2,), "trials": 1, "n_test": 2, **kwargs})


# -- Table 4 -----------------------------------------------------------------------------


def test_table4_against_noisy_measurements_is_bounded_by_the_noise_floor(small_table4):
    r = small_table4
    floor = 0.05 * np.sqrt(2.0 / np.pi)
    assert r.error_vs_measured_mm.shape == (20, 9, 2, 3)
    assert np.all(r.measured_mu_mm >= 0.8 * floor)
    assert np.all(r.truth_mu_mm < r.measured_mu_mm)
    assert np.all(r.measured_sigma_mm > 0.0)


def test_table4_noise_free_errors_vanish(head):
    r = table4_study(head, sigma_mm=0.0, trials=2)
    assert np.abs(r.error_vs_measured_mm).max() < 1e-6
    assert np.abs(r.error_vs_truth_mm).max() < 1e-6


def test_table4_rejects_bad_arguments(head):
    with pytest.raises(ValueError, match="sigma_mm"):
        table4_study(head, sigma_mm=-1.0, trials=1)
    with pytest.raises(ValueError, match="per_joint"):
        table4_study(head, per_joint=0, trials=1)


def test_format_table4_shows_the_paper_beside_ours(small_table4):
    text = format_table4(small_table4)
    assert "| left_plate | x | 0.65 | 0.24 |" in text
    assert "| right_plate | z | 0.11 | 0.35 |" in text
    assert len([ln for ln in text.splitlines() if ln.startswith("| ")]) == 1 + 6
    assert PAPER_TABLE4_MU_MM.shape == PAPER_TABLE4_SIGMA_MM.shape == (2, 3)


def test_format_fig11_has_one_row_per_m(tiny):
    text = format_fig11(tiny)
    rows = [ln for ln in text.splitlines() if ln.startswith("| ")]
    assert len(rows) == 1 + 3
    assert "σ = 0.5 mm (0.57°)" in rows[0]
    assert "9 (paper's choice)" in text


# -- JSON and plots --------------------------------------------------------------------


def test_fig11_json_round_trip(tiny):
    doc = json.loads(json.dumps(tiny.to_dict()))
    back = Fig11Result.from_dict(doc)
    np.testing.assert_array_equal(back.errors_mm, tiny.errors_mm)
    np.testing.assert_array_equal(back.per_joint, tiny.per_joint)
    np.testing.assert_array_equal(back.sigmas_mm, tiny.sigmas_mm)
    assert back.setup == tiny.setup
    assert back.to_dict() == doc


def test_table4_json_round_trip(small_table4):
    doc = json.loads(json.dumps(small_table4.to_dict()))
    back = Table4Result.from_dict(doc)
    np.testing.assert_array_equal(back.error_vs_measured_mm, small_table4.error_vs_measured_mm)
    np.testing.assert_array_equal(back.error_vs_truth_mm, small_table4.error_vs_truth_mm)
    assert back.setup == small_table4.setup
    assert back.to_dict() == doc
    assert doc["summary"]["left_plate"]["paper_mu_mm"] == [0.65, 0.23, 0.35]


def _is_png(path: Path) -> bool:
    return path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_plots_are_written(tiny, small_table4, tmp_path):
    for path in (
        plot_fig11(tiny, tmp_path / "f.png"),
        plot_table4(small_table4, tmp_path / "t.png"),
    ):
        assert _is_png(path)
        assert path.stat().st_size > 20_000


@pytest.mark.slow
def test_run_writes_png_and_json(tmp_path):
    r = run_fig11(tmp_path, per_joint=(2, 3), sigmas_mm=(0.5,), trials=2, n_test=10)
    assert _is_png(tmp_path / "fig11.png")
    assert Fig11Result.from_dict(json.loads((tmp_path / "fig11.json").read_text())).n_test == 10
    assert r.setup.frames == FRAMES
    t = run_table4(tmp_path, trials=2)
    assert _is_png(tmp_path / "table4.png")
    assert json.loads((tmp_path / "table4.json").read_text())["trials"] == t.trials == 2


@pytest.mark.slow
def test_main_prints_the_table(tmp_path, capsys):
    assert main(["table4", "--out", str(tmp_path), "--trials", "2", "--seed", "3"]) == 0
    out = capsys.readouterr().out
    assert "| left_plate | x | 0.65 | 0.24 |" in out
    assert (tmp_path / "table4.png").is_file()
    assert json.loads((tmp_path / "table4.json").read_text())["setup"]["seed"] == 3
