"""The model choice tells kinfw.progress a step per candidate; piped, the fits inside a
candidate (their stages and iterations) are not lines of their own."""

import io

import numpy as np
import pytest

from kinfw.model import load_robot
from kinfw.progress import LineReporter, reporting
from kinfw.simulation import perturb_robot
from kinfw.verification.evaluation import choose_parameters
from tests.head_data import plate_data
from tests.paths import HEAD_URDF
from tests.recorder import Recorder


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
    assert n == 11 and lines == [
        *(f"model choice: {i}/{n} candidates" for i in range(1, n + 1)),
        "model choice: the candidates' leave-one-out scores",
    ]


@pytest.mark.slow
def test_each_candidate_fit_is_a_loop_inside_the_model_choice(few_plates):
    recorder = Recorder()
    with reporting(recorder):
        choice = choose_parameters(*few_plates)
    outer = [t for t in recorder.tasks if t.depth == 0]
    assert [(t.name, t.total) for t in outer] == [("model choice", len(choice.candidates))]
    inner = [t for t in recorder.tasks if t.depth > 0]
    assert inner and {t.name for t in inner} == {"Levenberg-Marquardt"}
    # the candidates' own stages are inside the loop
    assert recorder.stages == ["model choice: the candidates' leave-one-out scores"]
