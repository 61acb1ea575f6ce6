"""Measurement files (``kinfw-measurements``, version 1, JSON): read, validate, write.
Also the hand-eye pose-pair files of ``kinfw handeye`` (CSV, JSON, easy_handeye2 YAML:
:func:`read_pose_pairs`, :func:`pose_pairs_text`; formats in ``_pose_pairs.py`` and
``docs/handeye.md``). And ROS 1 / ROS 2 bags (:func:`read_bag`,
:func:`measurements_from_bag`: joint states and a pose, point or TF stream, time-aligned;
``_bag_read.py``, ``_bag_align.py``, ``_bag_images.py`` and ``docs/bags.md``).

A measurement file lists samples; each sample is one robot configuration ``q`` and the
observations made in it::

    {
      "format": "kinfw-measurements", "version": 1,
      "units": {"length": "mm", "angle": "deg"},
      "joint_names": ["pan", "tilt"],
      "measured_in": "mocap",
      "samples": [
        {"q": [10.0, -5.0],
         "observations": [
           {"frame": "left_plate", "kind": "pose",
            "xyz": [100.0, 200.0, 1400.0], "quat_xyzw": [0, 0, 0.7071067811865476,
                                                         0.7071067811865476]},
           {"frame": "left_camera", "kind": "target", "target": "checkerboard",
            "xyz": [0.0, 50.0, 800.0], "quat_xyzw": [0, 0, 0, 1]},
           {"frame": "flange", "kind": "point", "xyz": [310.0, 5.0, 920.0],
            "offset": [0.0, 0.0, 25.0], "measured_in": "tracker"}
         ]}
      ]
    }

Observation kinds
-----------------
``"pose"``
    ``xyz`` and ``quat_xyzw`` (scalar last) of URDF frame ``frame`` in the measurement
    frame: ``meas_T_frame``. With ``"marker": "name"`` the pose is that of a rigid marker
    on ``frame`` whose pose in ``frame`` is unknown (one unknown per marker name).
``"target"``
    ``xyz`` and ``quat_xyzw`` of a fixed target seen by the camera frame ``frame`` on the
    robot: ``camera_T_target``. The optional ``"target"`` names the target (default
    ``"target"``); the target's pose in the world is unknown. ``marker``, ``offset`` and
    ``measured_in`` are not allowed on target observations.
``"point"``
    ``xyz`` only (no ``quat_xyzw``) of a point rigidly attached to ``frame``, in the
    measurement frame: ``meas_p_point``. ``"offset": [x, y, z]`` gives its position in
    ``frame`` when it is known; without it the offset is estimated. ``"marker"`` names a
    marker whose offset is unknown, so ``marker`` and ``offset`` exclude each other.

Payload and gravity
-------------------
A sample may say what the robot carries: ``"payload": {"frame": LINK, "mass_kg": m,
"com": [x, y, z], "inertia": [ixx, ixy, ixz, iyy, iyz, izz]}``: a URDF link or frame,
the mass in kg (>= 0), the centre of mass in that frame in the file's length unit
(optional, default the frame's origin) and the rotational inertia about the centre of
mass in the frame's axes, kg m^2, URDF order (optional, default a point mass). The
top-level ``"gravity": [gx, gy, gz]`` is gravity in the URDF root frame, m/s^2 (norm
between 0.1 and 100; default ``[0, 0, -9.81]``). They load the joints (joint compliance:
:mod:`kinfw.model`); :attr:`Measurements.payloads` (None when no sample has one) and
:attr:`Measurements.gravity` hold them, :meth:`Measurements.sample_payloads` gives every
sample's. The writer writes a sample's payload only when it has one and gravity only
when it is not the default.

A frame the URDF lacks (a camera on ``tool0``) may be declared in the top-level
``"mounts"`` section, ``{"camera": {"parent": "tool0"}}`` (optional start ``xyz``,
``quat_xyzw``): :func:`mounted_robot` adds it to the robot as a link on a fixed joint,
whose origin the calibration estimates (``docs/measurements.md``).

The measurement frame is the URDF root link unless ``"measured_in"`` names another frame
(one that is *not* in the URDF, whose pose in the root link is then estimated). A
top-level ``measured_in`` is the default for every ``pose`` and ``point`` observation
of the file; an observation may override it (name the root link to measure in the root).

Units
-----
``"units"`` is required: ``"length"`` is ``"m"`` or ``"mm"``, ``"angle"`` is ``"rad"`` or
``"deg"``. The reader converts to SI: ``xyz`` and ``offset`` by the length unit, and
*every* joint value by the angle unit (the file does not say which joints are
prismatic; in a ``"rad"`` file prismatic values are therefore read as metres). A file
with prismatic joints in millimetres, or mixed units, gives the optional top-level
``"joint_units"``: one of ``"m"``, ``"mm"``, ``"rad"``, ``"deg"`` per entry of
``joint_names``, which then wins over ``units.angle``. The writer always writes SI,
``{"length": "m", "angle": "rad"}``, with floats written by ``repr`` (exact round trip).

Rules
-----
``joint_names`` (non-empty, distinct) may list only the joints that moved; the others are
held at zero (:meth:`Measurements.q_of`). Every sample has ``q`` (one finite number per
joint) and a non-empty ``observations`` list. Quaternions must have a norm within 1e-3
of 1 and are renormalised (a file whose norms are off by more than 1e-6, as when written
with 4 or 5 decimals, gets one warning saying how many and by how much). A marker name
belongs to one frame. A key the reader does not know is ignored with a warning (one per
key and place: the top level, samples, payloads, or observations of one kind; naming
the first place, how many have it and the keys known there); a top-level ``"comment"``
(free text) is known. An observation kind lists its keys in
:attr:`~kinfw.observations.ObservationKind.file_keys` (a kind that does not: the keys
its ``parse`` reads). ``null`` for an optional key is the same as leaving it out (and is
never warned of). Every
problem raises :class:`DatasetError` naming the file, the key path
(``samples[7].observations[1].quat_xyzw``) and what was expected.

Observations are grouped (:class:`PoseObservations`, :class:`TargetObservations`,
:class:`PointObservations`, or the group of any kind registered in
:mod:`kinfw.observations`) in first-seen order; each group holds arrays with the batch
axis first and the sample index of every row. Parsing, writing, subsetting and merging
go through the registry: each kind's class reads and writes its own observations.
:func:`check_against_robot` checks a dataset against a URDF, :func:`check_joint_motion`
that the joints move enough to be identified.

The dataset is :class:`Measurements` (:mod:`kinfw.measurements`), the reader and
writer are in :mod:`kinfw.measurements` and the checks in
:mod:`kinfw.measurements`; this module re-exports their public names (the ones
callers import from here).
"""

from kinfw.measurements._bag_align import (
    DROP_REASONS,
    BagAlignment,
    joint_values_at,
    measurements_from_bag,
    time_offset_streams,
)
from kinfw.measurements._bag_images import (
    IMAGE_JOINTS_CSV,
    IMAGE_STAMPS_JSON,
    BagImages,
    write_bag_images,
)
from kinfw.measurements._bag_read import BagRecording, JointStates, MeasuredStream, read_bag
from kinfw.measurements._checks import (
    DISTINCT_TOL,
    DUPLICATE_RTOL,
    check_against_robot,
    check_joint_motion,
    drop_duplicate_samples,
    duplicate_samples,
    fixed_in_experiment,
    observed_joints,
    robot_measurement_frames,
)
from kinfw.measurements._csv import CsvTable, csv_table
from kinfw.measurements._dataset import (
    Measurements,
    check_measurements,
    concatenate_measurements,
    first_uses,
    merge_same_key,
)
from kinfw.measurements._figaroh_csv import (
    IGNORED_COLUMNS,
    matrix_from_figaroh_rpy,
    measurements_from_figaroh_csv,
)
from kinfw.measurements._file import (
    FORMAT,
    SUPPORTED_VERSIONS,
    measurements_from_dict,
    measurements_to_dict,
    read_measurements,
    write_measurements,
)
from kinfw.measurements._mounts import Mount, mounted_robot
from kinfw.measurements._pose_pairs import (
    HAND_POSE_COLUMNS,
    MIN_POSE_PAIRS,
    PLAIN_POSE_COLUMNS,
    POSE_PAIR_COLUMNS,
    HandPoses,
    PosePairs,
    drop_duplicate_pairs,
    duplicate_pairs,
    pose_pairs_from_measurements,
    pose_pairs_text,
    read_hand_poses,
    read_pose_pairs,
    target_views,
)
from kinfw.measurements._streams import (
    align_streams,
    check_stream,
    interpolate_poses,
    read_pose_csv,
)

__all__ = [
    "DISTINCT_TOL",
    "DROP_REASONS",
    "DUPLICATE_RTOL",
    "FORMAT",
    "HAND_POSE_COLUMNS",
    "IGNORED_COLUMNS",
    "IMAGE_JOINTS_CSV",
    "IMAGE_STAMPS_JSON",
    "MIN_POSE_PAIRS",
    "PLAIN_POSE_COLUMNS",
    "POSE_PAIR_COLUMNS",
    "SUPPORTED_VERSIONS",
    "BagAlignment",
    "BagImages",
    "BagRecording",
    "CsvTable",
    "HandPoses",
    "JointStates",
    "MeasuredStream",
    "Measurements",
    "Mount",
    "PosePairs",
    "align_streams",
    "check_against_robot",
    "check_joint_motion",
    "check_measurements",
    "check_stream",
    "concatenate_measurements",
    "csv_table",
    "drop_duplicate_pairs",
    "drop_duplicate_samples",
    "duplicate_pairs",
    "duplicate_samples",
    "first_uses",
    "fixed_in_experiment",
    "interpolate_poses",
    "joint_values_at",
    "matrix_from_figaroh_rpy",
    "measurements_from_bag",
    "measurements_from_dict",
    "measurements_from_figaroh_csv",
    "measurements_to_dict",
    "merge_same_key",
    "mounted_robot",
    "observed_joints",
    "pose_pairs_from_measurements",
    "pose_pairs_text",
    "read_bag",
    "read_hand_poses",
    "read_measurements",
    "read_pose_csv",
    "read_pose_pairs",
    "robot_measurement_frames",
    "target_views",
    "time_offset_streams",
    "write_bag_images",
    "write_measurements",
]
