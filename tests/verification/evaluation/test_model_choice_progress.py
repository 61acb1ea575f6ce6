"""The model choice tells kinfw.progress a step per candidate; piped, the fits inside a
candidate (its cross-validation, their iterations) are not lines of their own."""

import io

import numpy as np
import pytest

from kinfw.model import load_robot
from kinfw.progress import LineReporter, reporting
from kinfw.simulation import perturb_robot
from kinfw.verification.evaluation import choose_parameters
from tests.head_data import plate_data
from tests.paths import HEAD_URDF


@pytest.mark.slow
def test_piped_model_choice_is_the_full_fit_then_a_line_per_candidate():
    nominal = load_robot(HEAD_URDF)
    truth = load_robot(perturb_robot(nominal, np.random.default_rng(2), origin_mm=2.0))
    data = plate_data(truth, 8, 3)  # few samples: the choice cross-validates
    out = io.StringIO()
    with reporting(LineReporter(out)):
        choice = choose_parameters(nominal, data, k=2)
    lines = [line.split(" s  ", 1)[1] for line in out.getvalue().splitlines()]
    n = len(choice.candidates)
    first = lines.index("model choice: 1/11 candidates")
    assert n == 11 and lines[first:] == [f"model choice: {i}/{n} candidates" for i in range(1, 12)]
    # before the candidates, the full-data fit whose noise whitens their scores
    assert lines[0] == "checking the units" and "refine: start values (8 samples)" in lines
    assert not any(line.startswith("cross-validation fits") for line in lines)
