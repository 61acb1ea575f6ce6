"""A hand-eye calibration as a user keeps it (``kinfw handeye --out``): the camera's
mount for either setup, its covariance and what was used, written to and read from a
YAML or JSON file.

Setups
------
``eye-in-hand``
    The camera is on the hand, the target fixed in the world: the camera's *mount* is
    the hand (``hand_T_camera``) and the target's *holder* is the base
    (``base_T_target``).
``eye-to-hand``
    The camera is fixed in the world, the target on the hand: the mount is the base
    (``base_T_camera``), the holder the hand (``hand_T_target``). It is the solvers'
    equation with base and hand exchanged (:func:`solver_hand_poses`).

In both, at every pose ``i``:
``holder_T_target = solver_hand_poses[i] @ mount_T_camera @ camera_T_targets[i]``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import check_transform, inverse_transform

#: The setups, and the frames (mount of the camera, holder of the target) of each.
SETUPS = {"eye-in-hand": ("hand", "base"), "eye-to-hand": ("base", "hand")}
#: The ``format`` key of a calibration file; its ``version`` is 1.
HANDEYE_FORMAT = "kinfw-handeye"


def solver_hand_poses(base_T_hands: ArrayLike, setup: str) -> NDArray[np.float64]:
    """The poses to give the solvers as ``base_T_hands``: the hand's poses in the base
    (eye-in-hand) or their inverses, ``hand_T_base`` (eye-to-hand), shape (n, 4, 4)."""
    if setup not in SETUPS:
        raise ValueError(f"setup {setup!r} is not one of {', '.join(SETUPS)}")
    T = np.asarray(base_T_hands, dtype=float)
    return T if setup == "eye-in-hand" else inverse_transform(T)


@dataclass(frozen=True, slots=True)
class HandEyeCalibration:
    """The result of a hand-eye calibration, as written by ``kinfw handeye --out``.

    Attributes
    ----------
    setup : str
        ``"eye-in-hand"`` or ``"eye-to-hand"`` (:data:`SETUPS`).
    mount_T_camera : ndarray, shape (4, 4)
        Pose of the camera in its mount frame (the hand eye-in-hand, the robot's base
        eye-to-hand), metres.
    holder_T_target : ndarray, shape (4, 4)
        Pose of the target in the frame holding it (the base eye-in-hand, the hand
        eye-to-hand), metres.
    covariance : ndarray, shape (6, 6)
        Covariance of ``mount_T_camera``'s error ``(dphi, dt)``: ``dphi`` the rotation
        vector (rad) of ``true = estimate @ exp(dphi)``, in the camera frame; ``dt`` the
        translation error in the mount frame, metres.
    verdict : str
        ``"determined"``, ``"poorly determined"`` or ``"undetermined"``.
    verdict_message : str
        The verdict in words, naming the worst direction when not determined.
    n_samples : int
        Pose pairs given.
    rejected : tuple of int
        Indices (0-based, in the file's order) of the pairs rejected as outliers.
    mount_frame, camera_frame : str
        Names of the mount and camera frames for ROS outputs (TF / URDF names).
    """

    setup: str
    mount_T_camera: NDArray[np.float64]
    holder_T_target: NDArray[np.float64]
    covariance: NDArray[np.float64]
    verdict: str
    verdict_message: str
    n_samples: int
    rejected: tuple[int, ...]
    mount_frame: str
    camera_frame: str

    def __post_init__(self) -> None:
        if self.setup not in SETUPS:
            raise ValueError(f"setup {self.setup!r} is not one of {', '.join(SETUPS)}")
        check_transform(self.mount_T_camera, "mount_T_camera")
        check_transform(self.holder_T_target, "holder_T_target")
        if np.shape(self.covariance) != (6, 6):
            raise ValueError(f"covariance: expected shape (6, 6), got {np.shape(self.covariance)}")

    @property
    def mount_name(self) -> str:
        """``"hand"`` (eye-in-hand) or ``"base"`` (eye-to-hand): the camera's mount."""
        return SETUPS[self.setup][0]

    @property
    def holder_name(self) -> str:
        """``"base"`` (eye-in-hand) or ``"hand"`` (eye-to-hand): the target's holder."""
        return SETUPS[self.setup][1]

    @property
    def sigma_rotation_deg(self) -> NDArray[np.float64]:
        """1-sigma rotation of ``mount_T_camera`` about each camera axis, degrees, (3,)."""
        return np.degrees(np.sqrt(np.diag(self.covariance)[:3]))

    @property
    def sigma_translation_m(self) -> NDArray[np.float64]:
        """1-sigma translation of ``mount_T_camera`` along each mount axis, metres, (3,)."""
        return np.sqrt(np.diag(self.covariance)[3:])

    def to_dict(self) -> dict:
        """The calibration as plain lists and numbers (the file's content)."""
        return {
            "format": HANDEYE_FORMAT,
            "version": 1,
            "setup": self.setup,
            "units": {"length": "m", "angle": "rad"},
            "mount_frame": self.mount_frame,
            "camera_frame": self.camera_frame,
            f"{self.mount_name}_T_camera": np.asarray(self.mount_T_camera).tolist(),
            f"{self.holder_name}_T_target": np.asarray(self.holder_T_target).tolist(),
            "covariance": np.asarray(self.covariance).tolist(),
            "verdict": self.verdict,
            "verdict_message": self.verdict_message,
            "n_samples": self.n_samples,
            "rejected": list(self.rejected),
        }


def handeye_calibration_text(calibration: HandEyeCalibration, fmt: str) -> str:
    """The text of a ``"yaml"`` or ``"json"`` calibration file that
    :func:`read_handeye_calibration` reads back exactly (floats by ``repr``)."""
    data = calibration.to_dict()
    if fmt == "json":
        return json.dumps(data, indent=2) + "\n"
    if fmt == "yaml":
        import yaml

        return yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=120)
    raise ValueError(f"unknown calibration format {fmt!r} (yaml, json)")


def read_handeye_calibration(path: str | Path) -> HandEyeCalibration:
    """Read a calibration file written by ``kinfw handeye --out`` (YAML, or JSON by the
    ``.json`` suffix).

    Raises
    ------
    ValueError
        Not such a file, a version other than 1, a missing key (named), or transforms
        that are not rigid.
    """
    path = Path(path)
    text = path.read_text(encoding="utf-8")
    if path.suffix.lower() == ".json":
        data = json.loads(text)
    else:
        import yaml

        data = yaml.safe_load(text)
    if not isinstance(data, dict) or data.get("format") != HANDEYE_FORMAT:
        raise ValueError(f"{path}: not a {HANDEYE_FORMAT} file (no 'format: {HANDEYE_FORMAT}')")
    if data.get("version") != 1:
        raise ValueError(f"{path}: version {data.get('version')!r}; this kinfw reads version 1")
    try:
        mount, holder = SETUPS[data["setup"]]
        return HandEyeCalibration(
            setup=data["setup"],
            mount_T_camera=np.array(data[f"{mount}_T_camera"], dtype=float),
            holder_T_target=np.array(data[f"{holder}_T_target"], dtype=float),
            covariance=np.array(data["covariance"], dtype=float),
            verdict=data["verdict"],
            verdict_message=data["verdict_message"],
            n_samples=int(data["n_samples"]),
            rejected=tuple(int(i) for i in data["rejected"]),
            mount_frame=data["mount_frame"],
            camera_frame=data["camera_frame"],
        )
    except KeyError as err:
        raise ValueError(f"{path}: missing key {err.args[0]!r}") from None
