"""Hand-eye calibration: ``A X = X B`` (Tsai & Lenz 1989; :func:`solve_axxb`) and
``A = X B Y`` (Hirsh, DeSouza & Kak 2001; :func:`solve_axyb`), each ending in maximum
likelihood on SE(3) with covariance, verdict and outlier rejection; the closed forms of
Park, Andreff, Daniilidis, Shah and Li as starts (by name in :data:`START_METHODS`);
stage 2 of Shih et al. per camera (:func:`calibrate_cameras`); the time offset between
pose streams (:func:`best_time_offset`); the scale of a camera's target translations
against the robot's motion (:func:`translation_scale`: a board of the wrong size). For
``kinfw handeye``: either setup from pose pairs (:func:`calibrate_pose_pairs`, a
:class:`HandEyeCalibration` written and read back by :func:`handeye_calibration_text` /
:func:`read_handeye_calibration`), OpenCV's closed forms and the registered starts side
by side (:func:`fit_method`, :func:`handeye_methods`) with held-out errors
(:func:`loop_closure_errors`, :func:`kfold_errors`), and the ROS 2 outputs
(:func:`write_ros_outputs`).

One convention for every solver here (eye-in-hand): a camera rigidly mounted on the
robot's *hand* (the link it hangs from: end effector, flange, the head's plate) looks at
a *target* fixed in the world while the robot moves. Frames: ``base`` (the frame of the
forward kinematics: the robot's base, or the URDF root), ``hand``, ``camera``,
``target``; ``a_T_b`` is the pose of frame b in frame a. At every pose ``i``::

    base_T_target = base_T_hands[i] @ hand_T_camera @ camera_T_targets[i]

with the inputs ``base_T_hands`` (forward kinematics, OpenCV's ``gripper2base``) and
``camera_T_targets`` (camera extrinsics, OpenCV's ``target2cam``), and the unknowns
``hand_T_camera`` (the camera's mount, OpenCV's ``cam2gripper``) and ``base_T_target``.
Both solvers take the poses by these names, keyword-only, and return results that name
the transforms by them; the papers' ``X`` and ``Y`` are read-only aliases, and they
differ: Tsai & Lenz's ``X`` is ``hand_T_camera``, Hirsh et al.'s ``X`` is its inverse
``camera_T_hand``. Eye-to-hand (the camera fixed in the world, the target on the hand)
is the same equation with base and hand exchanged (the solvers' Warnings sections).
Quaternions are scalar last ``(x, y, z, w)`` throughout; the verdict is a
:class:`Verdict` with a message for people.
"""

from __future__ import annotations

from kinfw.identification.handeye._axxb import (
    HandEyeError,
    motion_pairs,
    solve_axxb,
)
from kinfw.identification.handeye._axyb import (
    convergence_factor,
    solve_axyb,
)
from kinfw.identification.handeye._axyb_iteration import (
    AXYBError,
)
from kinfw.identification.handeye._calibration import (
    HandEyeCalibration,
    handeye_calibration_text,
    read_handeye_calibration,
)
from kinfw.identification.handeye._cameras import (
    CameraCalibration,
    CamerasResult,
    calibrate_cameras,
    camera_mount,
)
from kinfw.identification.handeye._checks import (
    StartError,
)
from kinfw.identification.handeye._compare import (
    HANDEYE_METHODS,
    HeldOutErrors,
    MethodResult,
    calibrate_pose_pairs,
    compare_methods,
    fit_method,
    handeye_methods,
    kfold_errors,
    loop_closure_errors,
    repeated_pairs,
)
from kinfw.identification.handeye._ml import (
    PoseFit,
    fit_absolute,
    rejection_threshold,
)
from kinfw.identification.handeye._quaternion import (
    closed_form_start,
)
from kinfw.identification.handeye._result import (
    AXYBResult,
    HandEyeResult,
)
from kinfw.identification.handeye._ros import (
    ROS_FILES,
    static_transform_args,
    write_ros_outputs,
)
from kinfw.identification.handeye._scale import (
    translation_scale,
)
from kinfw.identification.handeye._starts import (
    START_METHODS,
    RankedStart,
    StartMethod,
    candidate_starts,
    rank_starts,
    register_start,
    unregister_start,
)
from kinfw.identification.handeye._starts_axxb import (
    andreff_axxb,
    daniilidis_axxb,
    park_axxb,
)
from kinfw.identification.handeye._starts_axyb import (
    li_axyb,
    shah_axyb,
)
from kinfw.identification.handeye._time_offset import (
    TimeOffsetResult,
    best_time_offset,
    implied_target_spread,
)
from kinfw.identification.handeye._uncertainty import (
    POOR_ROTATION_DEG,
    POOR_TRANSLATION_FRACTION,
    UNDETERMINED_ROTATION_DEG,
    UNDETERMINED_TRANSLATION_FRACTION,
    Uncertainty,
    Verdict,
    combined_verdict,
    uncertainty,
)

__all__ = [
    "HANDEYE_METHODS",
    "POOR_ROTATION_DEG",
    "POOR_TRANSLATION_FRACTION",
    "ROS_FILES",
    "START_METHODS",
    "UNDETERMINED_ROTATION_DEG",
    "UNDETERMINED_TRANSLATION_FRACTION",
    "AXYBError",
    "AXYBResult",
    "CameraCalibration",
    "CamerasResult",
    "HandEyeCalibration",
    "HandEyeError",
    "HandEyeResult",
    "HeldOutErrors",
    "MethodResult",
    "PoseFit",
    "RankedStart",
    "StartError",
    "StartMethod",
    "TimeOffsetResult",
    "Uncertainty",
    "Verdict",
    "andreff_axxb",
    "best_time_offset",
    "calibrate_cameras",
    "calibrate_pose_pairs",
    "camera_mount",
    "candidate_starts",
    "closed_form_start",
    "combined_verdict",
    "compare_methods",
    "convergence_factor",
    "daniilidis_axxb",
    "fit_absolute",
    "fit_method",
    "handeye_calibration_text",
    "handeye_methods",
    "implied_target_spread",
    "kfold_errors",
    "li_axyb",
    "loop_closure_errors",
    "motion_pairs",
    "park_axxb",
    "rank_starts",
    "read_handeye_calibration",
    "register_start",
    "rejection_threshold",
    "repeated_pairs",
    "shah_axyb",
    "solve_axxb",
    "solve_axyb",
    "static_transform_args",
    "translation_scale",
    "uncertainty",
    "unregister_start",
    "write_ros_outputs",
]
