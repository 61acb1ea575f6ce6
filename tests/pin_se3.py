"""SE(3) helpers and forward kinematics for the tests, computed with Pinocchio (independent of
:mod:`kinfw.geometry`, which the solvers use)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray


def rotation(rotvec: ArrayLike) -> NDArray[np.float64]:
    """The rotation matrix of a rotation vector (rad), by ``pin.exp3``."""
    return pin.exp3(np.asarray(rotvec, dtype=float))


def angle(R: ArrayLike) -> float:
    """Rotation angle of a matrix (rad), by ``pin.log3``."""
    return float(np.linalg.norm(pin.log3(np.asarray(R))))


def transform(R: ArrayLike, p: ArrayLike) -> NDArray[np.float64]:
    """4x4 rigid transform from a rotation and a translation."""
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, p
    return T


def inverse(T: ArrayLike) -> NDArray[np.float64]:
    """Inverse of one (4, 4) or a batch (..., 4, 4) of rigid transforms, by ``pin.SE3``."""
    return np.stack([pin.SE3(t).inverse().homogeneous for t in np.reshape(T, (-1, 4, 4))]).reshape(
        np.shape(T)
    )


def random_axis(rng: np.random.Generator) -> NDArray[np.float64]:
    """A uniformly random unit vector."""
    axis = rng.normal(size=3)
    return axis / np.linalg.norm(axis)


def pin_fk(xml: str, joint_names: tuple[str, ...], qs: np.ndarray, frame: str) -> np.ndarray:
    """root_T_frame by Pinocchio directly (framesForwardKinematics), shape (n, 4, 4)."""
    model = pin.buildModelFromXML(xml)
    data = model.createData()
    fid = model.getFrameId(frame, pin.FrameType.BODY)
    assert fid < model.nframes
    out = []
    for q_urdf in np.atleast_2d(qs):
        q = pin.neutral(model)
        for name, value in zip(joint_names, q_urdf, strict=True):
            joint = model.joints[model.getJointId(name)]
            if joint.nq == 2:
                q[joint.idx_q], q[joint.idx_q + 1] = np.cos(value), np.sin(value)
            else:
                q[joint.idx_q] = value
        pin.framesForwardKinematics(model, data, q)
        out.append(data.oMf[fid].homogeneous.copy())
    return np.array(out)
