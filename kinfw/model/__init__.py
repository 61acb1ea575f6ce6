"""The robot model: a URDF robot in Pinocchio (:class:`Robot`, :func:`load_robot`), the tree
CPC model (:class:`CPCModel`; numpy and CasADi forward kinematics), the parameter blocks
an estimation problem is made of (:class:`BlockKey`, :class:`CPCBlock`, ...), and what a
URDF cannot hold: the model spec (:class:`ModelSpec`) of named robot blocks
(:class:`JointComplianceBlock`, :class:`GearScaleBlock`, :class:`JointCouplingBlock`, or a
plugin's: :func:`register_block`), with the payloads and gravity torques they need
(:class:`Payloads`, :func:`gravity_torques`; docs/model.md).
"""

from __future__ import annotations

from kinfw.model._blocks import (
    CPC_KEY,
    BaseBlock,
    Block,
    BlockKey,
    CPCBlock,
    ParameterName,
    PointBlock,
    RigidFrameBlock,
    RobotBlock,
    SpecBlock,
    ZeroOffsetBlock,
)
from kinfw.model._cpc import (
    CPCModel,
    ZeroGeometry,
    cayley_coordinates,
    cpc_from_geometry,
    cpc_from_robot,
    geometry_from_cpc,
    geometry_from_robot,
    perpendicular_basis,
    rotation_from_axis,
)
from kinfw.model._cpc_casadi import cpc_fk_function, cpc_reference_vector
from kinfw.model._joint_blocks import GearScaleBlock, JointComplianceBlock, JointCouplingBlock
from kinfw.model._loads import (
    STANDARD_GRAVITY,
    BlockSamples,
    Payloads,
    gravity_torques,
    massless_links,
)
from kinfw.model._meshes import MissingMesh, mesh_dirs, resolve_meshes
from kinfw.model._model_spec import ModelSpec, block_from_spec, block_names, register_block
from kinfw.model._pose_chain import POSE_CHAIN_JOINTS, pose_chain_joint_values, pose_chain_urdf
from kinfw.model._prior import (
    JOINT_GROUPS,
    PRIOR_GROUPS,
    PriorScale,
    PriorScales,
    prior_groups,
    prior_sigmas,
    spec_prior_mean,
)
from kinfw.model._robot import (
    Robot,
    Topology,
    UnknownFrameError,
    builtin_head_urdf,
    check_robot,
    load_robot,
)
from kinfw.model._urdf_read import (
    MOVABLE_TYPES,
    XACRO_NAMESPACE,
    JointInfo,
    RobotModelError,
    captured_native_stderr,
    check_urdf_xml,
    expand_xacro,
    parse_joints,
    pinocchio_model,
    up_vector,
    xml_text,
)

__all__ = [
    "CPC_KEY",
    "JOINT_GROUPS",
    "MOVABLE_TYPES",
    "POSE_CHAIN_JOINTS",
    "PRIOR_GROUPS",
    "STANDARD_GRAVITY",
    "XACRO_NAMESPACE",
    "BaseBlock",
    "Block",
    "BlockKey",
    "BlockSamples",
    "CPCBlock",
    "CPCModel",
    "GearScaleBlock",
    "JointComplianceBlock",
    "JointCouplingBlock",
    "JointInfo",
    "MissingMesh",
    "ModelSpec",
    "ParameterName",
    "Payloads",
    "PointBlock",
    "PriorScale",
    "PriorScales",
    "RigidFrameBlock",
    "Robot",
    "RobotBlock",
    "RobotModelError",
    "SpecBlock",
    "Topology",
    "UnknownFrameError",
    "ZeroGeometry",
    "ZeroOffsetBlock",
    "block_from_spec",
    "block_names",
    "builtin_head_urdf",
    "captured_native_stderr",
    "cayley_coordinates",
    "check_robot",
    "check_urdf_xml",
    "cpc_fk_function",
    "cpc_from_geometry",
    "cpc_from_robot",
    "cpc_reference_vector",
    "expand_xacro",
    "geometry_from_cpc",
    "geometry_from_robot",
    "gravity_torques",
    "load_robot",
    "massless_links",
    "mesh_dirs",
    "parse_joints",
    "perpendicular_basis",
    "pinocchio_model",
    "pose_chain_joint_values",
    "pose_chain_urdf",
    "prior_groups",
    "prior_sigmas",
    "register_block",
    "resolve_meshes",
    "rotation_from_axis",
    "spec_prior_mean",
    "up_vector",
    "xml_text",
]
