"""How good is a model: its errors against measurements (:func:`evaluate_model`, what
``kinfw verify`` reports), k-fold cross-validation of the whole pipeline, closed-form
leave-one-out predictions, the default model choice, the Cramér-Rao bound, the
CPC-vs-Pinocchio cross-check, and the trial runner (in this process, a process pool or
on a Dask scheduler's workers).
"""

from __future__ import annotations

from kinfw.verification.evaluation._accuracy import (
    AccuracyReport,
    GroupErrors,
    evaluate_model,
    known_frames,
)
from kinfw.verification.evaluation._crlb import (
    CRLB,
    NORMAL_COVERAGE,
    cramer_rao,
    position_jacobians,
    predicted_position_ms,
    predicted_position_rms,
    true_chart_coordinates,
)
from kinfw.verification.evaluation._crosscheck import (
    CrossCheck,
    crosscheck_cpc,
    pose_discrepancy,
    random_joint_values,
)
from kinfw.verification.evaluation._crossval import (
    AUTO,
    BASELINES,
    CrossValidation,
    FoldScore,
    crossvalidate,
    fitted_unknowns,
    held_out_errors,
    rejected_keys,
    whitening_noise,
    without_observations,
)
from kinfw.verification.evaluation._loo import (
    LeaveOneOut,
    leave_one_out,
)
from kinfw.verification.evaluation._model_choice import (
    ROWS_PER_PARAMETER,
    VIEW_ROWS,
    Candidate,
    ModelChoice,
    choose_parameters,
    missing_compliance,
    rows_per_parameter,
)
from kinfw.verification.evaluation._reprojection import (
    reprojection_section,
)
from kinfw.verification.evaluation._trials import (
    check_count,
    open_executor,
    run_trials,
)

__all__ = [
    "AUTO",
    "BASELINES",
    "CRLB",
    "NORMAL_COVERAGE",
    "ROWS_PER_PARAMETER",
    "VIEW_ROWS",
    "AccuracyReport",
    "Candidate",
    "CrossCheck",
    "CrossValidation",
    "FoldScore",
    "GroupErrors",
    "LeaveOneOut",
    "ModelChoice",
    "check_count",
    "choose_parameters",
    "cramer_rao",
    "crosscheck_cpc",
    "crossvalidate",
    "evaluate_model",
    "fitted_unknowns",
    "held_out_errors",
    "known_frames",
    "leave_one_out",
    "missing_compliance",
    "open_executor",
    "pose_discrepancy",
    "position_jacobians",
    "predicted_position_ms",
    "predicted_position_rms",
    "random_joint_values",
    "rejected_keys",
    "reprojection_section",
    "rows_per_parameter",
    "run_trials",
    "true_chart_coordinates",
    "whitening_noise",
    "without_observations",
]
