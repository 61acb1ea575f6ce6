"""Argument types and options shared by the ``kinfw`` command parsers, and reading what
the options name: checked numbers, ``--camera FRAME=FILE``, ``--frames``, ``--payload
FRAME:MASS_KG[:CX,CY,CZ]`` and ``--gravity``, the measurement file with its ``--camera``
intrinsics and the calibration sidecar's path.

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
    from kinfw.model import PriorScale, Robot


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


def prior_scale_arg(text: str) -> PriorScale:
    """``--prior GROUP=VALUE UNIT`` (:meth:`kinfw.model.PriorScale.parse`)."""
    from kinfw.model import PriorScale

    try:
        return PriorScale.parse(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("prior: ")) from None


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


#: The form of ``--payload``.
PAYLOAD_FORM = "FRAME:MASS_KG[:CX,CY,CZ]"


def parse_payload(text: str) -> tuple[str, float, tuple[float, float, float]]:
    """``FRAME:MASS_KG[:CX,CY,CZ]`` of ``--payload``: a load of ``MASS_KG`` kg (>= 0)
    fixed to the URDF frame ``FRAME``, its centre of mass at ``CX,CY,CZ`` in that frame.

    Returns
    -------
    frame : str
    mass_kg : float
    com : tuple of 3 floats
        The centre of mass in ``FRAME``, in the command's length unit: metres unless the
        command has a ``--length-unit`` (default the frame's origin, ``(0, 0, 0)``).

    Raises
    ------
    argparse.ArgumentTypeError
        Naming the expected form (argparse adds the option).
    """
    parts = text.split(":")
    frame = parts[0].strip()
    if len(parts) not in (2, 3) or not frame:
        raise argparse.ArgumentTypeError(
            f"expected {PAYLOAD_FORM} (e.g. tool0:5 or tool0:5:0,0,0.08), got {text!r}"
        )
    try:
        mass_kg = float(parts[1])
    except ValueError:
        mass_kg = math.nan
    if not (math.isfinite(mass_kg) and mass_kg >= 0):
        raise argparse.ArgumentTypeError(
            f"expected {PAYLOAD_FORM} with MASS_KG a number >= 0 (kg), got {parts[1]!r} in {text!r}"
        )
    com = (0.0, 0.0, 0.0)
    if len(parts) == 3:
        try:
            values = [float(v) for v in parts[2].split(",")]
        except ValueError:
            values = []
        if len(values) != 3 or not all(map(math.isfinite, values)):
            raise argparse.ArgumentTypeError(
                f"expected {PAYLOAD_FORM} with CX,CY,CZ three numbers separated by commas, "
                f"got {parts[2]!r} in {text!r}"
            )
        com = (values[0], values[1], values[2])
    return frame, mass_kg, com


def add_payload_options(p: argparse.ArgumentParser, *, com_unit: str = "metres") -> None:
    """``--payload FRAME:MASS_KG[:CX,CY,CZ]`` and ``--gravity GX GY GZ``: what every sample
    of the file a command writes carries, and gravity (:func:`with_payload`)."""
    p.add_argument(
        "--payload",
        type=parse_payload,
        default=None,
        metavar=PAYLOAD_FORM,
        help=f"every sample carries MASS_KG kg fixed to the URDF frame FRAME, its centre of "
        f"mass at CX,CY,CZ in FRAME ({com_unit}; default the frame's origin); written as "
        "each sample's payload",
    )
    p.add_argument(
        "--gravity",
        nargs=3,
        type=number(float),
        default=None,
        metavar=("GX", "GY", "GZ"),
        help="gravity in the URDF root frame, m/s^2 (default 0 0 -9.81); written to the file",
    )


def with_payload(measurements: Any, args: argparse.Namespace, length_unit: str = "m") -> Any:
    """``measurements`` with ``--payload`` on every sample (its centre of mass in
    ``length_unit``, "m" or "mm") and ``--gravity``; a ValueError naming ``--gravity``
    when its norm is not one of gravity."""
    from dataclasses import replace

    from kinfw.model import Payloads
    from kinfw.observations import DatasetError

    changes: dict[str, Any] = {}
    if args.payload is not None:
        frame, mass_kg, com = args.payload
        scale = 1e-3 if length_unit == "mm" else 1.0
        changes["payloads"] = Payloads.constant(
            measurements.n_samples, frame, mass_kg, [scale * c for c in com]
        )
    if args.gravity is not None:
        changes["gravity"] = args.gravity
    try:
        return replace(measurements, **changes)
    except DatasetError as exc:
        given = " ".join(f"{g:g}" for g in args.gravity)
        reason = str(exc).removeprefix(f"{measurements.source}: ")
        raise ValueError(f"--gravity {given}: {reason}") from None


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
    robot = load_robot(path, xacro_args=xacro_args)
    return robot if getattr(args, "no_sidecar", False) else _with_sidecar_spec(robot, Path(path))


def _with_sidecar_spec(robot: Robot, path: Path) -> Robot:
    """``robot`` with the model spec of the calibration sidecar beside its URDF
    (``<stem>.kinfw.json``: compliance, gear scales...), when there is one that records
    robot blocks; the sidecar must be this URDF's (its SHA-256)."""
    from kinfw.files import sidecar_path
    from kinfw.records import read_sidecar

    side = sidecar_path(path)
    if not side.is_file():
        return robot
    sidecar = read_sidecar(side)
    if not sidecar.robot_blocks:
        return robot
    return robot.with_spec(sidecar.check_urdf(path).spec())


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


def add_model_option(p: argparse.ArgumentParser) -> None:
    """``--model SPEC`` (repeatable): robot blocks the URDF cannot hold, estimated with
    it (:func:`model_arg` reads them)."""
    p.add_argument(
        "--model",
        action="append",
        default=[],
        metavar="SPEC",
        help="what the URDF cannot hold, estimated with it (repeatable): compliance "
        "(joint compliance under gravity and payload, rad/Nm; compliance:J1,J2 for some "
        "joints), gear-scale:JOINT, coupling:JOINT=K*OTHER (K fixed; ?K or ? estimated), "
        "or a JSON/YAML file listing such specs; recorded in the sidecar, so verify, view, "
        "reach and export re-apply it",
    )


def model_arg(args: argparse.Namespace) -> Any:
    """The :class:`kinfw.model.ModelSpec` of ``--model`` (None when not given): each
    entry a spec text or a JSON/YAML file holding a list of them (or ``{"model":
    [...]}``)."""
    from kinfw.model import ModelSpec

    entries = getattr(args, "model", None) or []
    if not entries:
        return None
    texts: list[str] = []
    for entry in entries:
        path = Path(entry)
        if path.suffix.lower() in (".json", ".yaml", ".yml"):
            texts += _model_file(path)
        else:
            texts.append(entry)
    return ModelSpec.parse(texts)


def _model_file(path: Path) -> list[str]:
    """The spec texts of a model file (JSON or YAML: a list, or ``{"model": [...]}``)."""
    import yaml

    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ValueError(f"--model {path}: model file not found") from None
    except yaml.YAMLError as exc:
        raise ValueError(f"--model {path}: not JSON or YAML ({str(exc).splitlines()[0]})") from None
    if isinstance(doc, dict) and set(doc) == {"model"}:
        doc = doc["model"]
    if not isinstance(doc, list) or not all(isinstance(t, str) for t in doc):
        raise ValueError(
            f"--model {path}: expected a list of specs (compliance, gear-scale:JOINT, ...) "
            'or {"model": [...]}'
        )
    return doc


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
