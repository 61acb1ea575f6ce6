"""Argument types and options shared by the ``kinfw`` command parsers, and reading what
the options name: checked numbers, ``--camera FRAME=FILE``, ``--frames``, the measurement
file with its ``--camera`` intrinsics and the calibration sidecar's path.

Like :mod:`kinfw.cli`, this module imports only the standard library at start-up.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from kinfw.model import Robot


# -- numbers on the command line -----------------------------------------------------------
def number(
    kind: type,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    unit: str = "",
) -> Callable[[str], float | int]:
    """An argparse ``type``: ``kind`` (int or float) within ``[low, high]`` (``(low,
    high]`` with ``low_open``); argparse names the flag in the error.

    Parameters
    ----------
    kind : type
        ``int`` or ``float``.
    low, high : float, optional
        Bounds of the value, in the option's unit (none: unbounded).
    low_open : bool
        Exclude ``low`` itself.
    unit : str
        The unit named in the error, e.g. ``"(mm)"``.

    Returns
    -------
    callable
        ``parse(text) -> kind``, raising :class:`argparse.ArgumentTypeError`.
    """
    if low is not None and high is not None:
        want = f"{'>' if low_open else '>='} {low:g} and <= {high:g}"
    elif low is not None:
        want = f"{'>' if low_open else '>='} {low:g}"
    else:
        want = ""
    noun = "an integer" if kind is int else "a number"
    suffix = f" {unit}" if unit else ""

    def parse(text: str) -> float | int:
        try:
            value = kind(text)
        except ValueError:
            value = None
        if (
            value is None
            or not math.isfinite(value)
            or (low is not None and (value <= low if low_open else value < low))
            or (high is not None and value > high)
        ):
            raise argparse.ArgumentTypeError(
                f"expected {' '.join(filter(None, (noun, want)))}{suffix}, got {text!r}"
            )
        return value

    parse.__name__ = kind.__name__  # argparse's own messages say "invalid int value"
    return parse


MM = number(float, low=0.0, unit="(mm)")
DEG = number(float, low=0.0, unit="(deg)")
POSITIVE_MM = number(float, low=0.0, low_open=True, unit="(mm)")
POSITIVE_DEG = number(float, low=0.0, low_open=True, unit="(deg)")
POSITIVE_PX = number(float, low=0.0, low_open=True, unit="(px)")
COUNT = number(int, low=1)
SEED = number(int, low=0)


def up_arg(text: str) -> list[float]:
    """``"x y z"`` (or ``x,y,z``): three finite numbers, not all zero."""
    try:
        up = [float(v) for v in text.replace(",", " ").split()]
    except ValueError:
        up = []
    if len(up) != 3 or not all(map(math.isfinite, up)) or not any(up):
        raise argparse.ArgumentTypeError(
            f'expected three numbers "x y z", not all zero, got {text!r}'
        )
    return up


def frame_file(text: str) -> tuple[str, Path]:
    """``FRAME=FILE`` of ``--camera``."""
    frame, sep, file = text.partition("=")
    if not sep or not frame or not file:
        raise argparse.ArgumentTypeError(f"expected FRAME=FILE, got {text!r}")
    return frame, Path(file)


def add_camera_option(p: argparse.ArgumentParser) -> None:
    """``--camera FRAME=FILE`` (repeatable): intrinsics for ``pixels`` observations."""
    p.add_argument(
        "--camera",
        action="append",
        type=frame_file,
        metavar="FRAME=FILE",
        help="intrinsics of the camera frame FRAME for 'pixels' observations, from a ROS "
        "camera_info / OpenCV YAML or JSON file; overrides or adds to the data file's "
        '"cameras" section (and, for verify, the sidecar\'s); a FRAME no observation uses '
        "is an error (repeatable)",
    )


def mount_arg(text: str) -> tuple[str, str]:
    """``NAME:PARENT`` of ``--mount``."""
    name, sep, parent = text.partition(":")
    if not sep or not name.strip() or not parent.strip():
        raise argparse.ArgumentTypeError(
            f"expected NAME:PARENT (a frame the URDF lacks and the link it is on), got {text!r}"
        )
    return name.strip(), parent.strip()


def add_mount_option(p: argparse.ArgumentParser) -> None:
    """``--mount NAME:PARENT`` (repeatable): a frame of the data that the URDF lacks."""
    p.add_argument(
        "--mount",
        action="append",
        type=mount_arg,
        default=[],
        metavar="NAME:PARENT",
        help="the data's frame NAME (a camera, a marker body) is not in the URDF: add it as "
        "a link on a fixed joint to the URDF link PARENT (identity start), whose origin is "
        'calibrated and exported; adds to the data file\'s "mounts" section (repeatable)',
    )


def mounted_model(robot: Robot, *datasets: Any) -> Robot:
    """The robot with the mounted frames of ``datasets`` (their ``"mounts"`` and the
    command's ``--mount``, :func:`read_data`) that it lacks added on fixed joints."""
    from kinfw.measurements import mounted_robot

    for data in datasets:
        robot = mounted_robot(robot, data.mounts, data.source)
    return robot


# -- what the options name --------------------------------------------------------------
def xacro_arg(text: str) -> tuple[str, str]:
    """``NAME:=VALUE`` (xacro's own syntax) -> ``(NAME, VALUE)``."""
    name, sep, value = text.partition(":=")
    if not sep or not name.strip():
        raise argparse.ArgumentTypeError(f"expected NAME:=VALUE (as for xacro), got {text!r}")
    return name.strip(), value


def add_xacro_option(p: argparse.ArgumentParser) -> None:
    """``--xacro-arg NAME:=VALUE`` (repeatable), for a xacro URDF (:func:`load_model`)."""
    p.add_argument(
        "--xacro-arg",
        type=xacro_arg,
        action="append",
        default=[],
        metavar="NAME:=VALUE",
        help="argument of a xacro URDF (repeatable); the URDF may be a .xacro file, or - to "
        "read a URDF (robot_description) on stdin",
    )


def load_model(path: Path | str, args: argparse.Namespace) -> Robot:
    """The robot of a command's URDF argument: a URDF or xacro file (with the command's
    ``--xacro-arg`` values), or ``-``: the URDF text on stdin (a ``robot_description``)."""
    from kinfw.model import load_robot

    xacro_args = dict(getattr(args, "xacro_arg", None) or ())
    if str(path) == "-":
        text = sys.stdin.read()
        if not text.strip():
            raise ValueError(
                "-: stdin is empty; expected a URDF's XML text there (a robot_description), "
                "or give the URDF's file name instead of -"
            )
        return load_robot(text, xacro_args=xacro_args)
    return load_robot(path, xacro_args=xacro_args)


def add_package_dir_option(p: argparse.ArgumentParser) -> None:
    """``--package-dir DIR`` (repeatable): where the URDF's ``package://`` meshes live,
    before ``ROS_PACKAGE_PATH`` (:func:`kinfw.model.resolve_meshes`)."""
    p.add_argument(
        "--package-dir",
        action="append",
        default=[],
        metavar="DIR",
        help="where package:// meshes live (repeatable; then ROS_PACKAGE_PATH)",
    )


def frames_arg(
    value: str | None, default: tuple[str, ...], flag: str, robot: Robot
) -> tuple[str, ...]:
    """The frames of a ``--frames`` / ``--cameras`` option (comma- or space-separated),
    else the URDF hint ``default``; ValueError naming ``flag`` and the links when
    neither is there."""
    if value:
        return tuple(v for v in value.replace(",", " ").split() if v)
    if default:
        return default
    raise ValueError(
        f"{robot.source}: give {flag} (comma-separated frame names); this URDF has no "
        f'<kinfw frames="..." cameras="..."/> hint. Links: {", ".join(robot.link_names)}'
    )


def add_keep_duplicates_option(p: argparse.ArgumentParser) -> None:
    """``--keep-duplicates``: keep the samples (pose pairs) that repeat an earlier one,
    which are otherwise warned about and dropped before the fit."""
    p.add_argument(
        "--keep-duplicates",
        action="store_true",
        help="keep samples (pose pairs) that repeat an earlier one exactly (default: warned "
        "about and dropped before the fit, so each counts once in the sigmas)",
    )


def read_data(path: Path, args: argparse.Namespace) -> Any:
    """The measurement file ``path`` with the intrinsics of ``--camera FRAME=FILE``
    (override or add to its ``"cameras"`` section) and the frames of ``--mount
    NAME:PARENT`` (add to its ``"mounts"``); for a command with ``--keep-duplicates``
    not given, without the samples that repeat an earlier one (warned about:
    :func:`kinfw.measurements.drop_duplicate_samples`)."""
    from kinfw.camera import CameraError, read_camera
    from kinfw.measurements import Mount, drop_duplicate_samples, read_measurements
    from kinfw.observations import DatasetError

    cameras = {}
    given = getattr(args, "camera", None) or ()
    for frame, file in given:
        try:
            cameras[frame] = read_camera(file)
        except CameraError as exc:
            raise DatasetError(f"--camera {frame}={file}: {exc}") from None
    data = read_measurements(path, cameras=cameras)
    mounts = getattr(args, "mount", None) or ()
    data = data.with_mounts({name: Mount(parent) for name, parent in mounts})
    used = list(dict.fromkeys(g.camera for g in data.groups("pixels")))
    for frame, file in given:
        if frame not in used:
            has = (
                f"the camera frames of its 'pixels' observations: {', '.join(used)}"
                if used
                else "it has no 'pixels' observations"
            )
            raise DatasetError(
                f"--camera {frame}={file}: no observation of {path} uses camera frame "
                f"{frame!r} ({has})"
            )
    if not getattr(args, "keep_duplicates", True):
        data = drop_duplicate_samples(data)
    return data


def camera_inputs(args: argparse.Namespace) -> dict[str, Path]:
    """The ``--camera FRAME=FILE`` files, keyed ``--camera FRAME=`` (inputs an output must
    not overwrite, named for the message)."""
    given = getattr(args, "camera", None)
    if not isinstance(given, list):  # detect's --camera is one file, checked by detect_inputs
        return {}
    return {f"--camera {frame}=": file for frame, file in given}
