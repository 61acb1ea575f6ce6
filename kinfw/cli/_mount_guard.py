"""The plausibility guard on the mount ``kinfw handeye`` writes: with ``--urdf``, the
calibrated ``hand_T_camera`` against the URDF's (:func:`check_mount`); before any output
is written, refused beyond the bound unless ``--allow-large-changes``.

Like :mod:`kinfw.cli`, this module imports only the standard library at start-up.
"""

from __future__ import annotations

import argparse
import math
import warnings
from typing import Any

from kinfw.cli._fit import change_bound


def _urdf_camera(robot, args: argparse.Namespace) -> str | None:
    """The URDF frame of the camera whose targets were fitted: ``--camera-frame`` when the
    URDF has it, else the one camera of the measurement file's target or pixel groups when
    the URDF has that; None otherwise (no mount in the URDF to compare with)."""
    from kinfw.measurements import read_measurements

    if robot.has_frame(args.camera_frame):
        return args.camera_frame
    data = read_measurements(args.pairs)
    cameras = {
        g.camera for kind in ("target", "pixels") for g in data.groups(kind) if hasattr(g, "camera")
    }
    camera = cameras.pop() if len(cameras) == 1 else None
    return camera if camera is not None and robot.has_frame(camera) else None


def check_mount(args: argparse.Namespace, calibration: Any) -> None:
    """Refuse (:class:`kinfw.identification.checks.ImplausibleCalibrationError`) a mount
    that moved beyond the guard's bound from the URDF's (``--urdf``, eye-in-hand; the
    camera a frame of the URDF), unless ``--allow-large-changes`` (then a warning). Does
    nothing without a URDF to compare with."""
    if getattr(args, "urdf", None) is None or calibration.setup != "eye-in-hand":
        return
    import numpy as np

    from kinfw.cli._args import load_model
    from kinfw.geometry import inverse_transform
    from kinfw.identification.checks import ImplausibleCalibrationError, mount_plausibility

    robot = load_model(args.urdf, args)
    camera = _urdf_camera(robot, args)
    if camera is None or not robot.has_frame(args.hand_frame):
        return
    between = {j.name for j in robot.path_joints(camera)} - {
        j.name for j in robot.path_joints(args.hand_frame)
    }
    if between & set(robot.placeholder_joints):
        return  # a placeholder mount (kinfw pose-chain's identity): nothing to compare
    q = np.zeros((1, len(robot.joint_names)))
    root_T = {f: robot.frame_poses(q, f, robot.joint_names)[0] for f in (args.hand_frame, camera)}
    nominal = inverse_transform(root_T[args.hand_frame]) @ root_T[camera]
    name = f"{args.hand_frame}_T_{camera}"
    verdict = mount_plausibility(
        robot, name, nominal, calibration.mount_T_camera, bound=change_bound(args)
    )
    if verdict.plausible:
        return
    top = verdict.changes[0]
    said = (
        f"{args.pairs}: mount {name} {1e3 * top.shift_m:.3g} mm / "
        f"{math.degrees(top.turn_rad):.3g} deg off the URDF's, {top.ratio:.3g} x the bound"
    )
    if args.allow_large_changes:
        warnings.warn(f"{said}: written (--allow-large-changes)", UserWarning, stacklevel=2)
        return
    raise ImplausibleCalibrationError(
        f"{said} (--allow-large-changes writes it)\n"
        f"the bound: {verdict.bound_text()} ({verdict.why})\n"
        "likely causes, in order:\n"
        "  1. the board's size or the target's geometry is wrong: the camera moves along "
        "its optical axis by the scale error times the board's distance\n"
        f"  2. the URDF ({robot.model.name!r}) or --hand-frame / --camera-frame is another "
        "robot's or frame's: the mount is off by the distance between them\n"
        "  3. a unit (--unit mm for metres, or the reverse): positions off 1000 times\n"
        "  4. motions that do not determine the mount (all about one axis, too few): "
        "its verdict and 1-sigma say so"
    )
