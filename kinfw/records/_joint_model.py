"""The per-joint YAML of what a calibrated URDF cannot hold: ``CALIBRATED.joints.yaml``.

``kinfw calibrate --model ...`` writes it beside the calibrated URDF and its sidecar, for
controllers and vendor tools that take a joint's stiffness, gear scale or coupling (the
sidecar holds the same, :attr:`kinfw.records.CalibrationSidecar.robot_blocks`, for
kinfw to re-apply)::

    format: kinfw-joint-model
    version: 1
    urdf: calibrated.urdf
    joints:
      shoulder_lift_joint:
        compliance: {value: 5.0e-06, std: 2.1e-08, unit: rad/Nm}
        stiffness: {value: 200000.0, std: 840.0, unit: Nm/rad}
      tilt:
        gear_scale: {value: 0.003, std: 1.0e-05, unit: unitless}

A compliance's stiffness is its inverse, its sigma ``std_c / c^2`` (first order); a joint
that gravity does not load in the data is listed with compliance 0 and std 0 (not
estimated) and no stiffness.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from kinfw.records._records import RobotBlockRecord

FORMAT = "kinfw-joint-model"


def _stiffness_unit(unit: str) -> str | None:
    """``rad/Nm`` -> ``Nm/rad``, ``m/N`` -> ``N/m``; None for another unit."""
    per = {"rad/Nm": "Nm/rad", "m/N": "N/m"}
    return per.get(unit)


def joint_model_doc(records: Sequence[RobotBlockRecord], urdf: str | Path) -> dict[str, Any]:
    """The document of :mod:`this module <kinfw.records>`'s format for the calibrated blocks
    ``records`` of the URDF file ``urdf``: per joint (the entries' owners) each field's
    value, standard deviation and unit."""
    joints: dict[str, dict[str, Any]] = {}
    for r in records:
        for name, unit, value, std in zip(r.names, r.units, r.values, r.std, strict=True):
            owner, _, field = name.partition(":")
            entry = joints.setdefault(owner, {})
            entry[field] = {"value": float(value), "std": float(std), "unit": unit}
            stiff = _stiffness_unit(unit)
            if stiff is not None and value > 0:
                entry["stiffness"] = {
                    "value": 1.0 / float(value),
                    "std": float(std) / float(value) ** 2,
                    "unit": stiff,
                }
    return {"format": FORMAT, "version": 1, "urdf": Path(urdf).name, "joints": joints}


def joint_model_text(records: Sequence[RobotBlockRecord], urdf: str | Path) -> str:
    """:func:`joint_model_doc` as YAML text."""
    import yaml

    return yaml.safe_dump(joint_model_doc(records, urdf), sort_keys=False)


def joint_model_path(urdf_path: str | Path) -> Path:
    """Where the per-joint YAML of the calibrated URDF ``urdf_path`` goes:
    ``<stem>.joints.yaml`` beside it."""
    return Path(urdf_path).with_suffix(".joints.yaml")
