"""Simulation studies: the demo, the Cramér-Rao and robustness studies on the IIS head,
the pixel study, the value of calibration in use (gaze and reach), and their shared
plumbing (``kinfw reproduce``).
"""

from __future__ import annotations

from kinfw.verification.studies._common import (
    FieldsJSON,
    arrays_from,
    choice_main,
    freeze,
    json_list,
    json_lists,
    log_axes,
    new_figure,
    output_dir,
    plain_log_ticks,
    readonly,
    run_and_print,
    run_on_head,
    sample_std,
    save_figure,
    shared_legend,
    study_parser,
    write_json,
)
from kinfw.verification.studies._crlb_study import (
    CRLBStudy,
    crlb_study,
)
from kinfw.verification.studies._demo import (
    DEMO_FILES,
    N_STAGE2,
    NOISE_DEG,
    NOISE_MM,
    PIXEL_SIGMA,
    DemoResult,
    run_demo,
)
from kinfw.verification.studies._dh_robots import (
    UR10_JOINTS,
    ur10_urdf,
)
from kinfw.verification.studies._gaze_metrics import (
    pointing_errors_rad,
    triangulate,
    triangulation_errors_m,
)
from kinfw.verification.studies._gaze_study import (
    HEAD_DISTANCE_M,
    GazeSetup,
    GazeStudy,
    gaze_study,
    gaze_study_main,
    head_points,
    run_gaze,
)
from kinfw.verification.studies._head_experiment import (
    ExperimentSetup,
)
from kinfw.verification.studies._head_studies import (
    head_studies_main,
    run_crlb,
    run_robustness,
)
from kinfw.verification.studies._head_study_plots import (
    plot_crlb,
    plot_robustness,
)
from kinfw.verification.studies._head_study_tables import (
    format_crlb,
    format_robustness,
)
from kinfw.verification.studies._pixel_study import (
    PixelExperiment,
    arm_experiment,
    camera_target_errors,
    crlb_held_out,
    head_experiment,
    pose_errors,
    pose_path_data,
    rendered_detections,
    target_pose,
)
from kinfw.verification.studies._robust import (
    RobustStudy,
    robustness_study,
)

__all__ = [
    "DEMO_FILES",
    "HEAD_DISTANCE_M",
    "NOISE_DEG",
    "NOISE_MM",
    "N_STAGE2",
    "PIXEL_SIGMA",
    "UR10_JOINTS",
    "CRLBStudy",
    "DemoResult",
    "ExperimentSetup",
    "FieldsJSON",
    "GazeSetup",
    "GazeStudy",
    "PixelExperiment",
    "RobustStudy",
    "arm_experiment",
    "arrays_from",
    "camera_target_errors",
    "choice_main",
    "crlb_held_out",
    "crlb_study",
    "format_crlb",
    "format_robustness",
    "freeze",
    "gaze_study",
    "gaze_study_main",
    "head_experiment",
    "head_points",
    "head_studies_main",
    "json_list",
    "json_lists",
    "log_axes",
    "new_figure",
    "output_dir",
    "plain_log_ticks",
    "plot_crlb",
    "plot_robustness",
    "pointing_errors_rad",
    "pose_errors",
    "pose_path_data",
    "readonly",
    "rendered_detections",
    "robustness_study",
    "run_and_print",
    "run_crlb",
    "run_demo",
    "run_gaze",
    "run_on_head",
    "run_robustness",
    "sample_std",
    "save_figure",
    "shared_legend",
    "study_parser",
    "target_pose",
    "triangulate",
    "triangulation_errors_m",
    "ur10_urdf",
    "write_json",
]
