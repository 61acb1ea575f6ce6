"""A refused ``--params`` names the models the data do determine, best first.

Four samples of the IIS head's two plates (48 residual rows) cannot determine the full
set's 32 parameters with the noise estimated; the refusal lists the candidates the
model choice could fit and score, best leave-one-out error first. Truth: each listed
model calibrates these data (it is determined), and the first is what ``--params auto``
fits.
"""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest

from kinfw import builtin_head_urdf
from kinfw.identification.checks import InsufficientDataError
from kinfw.model import load_robot
from kinfw.simulation import perturb_robot
from kinfw.verification.reporting import calibrate_and_report
from tests.head_data import plate_data


@pytest.mark.slow
def test_a_refusal_lists_the_determined_models_best_first():
    nominal = load_robot(builtin_head_urdf())
    truth = load_robot(
        perturb_robot(nominal, np.random.default_rng(1), origin_mm=2, origin_deg=0.5)
    )
    data = plate_data(truth, 4, 2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        with pytest.raises(InsufficientDataError, match="too little data") as refused:
            calibrate_and_report(nominal, data, parameters="full")
        listed = str(refused.value).split("best first: ")[1]
        models = re.findall(
            r"--params (\w+)(?: --prior-mm ([\d.]+) --prior-deg ([\d.]+))? \(([\d.]+)\)", listed
        )
        assert len(models) == 4 and "and 6 more" in listed
        scores = [float(m[3]) for m in models]
        assert scores == sorted(scores)
        auto = calibrate_and_report(nominal, data)
        first = models[0]
        assert (first[0], first[1] or None) == (auto.model.parameters[0], None)
        for name, mm, deg, _ in models:
            prior = None if not mm else (float(mm) * 1e-3, np.radians(float(deg)))
            fitted = calibrate_and_report(nominal, data, parameters=name, prior=prior)
            assert fitted.calibration.refined is not None
