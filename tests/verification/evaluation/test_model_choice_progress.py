"""The model choice tells kinfw.progress a step per candidate fit and a step per
candidate's leave-one-out score; piped, the fits inside a candidate (their stages and
iterations) are not lines of their own."""

import io

import numpy as np
import pytest

from kinfw.model import load_robot
from kinfw.progress import LineReporter, reporting
from kinfw.simulation import perturb_robot, random_configurations, simulate_at
from kinfw.verification.evaluation import choose_parameters
from tests.head_data import plate_data
from tests.paths import HEAD_URDF
from tests.recorder import Recorder
from tests.robots import PLANAR_2R


@pytest.fixture(scope="module")
def few_plates():
    nominal = load_robot(HEAD_URDF)
    truth = load_robot(perturb_robot(nominal, np.random.default_rng(2), origin_mm=2.0))
    return nominal, plate_data(truth, 8, 3)  # few samples: the choice scores candidates


@pytest.mark.slow
def test_piped_model_choice_is_a_line_per_candidate(few_plates):
    out = io.StringIO()
    with reporting(LineReporter(out)):
        choice = choose_parameters(*few_plates)
    lines = [line.split(" s  ", 1)[1] for line in out.getvalue().splitlines()]
    n = len(choice.candidates)
    assert n == 4 and lines == [
        *(f"model choice: {i}/{n} candidates" for i in range(1, n + 1)),
        *(f"model choice: leave-one-out scores: {i}/{n} candidates" for i in range(1, n + 1)),
    ]


@pytest.mark.slow
def test_each_candidate_fit_is_a_loop_inside_the_model_choice(few_plates):
    recorder = Recorder()
    with reporting(recorder):
        choice = choose_parameters(*few_plates)
    n = len(choice.candidates)
    outer = [t for t in recorder.tasks if t.depth == 0]
    assert [(t.name, t.total) for t in outer] == [
        ("model choice", n),
        ("model choice: leave-one-out scores", n),
    ]
    assert [done for done, _ in outer[1].steps] == list(range(1, n + 1)) and outer[1].closed
    inner = [t for t in recorder.tasks if t.depth > 0]
    assert inner and {t.name for t in inner} == {"Levenberg-Marquardt"}
    # the candidates' own stages are inside the loops
    assert recorder.stages == []


def test_the_leave_one_out_scores_are_a_step_per_candidate():
    """A planar 2R arm's 8 noisy tool poses (few: the candidates are scored): after the
    fits, the scoring is a loop of its own, a step per candidate, in the order fitted."""
    nominal = load_robot(PLANAR_2R)
    truth = load_robot(perturb_robot(nominal, np.random.default_rng(2), origin_mm=2.0))
    rng = np.random.default_rng(3)
    names = nominal.topology(("tool",)).joint_names
    qs = random_configurations(*nominal.joint_limits(names), 8, rng, fraction=0.8)
    data = simulate_at(truth, qs, names, frames=["tool"], rng=rng, noise_m=5e-4, noise_rad=5e-3)
    recorder = Recorder()
    with reporting(recorder):
        choice = choose_parameters(nominal, data)
    n = len(choice.candidates)
    fits, scores = (t for t in recorder.tasks if t.depth == 0)
    assert (fits.name, fits.total) == ("model choice", n)
    assert (scores.name, scores.total, scores.unit) == (
        "model choice: leave-one-out scores",
        n,
        "candidates",
    )
    assert [done for done, _ in scores.steps] == list(range(1, n + 1)) and scores.closed
    assert recorder.tasks.index(scores) > recorder.tasks.index(fits)
    assert all(np.isfinite(c.whitened) or c.failed for c in choice.candidates)
