"""The calibration pipeline: stage 1 (kinematics) then stage 2 (cameras), as the data allows.

This is the Python API behind ``kinfw calibrate``::

    from kinfw import load_robot, read_measurements
    from identification.pipeline import calibrate

    result = calibrate(load_robot("nominal.urdf"), read_measurements("data.json"))
    open("calibrated.urdf", "w").write(result.urdf_xml)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from identification.cameras import CamerasResult, calibrate_cameras
from identification.closed_form import ClosedFormResult, identify_closed_form
from kinfw.measurements import DatasetError, Measurements
from kinfw.robot import Robot
from kinfw.transforms import average_transform
from kinfw.urdf_export import ExportResult, edit_urdf, export_urdf

__all__ = ["Calibration", "calibrate"]


@dataclass(frozen=True, slots=True)
class Calibration:
    """A calibrated URDF and the stages that produced it.

    Attributes
    ----------
    urdf_xml : str
        The calibrated URDF: the nominal one with only joint origins and axes changed.
    closed_form : ClosedFormResult or None
        Stage 1, when the data has ``pose`` observations in the root frame.
    export : ExportResult or None
        Stage 1's export (measurement-frame pose, moved link frames).
    cameras : CamerasResult or None
        Stage 2, when the data has ``target`` observations.
    """

    urdf_xml: str
    closed_form: ClosedFormResult | None
    export: ExportResult | None
    cameras: CamerasResult | None


def calibrate(nominal: Robot, data: Measurements) -> Calibration:
    """Run the stages the data supports on the nominal robot.

    Stage 1 (Shih et al. section 4, :func:`identify_closed_form`) runs when the data has
    ``pose`` observations in the root frame and rewrites the joints on their paths;
    stage 2 (section 5, :func:`calibrate_cameras`) runs when it has ``target``
    observations, on the stage-1 kinematics or, without stage-1 data, on the nominal
    URDF's (trusted), and rewrites each camera's fixed mount.

    Raises
    ------
    DatasetError
        When the data supports neither stage, or a stage refuses it (with the reason).
    """
    closed_form = export = cameras = None
    xml = nominal.urdf_xml
    if any(g.marker is None and g.measured_in is None for g in data.poses):
        closed_form = identify_closed_form(nominal, data)
        export = export_urdf(nominal, closed_form.geometry)
        xml = export.urdf_xml
    if data.targets:
        cameras = calibrate_cameras(Robot(xml, nominal.source), data)
        mounts: dict[str, list[np.ndarray]] = {}
        for c in cameras.cameras:  # a camera that saw several targets: average its mounts
            mounts.setdefault(c.joint, []).append(c.hand_T_camera)
        xml = edit_urdf(xml, joint_origins={joint: average_transform(np.stack(poses))
                                            for joint, poses in mounts.items()})
    if closed_form is None and cameras is None:
        raise DatasetError(
            f"{data.source}: nothing to calibrate: the closed form needs 'pose' observations "
            "in the root frame (stage 1) and the hand-eye step 'target' observations (stage 2)")
    return Calibration(xml, closed_form, export, cameras)
