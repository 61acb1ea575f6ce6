"""The estimation problem: parameter blocks, residual groups, solver, noise, diagnostics.

- :mod:`.build`: :func:`build_problem` assembles a :class:`LeastSquaresProblem` from a
  robot and measurements, looping over the observation kinds of :mod:`kinfw.observations`
  and the parameter blocks of :mod:`kinfw.blocks`;
- :mod:`.problem`: the problem's data classes (:class:`LeastSquaresProblem`,
  :class:`ResidualGroup`, :class:`Unknown`);
- :mod:`.start`: the start values, in closed form (the kinds' estimators);
- :mod:`.functions`: the CasADi residual functions, cached by structure;
- :mod:`.gauge`: which robot parameters are free;
- :mod:`.solver`: Levenberg-Marquardt with robust losses (IRLS);
- :mod:`.noise`: :class:`NoiseModel` and variance-component estimation;
- :mod:`.diagnostics`: covariance, identifiability, per-group residuals.

:func:`identification.refine.refine` orchestrates them.
"""

from .build import build_problem
from .diagnostics import (
    GroupResiduals,
    Identifiability,
    covariance_and_identifiability,
    group_residuals,
)
from .functions import GroupFunctions, clear_function_cache
from .noise import NoiseModel, NoiseShape, estimate_noise, noise_shape
from .problem import PRIOR, LeastSquaresProblem, ResidualGroup, Unknown
from .solver import (
    LOSSES,
    levenberg_marquardt,
    negligible_columns,
    observation_norms,
    row_weights,
    thresholds,
)
from .start import estimate_unknowns, express_in

__all__ = [
    "LOSSES",
    "PRIOR",
    "GroupFunctions",
    "GroupResiduals",
    "Identifiability",
    "LeastSquaresProblem",
    "NoiseModel",
    "NoiseShape",
    "ResidualGroup",
    "Unknown",
    "build_problem",
    "clear_function_cache",
    "covariance_and_identifiability",
    "estimate_noise",
    "estimate_unknowns",
    "express_in",
    "group_residuals",
    "levenberg_marquardt",
    "negligible_columns",
    "noise_shape",
    "observation_norms",
    "row_weights",
    "thresholds",
]
