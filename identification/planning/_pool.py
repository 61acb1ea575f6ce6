"""The candidate pool of measurement planning, and its constraints.

:func:`candidate_pool` takes the user's recorded joint states or random configurations
inside the joint limits and keeps those that satisfy the constraints: the target in view
of a camera (the visibility rules of :func:`kinfw.simulation.visible_points`),
the measured frames facing the tracker, and optionally no self-collision
(:func:`collision_free`). :mod:`kinfw.identification.planning` chooses the configurations from it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import inverse_transform
from kinfw.identification.planning._objective import Setup
from kinfw.model import Robot, mesh_dirs, resolve_meshes
from kinfw.simulation import random_configurations


@dataclass(frozen=True, eq=False)
class Pool:
    """Candidate configurations after the constraints, and how many each dropped."""

    qs: NDArray[np.float64]
    dropped: dict[str, int] = field(default_factory=dict)


def _visible(robot, setup, qs, names, w_T_target) -> NDArray[np.bool_]:
    from kinfw.simulation import visible_points

    board_p = setup.board_points()
    seen = np.zeros(len(qs), bool)
    for camera, intr in setup.camera_intrinsics().items():
        c_T_b = inverse_transform(robot.frame_poses(qs, camera, names)) @ w_T_target
        seen |= visible_points(intr, c_T_b, board_p).any(axis=1)
    return seen


def _facing(robot, setup, qs, names) -> NDArray[np.bool_]:
    ok = np.ones(len(qs), bool)
    cos_max = np.cos(np.radians(setup.max_facing_deg))
    for frame in setup.frames:
        T = robot.frame_poses(qs, frame, names)
        d = np.asarray(setup.tracker_p, float) - T[:, :3, 3]
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        ok &= np.einsum("ni,ni->n", d, T[:, :3, 2]) >= cos_max
    return ok


def collision_free(
    robot: Robot, qs: ArrayLike, names, package_dirs: Sequence[str | Path] = ()
) -> NDArray[np.bool_]:
    """Which configurations are free of self-collision (Pinocchio + coal/hpp-fcl).

    Pairs that cannot tell a collision are left out, as MoveIt's setup assistant does:
    geometries on one joint's link or on adjacent links (touching at their joint), and
    pairs already in contact at the middle of the joint ranges (overlapping meshes).

    Parameters
    ----------
    robot : Robot
    qs : array_like, shape (N, J)
        Joint values of ``names``.
    names : sequence of str
    package_dirs : sequence of path
        Where the collision meshes' ``package://`` paths live
        (:func:`kinfw.model.resolve_meshes`).

    Raises
    ------
    ValueError
        The check cannot be made as asked: the URDF has no collision geometry, a
        collision mesh is not found (each named, with where it was looked for), or the
        collision library is missing. A check that silently did nothing would pass
        colliding configurations.
    """
    import pinocchio as pin

    if "<collision" not in robot.urdf_xml:
        raise ValueError(
            f"{robot.source}: no <collision> geometry in the URDF: self-collision cannot be "
            "checked (drop --collisions, or use a URDF with collision geometry)"
        )
    xml, missing = resolve_meshes(robot, package_dirs, "collision")
    if missing:
        names_missing = ", ".join(f"{m.filename} (link {m.link!r})" for m in missing[:3])
        more = f" and {len(missing) - 3} more" if len(missing) > 3 else ""
        searched = [str(d) for d in mesh_dirs(package_dirs)] or "no package directories"
        raise ValueError(
            f"{robot.source}: {len(missing)} collision mesh(es) not found: {names_missing}"
            f"{more} (searched {searched}); give --package-dir DIR where the packages live"
        )
    try:
        geom = pin.buildGeomFromUrdfString(robot.model, xml, pin.COLLISION)
        geom.addAllCollisionPairs()
        data, gdata = robot.model.createData(), pin.GeometryData(geom)
    except Exception as exc:  # no coal/hpp-fcl, or a mesh that cannot be read
        raise ValueError(
            f"{robot.source}: self-collision cannot be checked ({exc}); drop --collisions"
        ) from None
    parents = robot.model.parents
    lower, upper = robot.joint_limits(tuple(names))
    middle = robot.pin_configurations((0.5 * (lower + upper))[None], tuple(names))[0]
    pin.computeCollisions(robot.model, data, geom, gdata, middle, False)
    for k in reversed(range(len(geom.collisionPairs))):
        pair = geom.collisionPairs[k]
        a = geom.geometryObjects[pair.first].parentJoint
        b = geom.geometryObjects[pair.second].parentJoint
        if a == b or parents[a] == b or parents[b] == a or gdata.collisionResults[k].isCollision():
            geom.removeCollisionPair(pair)
    gdata = pin.GeometryData(geom)
    full = robot.pin_configurations(np.atleast_2d(qs), tuple(names))
    ok = np.empty(len(full), bool)
    for k, q in enumerate(full):
        ok[k] = not pin.computeCollisions(robot.model, data, geom, gdata, q, True)
    return ok


def candidate_pool(
    robot: Robot,
    setup: Setup,
    joint_names: Sequence[str],
    w_T_target: NDArray | None,
    *,
    qs: ArrayLike | None = None,
    within_limits: float | None = None,
    n: int = 1000,
    rng: np.random.Generator | None = None,
    collisions: bool = False,
    package_dirs: Sequence[str | Path] = (),
) -> Pool:
    """The candidate configurations: ``qs`` (recorded joint states) or ``n`` random
    configurations in the centred ``within_limits`` fraction of each joint range, kept
    when inside the joint limits, the board is seen (stage 2), the frames face the
    tracker (``setup.tracker_p``) and, with ``collisions``, free of self-collision
    (:func:`collision_free`, its meshes under ``package_dirs``)."""
    lower, upper = robot.joint_limits(joint_names)
    if qs is None:
        if within_limits is None or rng is None:
            raise ValueError("candidate_pool: give qs, or within_limits and rng")
        qs = random_configurations(lower, upper, n, rng, fraction=within_limits)
    qs = np.atleast_2d(np.asarray(qs, dtype=float))
    dropped = {}
    keep = np.all((qs >= lower - 1e-9) & (qs <= upper + 1e-9), axis=1)
    dropped["outside the joint limits"] = int((~keep).sum())
    if setup.cameras:
        seen = _visible(robot, setup, qs, joint_names, w_T_target)
        dropped["board not seen"] = int((keep & ~seen).sum())
        keep &= seen
    if setup.frames and setup.tracker_p is not None:
        facing = _facing(robot, setup, qs, joint_names)
        dropped["not facing the tracker"] = int((keep & ~facing).sum())
        keep &= facing
    if collisions:
        free = collision_free(robot, qs, joint_names, package_dirs)
        dropped["self-collision"] = int((keep & ~free).sum())
        keep &= free
    return Pool(qs[keep], {k: v for k, v in dropped.items() if v})
