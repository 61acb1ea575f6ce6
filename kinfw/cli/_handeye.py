"""``kinfw handeye``: hand-eye calibration from pose pairs (CSV, JSON, easy_handeye2
YAML; :func:`kinfw.measurements.read_pose_pairs`) or a measurement file with a URDF
(:func:`kinfw.measurements.pose_pairs_from_measurements`: target observations, or the
images of ``kinfw detect`` posed by PnP), eye-in-hand or eye-to-hand, with
OpenCV's closed forms side by side, held-out errors, a typed result file and ROS 2
outputs (:mod:`kinfw.identification.handeye`).

Like the other command modules, only the standard library is imported at start-up.
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

from kinfw.cli._args import add_keep_duplicates_option, add_xacro_option, number
from kinfw.cli._fit_parser import add_guard_options
from kinfw.cli._mount_guard import check_mount
from kinfw.files import check_output_dir, check_outputs, json_text, write_text_atomic

#: Folds of the cross-validation when --method is given without --holdout or --k.
DEFAULT_K = 5
CAMERA_FRAME = "camera_link"
_METRES_PER = {"m": 1.0, "mm": 1e-3}
_OPENCV = ("tsai", "park", "horaud", "andreff", "daniilidis", "shah", "li")


def _methods(text: str) -> list[str]:
    """``--method``: OpenCV's closed forms by name (the standard library alone), or
    ``all`` / a name of a registered start (a plugin's), which loads the hand-eye
    package to list them (:func:`kinfw.identification.handeye.handeye_methods`)."""
    names = [m.strip().lower() for m in text.split(",")]
    if text.strip() != "all" and all(m in _OPENCV for m in names):
        return names
    from kinfw.identification.handeye import handeye_methods

    known = [m for m in handeye_methods() if m != "kinfw"]
    if text.strip() == "all":
        return known
    unknown = [m for m in names if m not in known]
    if unknown:
        raise argparse.ArgumentTypeError(
            f"unknown method(s) {', '.join(unknown)}: use all or some of {', '.join(known)}"
        )
    return names


def add_handeye_parser(sub: argparse._SubParsersAction) -> None:
    """The ``handeye`` sub-command."""
    p = sub.add_parser(
        "handeye",
        help="hand-eye calibration from pose pairs (CSV, JSON, easy_handeye2 YAML)",
        description="Hand-eye calibration from pose pairs: the camera's pose on the hand "
        "(--setup eye-in-hand: hand_T_camera, and base_T_target) or in the robot's base "
        "(eye-to-hand: base_T_camera, and hand_T_target), by maximum likelihood from "
        "Tsai-Lenz with outlier rejection, with 1-sigma per axis and a verdict. "
        "PAIRS: a .csv with a header row and the columns hand_x, hand_y, hand_z, "
        "hand_qx, hand_qy, hand_qz, hand_qw, sensor_x, sensor_y, sensor_z, sensor_qx, "
        "sensor_qy, sensor_qz, sensor_qw (base_T_hand and camera_T_target: position, then "
        "unit quaternion scalar last; metres unless --unit mm); a .json list of "
        "[base_T_hand, camera_T_target] pairs of 4x4 row-major matrices; or "
        "easy_handeye2's saved samples (.yaml, .yml, .samples). Before the fit, pairs "
        "whose quaternions look stored scalar first or whose lengths look like another "
        "unit are refused, and pairs recorded twice are dropped (warned).",
    )
    p.add_argument(
        "pairs",
        type=Path,
        metavar="PAIRS",
        help="the pose-pair file (or, with --urdf, a kinfw measurement file: target "
        "observations, or the pixels observations of kinfw detect, posed by PnP)",
    )
    p.add_argument(
        "--setup",
        choices=("eye-in-hand", "eye-to-hand"),
        help="the camera on the hand looking at a fixed target (eye-in-hand), or fixed "
        "looking at a target on the hand (eye-to-hand); default: the file's "
        "(easy_handeye2) or eye-in-hand",
    )
    p.add_argument(
        "--unit", choices=tuple(_METRES_PER), default="m", help="length unit of the files"
    )
    p.add_argument(
        "--method",
        type=_methods,
        metavar="all|NAME[,NAME...]",
        help="also fit OpenCV's closed forms (tsai, park, horaud, andreff, daniilidis: "
        "calibrateHandEye; shah, li: calibrateRobotWorldHandEye) or a closed-form start a "
        "plugin registered (by its name; all: every one) and print a table of their "
        "results and held-out errors beside kinfw's",
    )
    p.add_argument(
        "--holdout",
        type=Path,
        metavar="FILE",
        help="pose pairs not used in the fit, read as PAIRS is (with --urdf a measurement "
        "file): print the held-out loop-closure errors (deg, mm) of every method",
    )
    p.add_argument(
        "--k",
        type=number(int, low=2),
        help=f"k-fold cross-validation of every method (default with --method and no "
        f"--holdout: {DEFAULT_K})",
    )
    p.add_argument("--json", action="store_true", help="print the result as JSON on stdout")
    p.add_argument(
        "--out",
        type=Path,
        metavar="RESULT.yaml",
        help="write the calibration (transforms, 6x6 covariance, setup, samples used and "
        "rejected) as YAML (or JSON for a .json name); read it back with "
        "kinfw.identification.handeye.read_handeye_calibration",
    )
    p.add_argument(
        "--ros-out",
        type=Path,
        metavar="DIR",
        help="write ROS 2 outputs there: static_transform_publisher.sh, handeye.launch.py, "
        "handeye_calibration.yaml (easy_handeye2) and handeye_mount.urdf",
    )
    p.add_argument("--base-frame", default="base_link", help="the robot base's TF frame")
    p.add_argument(
        "--hand-frame",
        help="the hand's TF frame (default tool0; with --urdf, the link the camera's "
        "fixed joint hangs on)",
    )
    p.add_argument(
        "--camera-frame",
        default=CAMERA_FRAME,
        help="the camera's TF frame (with --urdf: the URDF camera frame whose target "
        "observations to use, when several cameras observe)",
    )
    p.add_argument(
        "--urdf",
        default=argparse.SUPPRESS,
        help="PAIRS (and --holdout) is a kinfw measurement file (target observations of a "
        "camera on the robot, or images' pixels from kinfw detect: PnP per image with the "
        "file's intrinsics): the hand's poses are this URDF's forward kinematics of "
        "--hand-frame (eye-in-hand, metres)",
    )
    add_xacro_option(p)
    add_keep_duplicates_option(p)
    add_guard_options(p)
    p.set_defaults(func=cmd_handeye, check_outputs=check_handeye_outputs)


def check_handeye_outputs(args: argparse.Namespace) -> None:
    """The output paths, before any work."""
    inputs = {"PAIRS": args.pairs, "--holdout": args.holdout}
    check_outputs({"--out": args.out}, inputs=inputs)
    if args.ros_out is not None:
        check_output_dir(args.ros_out, label="--ros-out")


def _pose_line(name: str, T) -> str:
    """``name: xyz [mm] [...]  quat xyzw [...]`` of a transform in metres."""
    import numpy as np

    from kinfw.geometry import xyz_quat_xyzw_from_transform

    xyz, q = xyz_quat_xyzw_from_transform(T)
    return (
        f"{name}: xyz [mm] {np.array2string(xyz * 1e3, precision=3, suppress_small=True)}"
        f"  quat xyzw {np.array2string(q, precision=6, suppress_small=True)}"
    )


def _camera_link(robot, data, camera: str | None) -> str:
    """The URDF link whose fixed joint carries the camera of ``data``'s target views
    (``camera``, or the one camera that observes): ``--hand-frame``'s default with
    ``--urdf`` (``tool0`` when nothing observes a target: the pose pairs' reader refuses
    that file)."""
    from kinfw.measurements import target_views

    cameras = sorted({g.camera for g in target_views(data)} if camera is None else {camera})
    if not cameras:  # no views: pose_pairs_from_measurements says so
        return "tool0"
    if len(cameras) != 1 or not robot.has_frame(cameras[0]):
        raise ValueError(
            f"--hand-frame: not given and not found: {data.source}'s camera(s) "
            f"{cameras} {'are' if len(cameras) > 1 else 'is not'} one link of "
            f"{robot.source}; give the link the camera is mounted on (--hand-frame LINK)"
        )
    path = robot.path_joints(cameras[0])
    if not path or path[-1].is_movable:
        raise ValueError(
            f"--hand-frame: not given, and camera {cameras[0]!r} of {robot.source} is not on "
            "a fixed joint; give the link the camera is mounted on (--hand-frame LINK)"
        )
    return path[-1].parent


def _read_pairs(args: argparse.Namespace):
    """The pairs to fit (metres) and the held-out ones (or None), both read the same way
    (pose-pair files, or with --urdf measurement files) and checked before any fit:
    duplicates of the fit's pairs dropped (warned; unless --keep-duplicates), quaternion
    order and length unit refused when wrong; warns when held-out pairs repeat the
    fit's."""
    from kinfw.identification.handeye import repeated_pairs
    from kinfw.measurements import drop_duplicate_pairs, read_pose_pairs

    scale = _METRES_PER[args.unit]
    if getattr(args, "urdf", None) is not None:
        if args.setup == "eye-to-hand":
            raise ValueError(
                "--urdf: a measurement file's targets are seen by a camera on "
                "the robot (eye-in-hand); --setup eye-to-hand does not apply"
            )
        from kinfw.cli._args import load_model
        from kinfw.identification.checks import check_units
        from kinfw.measurements import (
            drop_duplicate_samples,
            pose_pairs_from_measurements,
            read_measurements,
        )

        robot = load_model(args.urdf, args)
        camera = args.camera_frame if args.camera_frame != CAMERA_FRAME else None

        def read(path: Path, fit: bool):
            data = read_measurements(path)
            if fit and not args.keep_duplicates:
                data = drop_duplicate_samples(data)
            if args.hand_frame is None:
                args.hand_frame = _camera_link(robot, data, camera)
            if all(robot.has_frame(f) for f in data.observed_frames):
                check_units(robot, data)  # calibrate's: the motion against the URDF's
            pairs = pose_pairs_from_measurements(
                data, robot, hand_frame=args.hand_frame, camera=camera
            )
            return _checked(pairs, args, ("sensor",), "m")
    else:
        args.hand_frame = args.hand_frame or "tool0"

        def read(path: Path, fit: bool):
            pairs = read_pose_pairs(path).scaled(scale)
            if fit and not args.keep_duplicates:
                pairs = drop_duplicate_pairs(pairs)
            sides = () if path.suffix.lower() == ".json" else ("hand", "sensor")
            return _checked(pairs, args, sides, args.unit)

    pairs = read(args.pairs, True)
    holdout = read(args.holdout, False) if args.holdout else None
    if holdout is not None:
        repeated = repeated_pairs(
            pairs.base_T_hands,
            pairs.sensor_T_targets,
            held_base_T_hands=holdout.base_T_hands,
            held_camera_T_targets=holdout.sensor_T_targets,
        )
        if repeated:
            warnings.warn(
                f"--holdout {args.holdout}: {len(repeated)} of its {len(holdout)} pairs are "
                f"also in {args.pairs} (e.g. pair {repeated[0]}): their errors are in-sample, "
                "not held-out",
                UserWarning,
                stacklevel=2,
            )
    return pairs, holdout


def _checked(pairs, args: argparse.Namespace, quaternions: tuple[str, ...], unit: str):
    """``pairs``, refused when their quaternions look stored in the other order or their
    lengths in another unit than ``unit``
    (:func:`kinfw.identification.checks.check_pose_pair_data`)."""
    from kinfw.identification.checks import check_pose_pair_data

    check_pose_pair_data(
        pairs.base_T_hands,
        pairs.sensor_T_targets,
        setup=args.setup or pairs.setup or "eye-in-hand",
        source=pairs.source,
        unit=unit,
        quaternions=quaternions,
    )
    return pairs


def cmd_handeye(args: argparse.Namespace) -> int:
    """Calibrate, compare (``--method``), write (``--out``, ``--ros-out``), print (or
    ``--json``); 0 on success."""
    from kinfw.identification.handeye import calibrate_pose_pairs, compare_methods

    pairs, holdout = _read_pairs(args)
    setup = args.setup or pairs.setup or "eye-in-hand"
    mount_frame = args.hand_frame if setup == "eye-in-hand" else args.base_frame
    calibration, _ = calibrate_pose_pairs(
        base_T_hands=pairs.base_T_hands,
        camera_T_targets=pairs.sensor_T_targets,
        setup=setup,
        frames=(mount_frame, args.camera_frame),
        keep_duplicates=args.keep_duplicates,
    )
    _warn_target_scale(pairs, calibration)  # a board of the wrong size, named first
    check_mount(args, calibration)  # the plausibility guard, before anything is written
    k = args.k or (DEFAULT_K if args.method and holdout is None else None)
    if k is not None and k > len(pairs):
        raise ValueError(f"--k {k}: more folds than the {len(pairs)} pose pairs")
    rows = compare_methods(
        args.method or [],
        calibration,
        base_T_hands=pairs.base_T_hands,
        camera_T_targets=pairs.sensor_T_targets,
        held_out=None if holdout is None else (holdout.base_T_hands, holdout.sensor_T_targets),
        k=k,
    )
    if args.out is not None:
        from kinfw.identification.handeye import handeye_calibration_text

        fmt = "json" if args.out.suffix.lower() == ".json" else "yaml"
        write_text_atomic(args.out, handeye_calibration_text(calibration, fmt))
    if args.ros_out is not None:
        from kinfw.identification.handeye import write_ros_outputs

        write_ros_outputs(
            args.ros_out, calibration, base_frame=args.base_frame, hand_frame=args.hand_frame
        )
    if args.json:
        print(json_text(_json(calibration, rows, k)))
    else:
        _print_calibration(calibration, pairs.source)
        if len(rows) > 1 or holdout is not None or k:
            _print_table(rows, calibration.mount_name, holdout is not None, k)
    return 0


def _warn_target_scale(pairs, calibration) -> None:
    """Warn when the sensor's target translations follow the hand's motion at a scale
    other than 1 (:func:`kinfw.identification.handeye.translation_scale`: a board given
    the wrong square size), beyond :class:`kinfw.identification.checks.TargetScale`'s
    rule; the hand-eye solve absorbs such a factor into the mount and the target."""
    import numpy as np

    from kinfw.identification.checks import TargetScale
    from kinfw.identification.handeye import translation_scale

    hands = pairs.base_T_hands
    if calibration.setup == "eye-in-hand":  # the camera rides on the hand
        links, targets = hands, None
        rotations = hands[:, :3, :3] @ calibration.mount_T_camera[:3, :3]
    else:  # a static camera in the base, the target on the hand
        links, targets = np.tile(np.eye(4), (len(hands), 1, 1)), hands
        rotations = np.tile(calibration.mount_T_camera[:3, :3], (len(hands), 1, 1))
    found = translation_scale(
        base_T_links=links,
        base_R_cameras=rotations,
        camera_p_targets=pairs.sensor_T_targets[:, :3, 3],
        base_T_target_links=targets,
    )
    if found is None:
        return
    scale = TargetScale(calibration.camera_frame, "target", found[0], found[1], len(hands))
    if scale.off:
        warnings.warn(f"{pairs.source}: {scale.message()}", UserWarning, stacklevel=2)


def _errors(e) -> dict | None:
    if e is None:
        return None
    return {"rms_rotation_deg": e.rms_rotation_deg, "rms_translation_mm": 1e3 * e.rms_translation}


def _json(calibration, rows, k: int | None) -> dict:
    """``--json``'s document: the calibration, its 1-sigma and every method's results."""
    return {
        "calibration": calibration.to_dict(),
        "sigma_rotation_deg": calibration.sigma_rotation_deg.tolist(),
        "sigma_translation_mm": (1e3 * calibration.sigma_translation_m).tolist(),
        "methods": [
            {
                "method": r.method,
                f"{calibration.mount_name}_T_camera": None
                if r.mount_T_camera is None
                else r.mount_T_camera.tolist(),
                f"{calibration.holder_name}_T_target": None
                if r.holder_T_target is None
                else r.holder_T_target.tolist(),
                "holdout": _errors(r.holdout),
                "kfold": _errors(r.kfold),
                "k": k if r.kfold is not None else None,
                "error": r.error,
            }
            for r in rows
        ],
    }


def _print_calibration(c, source: str) -> None:
    import numpy as np

    print(f"kinfw handeye: {c.n_samples} pose pairs from {source} ({c.setup}), ", end="")
    print(f"{len(c.rejected)} rejected" + (f": {list(c.rejected)}" if c.rejected else ""))
    print(_pose_line(f"{c.mount_name}_T_camera", c.mount_T_camera))
    rpy = np.degrees(_rpy(c.mount_T_camera))
    print(f"  rpy [deg] {np.array2string(rpy, precision=4, suppress_small=True)}")
    print(
        f"  1-sigma: {np.array2string(1e3 * c.sigma_translation_m, precision=3)} mm "
        f"(along {c.mount_name} x y z), "
        f"{np.array2string(c.sigma_rotation_deg, precision=4)} deg (about camera x y z)"
    )
    print(_pose_line(f"{c.holder_name}_T_target", c.holder_T_target))
    print(f"verdict: {c.verdict_message}")


def _rpy(T):
    import pinocchio as pin

    return pin.rpy.matrixToRpy(T[:3, :3])


def _print_table(rows, mount: str, holdout: bool, k: int | None) -> None:
    import numpy as np

    from kinfw.geometry import rotation_angle

    header = ["method", "x mm", "y mm", "z mm", "roll", "pitch", "yaw", "vs kinfw deg/mm"]
    if holdout:
        header += ["holdout deg", "holdout mm"]
    if k:
        header += [f"{k}-fold deg", f"{k}-fold mm"]
    X0 = rows[0].mount_T_camera
    lines = [header]
    for r in rows:
        m, X, h, f = r.method, r.mount_T_camera, r.holdout, r.kfold
        if X is None:
            lines.append([m, f"failed: {r.error[:60]}"])
            continue
        d_rot = float(np.degrees(rotation_angle(X0[:3, :3].T @ X[:3, :3])))
        d_t = 1e3 * float(np.linalg.norm(X0[:3, 3] - X[:3, 3]))
        line = [m, *(f"{1e3 * v:.2f}" for v in X[:3, 3])]
        line += [f"{v:.3f}" for v in np.degrees(_rpy(X))]
        line.append(f"{d_rot:.3f}/{d_t:.2f}")
        for e in (h, f):
            if e is not None:
                line += [f"{e.rms_rotation_deg:.3f}", f"{1e3 * e.rms_translation:.2f}"]
        lines.append(line)
    print(
        f"\n{mount}_T_camera by method (rpy deg); held-out: RMS loop-closure error of "
        "camera_T_target (rotation deg, translation mm)"
    )
    lines = [r if len(r) > 2 else [r[0], *([""] * (len(header) - 1)), r[1]] for r in lines]
    widths = [max(len(r[i]) for r in lines) for i in range(len(header))]
    for r in lines:
        cells = [
            f"{r[0]:<{widths[0]}}",
            *(f"{v:>{w}}" for v, w in zip(r[1:], widths[1:], strict=False)),
        ]
        print("  ".join(cells + r[len(header) :]).rstrip())
