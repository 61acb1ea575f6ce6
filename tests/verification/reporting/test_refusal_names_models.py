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
from kinfw.model import PriorScale, PriorScales, load_robot
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
        models = re.findall(r"--params (\w+)((?: --prior[^(]*?)?) \(([\d.]+)\)", listed)
        assert len(models) >= 3  # frames, offsets, full under the chosen prior by group
        scores = [float(m[2]) for m in models]
        assert scores == sorted(scores)
        auto = calibrate_and_report(nominal, data)
        first = models[0]
        assert first[0] == auto.model.parameters[0]
        assert (first[1] == "") == (auto.model.prior is None)
        for name, options, _ in models:
            fitted = calibrate_and_report(nominal, data, parameters=name, prior=_prior(options))
            assert fitted.calibration.refined is not None


def _prior(options: str) -> PriorScales | None:
    """The prior of ``--prior-mm A --prior-deg B`` and ``--prior GROUP=VALUE`` options."""
    uniform = re.search(r"--prior-mm ([\d.e-]+) --prior-deg ([\d.e-]+)", options)
    prior = PriorScales()
    if uniform:
        prior = PriorScales.uniform(float(uniform[1]) * 1e-3, np.radians(float(uniform[2])))
    groups = [PriorScale.parse(t) for t in re.findall(r"--prior (\S+)", options)]
    prior = prior.with_sigmas({(g.group, g.unit): g.sigma for g in groups}, "given")
    return prior if prior.scales else None
