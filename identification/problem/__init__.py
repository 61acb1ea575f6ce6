"""The estimation problem: parameter blocks, residual groups, solver, noise, diagnostics.

- :mod:`.build`: :func:`build_problem` assembles a :class:`LeastSquaresProblem` from a
  robot and measurements, looping over the observation kinds of :mod:`kinfw.observations`
  and the parameter blocks of :mod:`kinfw.model`;
- :mod:`.problem`: the problem's data classes (:class:`LeastSquaresProblem`,
  :class:`ResidualGroup`, :class:`Unknown`);
- :mod:`.start`: the start values, in closed form (the kinds' estimators);
- :mod:`.functions`: the CasADi residual functions, cached by structure;
- :mod:`.gauge`: which robot parameters are free;
- :mod:`.solver`: Levenberg-Marquardt with robust losses (IRLS);
- :mod:`.noise`: :class:`NoiseModel` and variance-component estimation;
- :mod:`.diagnostics`: covariance, identifiability, per-group residuals;
- :mod:`.refine`: :func:`refine` orchestrates them into a :class:`RefineResult`
  (:mod:`.refine_result`).

:func:`refine`, :class:`RefineResult`, :data:`REJECT_Z` and :func:`information_matrix`
are imported here for :mod:`kinfw.identification`, their one public import path
(``from kinfw.identification import refine``), and are not in this face's ``__all__``
(imported with redundant aliases, ``refine as refine``, the marker of a re-export).
"""

from kinfw.identification.problem._build import build_problem
from kinfw.identification.problem._diagnostics import (
    WORLD_MOTION,
    GroupResiduals,
    Identifiability,
    RejectedObservation,
    covariance_and_identifiability,
    group_residuals,
    rejected_observations,
)
from kinfw.identification.problem._functions import (
    MAP_CHUNK,
    GroupFunctions,
    build_functions,
    clear_function_cache,
    group_functions,
)
from kinfw.identification.problem._gauge import STRUCTURAL_RANK_TOL, relative_gauge, robot_blocks
from kinfw.identification.problem._noise import (
    NoiseModel,
    NoiseShape,
    chi2_cdf,
    estimate_noise,
    noise_shape,
    norm2_cdf,
    quantile,
)
from kinfw.identification.problem._prior_choice import (
    SEARCH_SPAN,
    LinearisedFit,
    LinearLeaveOneOut,
    choose_prior,
    linearised_fit,
)
from kinfw.identification.problem._problem import (
    PRIOR,
    LeastSquaresProblem,
    NormalEquations,
    ResidualGroup,
    Unknown,
)

# for kinfw.identification, their one public path (redundant aliases: re-exported there)
from kinfw.identification.problem._refine import CHOICE_START as CHOICE_START
from kinfw.identification.problem._refine import PRIOR_TIGHTENINGS, UNDETERMINED_LEFT
from kinfw.identification.problem._refine import REJECT_Z as REJECT_Z
from kinfw.identification.problem._refine import information_matrix as information_matrix
from kinfw.identification.problem._refine import refine as refine
from kinfw.identification.problem._refine_result import RefineResult as RefineResult
from kinfw.identification.problem._solver import (
    LOSS_SCALE,
    LOSSES,
    NEGLIGIBLE_COLUMN,
    column_norms,
    levenberg_marquardt,
    leverage_sums,
    leverages,
    negligible_columns,
    normal_equations,
    observation_norms,
    robust_loss,
    row_weights,
    scaled_columns,
    tall_r,
    thresholds,
)
from kinfw.identification.problem._start import (
    MARKER_RANK_TOL,
    estimate_unknowns,
    express_in,
    frame_from_markers,
    start_context,
)

__all__ = [
    "LOSSES",
    "LOSS_SCALE",
    "MAP_CHUNK",
    "MARKER_RANK_TOL",
    "NEGLIGIBLE_COLUMN",
    "PRIOR",
    "PRIOR_TIGHTENINGS",
    "SEARCH_SPAN",
    "STRUCTURAL_RANK_TOL",
    "UNDETERMINED_LEFT",
    "WORLD_MOTION",
    "GroupFunctions",
    "GroupResiduals",
    "Identifiability",
    "LeastSquaresProblem",
    "LinearLeaveOneOut",
    "LinearisedFit",
    "NoiseModel",
    "NoiseShape",
    "NormalEquations",
    "RejectedObservation",
    "ResidualGroup",
    "Unknown",
    "build_functions",
    "build_problem",
    "chi2_cdf",
    "choose_prior",
    "clear_function_cache",
    "column_norms",
    "covariance_and_identifiability",
    "estimate_noise",
    "estimate_unknowns",
    "express_in",
    "frame_from_markers",
    "group_functions",
    "group_residuals",
    "levenberg_marquardt",
    "leverage_sums",
    "leverages",
    "linearised_fit",
    "negligible_columns",
    "noise_shape",
    "norm2_cdf",
    "normal_equations",
    "observation_norms",
    "quantile",
    "rejected_observations",
    "relative_gauge",
    "robot_blocks",
    "robust_loss",
    "row_weights",
    "scaled_columns",
    "start_context",
    "tall_r",
    "thresholds",
]
