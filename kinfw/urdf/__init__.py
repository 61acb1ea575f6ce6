"""Writing a calibrated model back into the robot's own URDF text: every tag kept, joint
origins and axes changed on measured paths, link frames re-expressed so nothing attached
moves (:func:`export_urdf`, :func:`write_urdf`, :func:`edit_urdf`); new links on fixed
joints (:func:`add_fixed_links`); what a calibration changed, joint by joint
(:func:`origin_changes`); and into the files ROS 2 loads: a ``robot_description``
parameter file and launch file (:func:`write_robot_description`) and, for a UR arm,
``ur_description``'s kinematics file (:func:`ur_kinematics_from_robot`,
:func:`ur_kinematics_text`).
"""

from __future__ import annotations

from kinfw.urdf._changes import (
    OriginChange,
    origin_changes,
)
from kinfw.urdf._edit import (
    ExportError,
    add_fixed_links,
    edit_urdf,
)
from kinfw.urdf._export import (
    ExportResult,
    export_urdf,
    write_urdf,
)
from kinfw.urdf._robot_description import (
    ROBOT_DESCRIPTION_FILES,
    robot_description_launch_text,
    robot_description_params_text,
    write_robot_description,
)
from kinfw.urdf._ur import (
    UR_JOINTS,
    URKinematics,
    ur_kinematics_from_dh,
    ur_kinematics_from_robot,
    ur_kinematics_text,
)

__all__ = [
    "ROBOT_DESCRIPTION_FILES",
    "UR_JOINTS",
    "ExportError",
    "ExportResult",
    "OriginChange",
    "URKinematics",
    "add_fixed_links",
    "edit_urdf",
    "export_urdf",
    "origin_changes",
    "robot_description_launch_text",
    "robot_description_params_text",
    "ur_kinematics_from_dh",
    "ur_kinematics_from_robot",
    "ur_kinematics_text",
    "write_robot_description",
    "write_urdf",
]
