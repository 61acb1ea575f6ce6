"""A (calibrated) URDF as ROS 2 loads a ``robot_description``: ``robot_state_publisher``'s
parameter file and a Python launch file (:func:`write_robot_description`).

- ``robot_description.urdf``: the URDF text itself;
- ``robot_state_publisher.yaml``: ``robot_state_publisher: ros__parameters:
  robot_description: "<robot ...>"`` (``ros2 run robot_state_publisher
  robot_state_publisher --ros-args --params-file robot_state_publisher.yaml``);
- ``robot_description.launch.py``: a ``robot_state_publisher`` node whose
  ``robot_description`` is the URDF file next to the launch file, read at launch.
"""

from __future__ import annotations

from pathlib import Path

from kinfw.files import write_text_atomic

#: The files :func:`write_robot_description` writes, by what they hold.
ROBOT_DESCRIPTION_FILES = {
    "urdf": "robot_description.urdf",
    "params": "robot_state_publisher.yaml",
    "launch": "robot_description.launch.py",
}


def robot_description_params_text(urdf_xml: str, *, node: str = "robot_state_publisher") -> str:
    """A ROS 2 parameter file giving ``node`` the parameter ``robot_description`` =
    ``urdf_xml`` (a YAML string; PyYAML reads it back unchanged)."""
    import yaml

    return yaml.safe_dump(
        {node: {"ros__parameters": {"robot_description": urdf_xml}}},
        sort_keys=False,
        width=float("inf"),
    )


def robot_description_launch_text(urdf_name: str = ROBOT_DESCRIPTION_FILES["urdf"]) -> str:
    """A ROS 2 Python launch file: ``robot_state_publisher`` with the URDF file
    ``urdf_name`` (next to the launch file) as its ``robot_description``."""
    return f'''"""Publish the calibrated robot (written by kinfw export robot-description):
robot_state_publisher with {urdf_name!r}, next to this file, as its robot_description."""

from pathlib import Path

from launch import LaunchDescription
from launch_ros.actions import Node

URDF = Path(__file__).resolve().with_name({urdf_name!r})


def generate_launch_description():
    return LaunchDescription([
        Node(
            package="robot_state_publisher",
            executable="robot_state_publisher",
            name="robot_state_publisher",
            output="screen",
            parameters=[{{"robot_description": URDF.read_text()}}],
        ),
    ])
'''


def write_robot_description(directory: str | Path, urdf_xml: str) -> list[Path]:
    """Write :data:`ROBOT_DESCRIPTION_FILES` into ``directory`` (created if missing),
    each atomically; returns their paths."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    texts = {
        "urdf": urdf_xml,
        "params": robot_description_params_text(urdf_xml),
        "launch": robot_description_launch_text(),
    }
    return [write_text_atomic(directory / ROBOT_DESCRIPTION_FILES[k], t) for k, t in texts.items()]
