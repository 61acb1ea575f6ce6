"""Start values of a least-squares problem, in closed form.

The start model's poses at the samples (:func:`start_context`), the model moved into an
external measurement frame (:func:`express_in`), and every unknown block's start value
from the observation kinds' estimators (:func:`estimate_unknowns`): the one place where
start values are computed, for the calibration and for ``kinfw verify`` alike.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from kinfw.geometry import (
    average_transform,
    matrix_from_rotation_vector,
    project_to_rotation,
    rotation_vector_from_matrix,
    skew,
)
from kinfw.measurements import Measurements
from kinfw.model import Block, BlockKey, CPCModel, RigidFrameBlock
from kinfw.observations import DatasetError, StartContext, kind_of


def start_context(
    model: CPCModel, q_all: NDArray, meas_T_w: dict[str, NDArray], model_frame: str | None
) -> StartContext:
    """The kinds' start context: ``model``'s frame poses at ``q_all`` and the external
    frames' start poses ``meas_T_w``."""
    # q_all is (n, J): frame_poses keeps the batch axis, (n, E, 4, 4)
    return StartContext(model.frame_poses(q_all), model.topology.frames, meas_T_w, model_frame)


def express_in(
    model: CPCModel,
    measurements: Measurements,
    q_all: NDArray,
    name: str,
    meas_T_root: NDArray | None = None,
) -> CPCModel:
    """The model moved into the external frame ``name`` by ``name_T_root``: given, or a
    closed-form estimate (the kinds' root-pose estimates averaged, or, when the frame is
    seen only through points and markers, :func:`frame_from_markers`)."""
    from kinfw.model import ZeroGeometry, cpc_from_geometry, geometry_from_cpc

    groups = [g for g in measurements.all_groups() if kind_of(g).measured_in(g) == name]
    if meas_T_root is None:
        start = start_context(model, q_all, {}, None)
        est = [e for g in groups if (e := kind_of(g).root_pose_estimates(g, start)) is not None]
        if est:
            meas_T_root = average_transform(np.concatenate(est))
        else:
            meas_T_root = _from_markers(groups, start, name, measurements.source)
    geo = geometry_from_cpc(model)
    R, p = meas_T_root[:3, :3], meas_T_root[:3, 3]
    moved = ZeroGeometry(
        geo.topology, geo.axes @ R.T, geo.points @ R.T + p, meas_T_root @ geo.w_T_frames
    )
    return cpc_from_geometry(moved, sign=model.sign)


def _from_markers(groups: list[Any], start: StartContext, name: str, source: str) -> NDArray:
    """``name_T_w`` from the groups' marker tracks (:func:`frame_from_markers`); a clear
    error when the groups have none."""
    tracks = [t for g in groups if (t := kind_of(g).marker_tracks(g, start)) is not None]
    if not tracks:
        raise DatasetError(
            f"{source}: frame {name!r} is observed through nothing that places it (no "
            "marker-free pose, no point or marker); give some observations of the robot in it"
        )
    return frame_from_markers(tracks, name, source)


def estimate_unknowns(
    measurements: Measurements,
    groups: list[Any],
    model0: CPCModel,
    q_all: NDArray,
    model_frame: str | None,
    given: dict[BlockKey, NDArray],
) -> tuple[list[Block], list[tuple[BlockKey, str]]]:
    """Every unknown block with its start value, in closed form (or as ``given``).

    External measurement frames first (from the kinds' root-pose estimates; a
    ``measured_in`` that is an end frame of ``model0`` is a robot frame, no unknown), then the
    blocks the groups request (:meth:`ObservationKind.unknowns`), merged by key. Returns
    the blocks and a description of each one estimated from these data.
    """
    # the frames' poses once for both contexts (only the external frames differ)
    start = start_context(model0, q_all, {}, model_frame)
    blocks: list[Block] = []
    fitted: list[tuple[BlockKey, str]] = []
    meas_T_w: dict[str, NDArray] = {}
    # a measured_in that is a frame of the model moves with the robot: not an unknown
    external = sorted(
        {kind_of(g).measured_in(g) for g in groups}
        - {None, model_frame}
        - set(model0.topology.frames)
    )
    for name in external:
        key = BlockKey("frame", name)
        if key in given:
            meas_T_w[name] = np.asarray(given[key], dtype=float)
        else:
            est = [
                e
                for g in groups
                if kind_of(g).measured_in(g) == name
                and (e := kind_of(g).root_pose_estimates(g, start)) is not None
            ]
            if est:
                meas_T_w[name] = average_transform(np.concatenate(est))
                how = f"from {sum(map(len, est))} poses"
            else:
                mine = [g for g in groups if kind_of(g).measured_in(g) == name]
                meas_T_w[name] = _from_markers(mine, start, name, measurements.source)
                how = "with the markers' offsets, lifted linear least squares"
            fitted.append((key, f"pose of the root link in {name!r} ({how})"))
        blocks.append(RigidFrameBlock(key, start=meas_T_w[name]))
    start = start.with_frames(meas_T_w)
    requests: dict[BlockKey, list[Any]] = {}
    for g in groups:
        for req in kind_of(g).unknowns(g, start):
            requests.setdefault(req.key, []).append(req)
    for key, reqs in requests.items():
        if key in given:
            value = np.asarray(given[key], dtype=float)
            blocks.append(reqs[0].block(key, value[None]))
        else:
            blocks.append(reqs[0].block(key, np.concatenate([r.estimates for r in reqs])))
            fitted.append((key, reqs[0].description))
    return blocks, fitted


# -- an external frame seen only through markers: W and the offsets together --------------
#
# A marker k on frame f is measured in the external frame as p_i = W T_i m_k (homogeneous),
# with W = meas_T_w = [R | t] and the offset m_k unknown, T_i = [R_i | t_i] the start
# model's pose of f at sample i. Multiplied by W^-1 = [S | s] (S = R^T, s = -R^T t):
#
#     S p_i + s - R_i m_k = t_i                                             (lifted, linear)
#
# linear in the 12 entries of [S | s] and the 3 of each m_k (a known offset o moves R_i o
# to the right-hand side): 3 equations per observation, 12 + 3K unknowns, solved by linear
# least squares with no start. S is then projected onto SO(3) (the nearest rotation), t and
# the offsets re-solved linearly given R, and all of (R, t, m_k) refined by Gauss-Newton on
# the original residual p_i - W T_i m_k (a pose-marker's rotation adds R_A = R R_i R_X).
# When the points are coplanar the lifted system loses rank (S + v n^T absorbs n.p = c);
# then the equivalent forward lifting p_i = sum_jk R_i[j,k] Z_k[:, j, k] + R t_i + t with
# Z_k = R m_k^T per column (27 + 12 unknowns per marker, rows decoupled) is tried. The
# determinacy verdict is the Gauss-Newton Jacobian's rank at the solution: a null vector
# names the quantities the data leave undetermined.

MARKER_RANK_TOL = 1e-7
"""Relative singular value (columns scaled to unit norm) below which a direction of the
marker start problem counts as undetermined."""


def _lifted_inverse(tracks, labels):
    """The lifted linear solve ``S p + s - R_i m = t_i``: (R, t) or None (rank lost)."""
    K = len(labels)
    rows, rhs = [], []
    for T, p, offset, _, label in tracks:
        n = len(T)
        A = np.zeros((n, 3, 12 + 3 * K))
        for a in range(3):
            A[:, a, 3 * a : 3 * a + 3] = p
            A[:, a, 9 + a] = 1.0
        b = T[:, :3, 3].copy()
        if offset is None:
            k = labels.index(label)
            A[:, :, 12 + 3 * k : 15 + 3 * k] = -T[:, :3, :3]
        else:
            b += T[:, :3, :3] @ offset
        rows.append(A.reshape(3 * n, -1))
        rhs.append(b.reshape(-1))
    A, b = np.concatenate(rows), np.concatenate(rhs)
    if A.shape[0] < A.shape[1] or not _full_rank(A):
        return None
    x = np.linalg.lstsq(A, b, rcond=None)[0]
    R = project_to_rotation(x[:9].reshape(3, 3)).T
    return R, -R @ x[9:12]


def _lifted_forward(tracks, labels):
    """The forward lifting ``p = sum R_i[j,k] Z[:, j, k] + R t_i + t``: (R, t) or None."""
    K = len(labels)
    rows, rhs = [], []
    for T, p, offset, _, label in tracks:
        n = len(T)
        A = np.zeros((n, 12 + 9 * K))  # per output row a: R[a,:], t[a], Z_k[a] (9 each)
        v = T[:, :3, 3] if offset is None else T[:, :3, :3] @ offset + T[:, :3, 3]
        A[:, :3], A[:, 3] = v, 1.0
        if offset is None:
            k = labels.index(label)
            A[:, 4 + 9 * k : 13 + 9 * k] = T[:, :3, :3].reshape(n, 9)
        rows.append(A[:, : 4 + 9 * K])
        rhs.append(p)
    A, b = np.concatenate(rows), np.concatenate(rhs)
    if A.shape[0] < A.shape[1] or not _full_rank(A):
        return None
    x = np.linalg.lstsq(A, b, rcond=None)[0]  # (4 + 9K, 3): one column per output row
    R = project_to_rotation(x[:3].T)
    return R, x[3]


def _full_rank(A):
    scale = np.linalg.norm(A, axis=0)
    if np.any(scale == 0.0):
        return False
    s = np.linalg.svd(A / scale, compute_uv=False)
    return s[-1] > MARKER_RANK_TOL * s[0]


def _marker_values(tracks, labels, R, t):
    """Given W = [R | t], every unknown offset by linear least squares (the mean of
    ``R_i^T (R^T (p_i - t) - t_i)``) and every pose marker's rotation (chordal mean)."""
    offsets, rotations = {}, {}
    for label in labels:
        est = [
            np.einsum("nji,nj->ni", T[:, :3, :3], (p - t) @ R - T[:, :3, 3])
            for T, p, offset, _, lab in tracks
            if lab == label and offset is None
        ]
        offsets[label] = np.concatenate(est).mean(axis=0)
        rot = [
            np.swapaxes(T[:, :3, :3], 1, 2) @ R.T @ RA
            for T, _, offset, RA, lab in tracks
            if lab == label and RA is not None
        ]
        if rot:
            rotations[label] = project_to_rotation(np.concatenate(rot).mean(axis=0))
    return offsets, rotations


def _gauss_newton(tracks, labels, R, t, offsets, rotations, iterations=50):
    """Refine (R, t, offsets, rotations) on ``p - W T m`` (and ``log(R_pred^T R_A)``);
    returns them and the Jacobian at the end (columns: W rotation, W translation, then
    3 (offset) + 3 (rotation, pose markers) per label)."""
    cols = {}
    k = 6
    for label in labels:
        cols[label] = k
        k += 3 + (3 if label in rotations else 0)
    P = k
    for _ in range(iterations):
        rs, Js = [], []
        for T, p, offset, RA, label in tracks:
            n = len(T)
            m = offsets[label] if offset is None else offset
            v = T[:, :3, :3] @ m + T[:, :3, 3]
            r = p - (v @ R.T + t)
            J = np.zeros((n, 3, P))
            J[:, :, :3] = R @ skew(v)
            J[:, :, 3:6] = -np.eye(3)
            if offset is None:
                c = cols[label]
                J[:, :, c : c + 3] = -R @ T[:, :3, :3]
            rs.append(r.reshape(-1))
            Js.append(J.reshape(3 * n, P))
            if RA is not None and label in rotations:
                RiX = T[:, :3, :3] @ rotations[label]
                E = np.swapaxes(RiX, 1, 2) @ R.T @ RA
                rho = rotation_vector_from_matrix(E)
                Jr = np.zeros((n, 3, P))
                Jr[:, :, :3] = -np.swapaxes(RiX, 1, 2)
                c = cols[label] + 3
                Jr[:, :, c : c + 3] = -np.eye(3)
                rs.append(rho.reshape(-1))
                Js.append(Jr.reshape(3 * n, P))
        r, J = np.concatenate(rs), np.concatenate(Js)
        dx = np.linalg.lstsq(J, -r, rcond=None)[0]
        R = R @ matrix_from_rotation_vector(dx[:3])
        t = t + dx[3:6]
        for label in labels:
            c = cols[label]
            offsets[label] = offsets[label] + dx[c : c + 3]
            if label in rotations:
                rotations[label] = rotations[label] @ matrix_from_rotation_vector(dx[c + 3 : c + 6])
        if np.linalg.norm(dx) < 1e-14:
            break
    return R, t, offsets, rotations, J, cols


def _undetermined(J, cols, rotations, name, describe):
    """The quantities along the null directions of the column-scaled Jacobian, or ()."""
    scale = np.linalg.norm(J, axis=0)
    scale[scale == 0.0] = 1.0
    # Vt is (P, P) either way; U is never used, so it is built (N, N) only when N < P
    _, s, Vt = np.linalg.svd(J / scale, full_matrices=J.shape[0] < J.shape[1])
    rank = int(np.sum(s > MARKER_RANK_TOL * s[0])) if len(s) and s[0] > 0 else 0
    seen: dict[str, list[NDArray]] = {}  # quantity -> its directions in the null space
    for v in Vt[rank:] / scale:
        parts = [(f"the rotation of {name!r}", v[:3]), (f"the position of {name!r}", v[3:6])]
        for label, c in cols.items():
            parts.append((describe[label], v[c : c + 3]))
            if label in rotations:
                parts.append((f"the rotation of {describe[label][4:]}", v[c + 3 : c + 6]))
        big = max(np.linalg.norm(p) for _, p in parts)
        for what, p in parts:
            if np.linalg.norm(p) > 0.1 * big:
                seen.setdefault(what, []).append(p / np.linalg.norm(p))
    names = []
    for what, dirs in seen.items():
        if len(dirs) == 1:
            d = dirs[0]
            names.append(f"{what} along [{d[0]:.2f}, {d[1]:.2f}, {d[2]:.2f}]")
        else:
            names.append(f"{what} ({min(len(dirs), 3)} directions)")
    return tuple(names)


def frame_from_markers(
    tracks: list[tuple[Any, ...]], name: str, source: str
) -> NDArray[np.float64]:
    """``meas_T_w`` of an external frame ``name`` seen only through markers, points of
    unknown offset or marker poses (see the comment above for the method).

    Parameters
    ----------
    tracks : list of tuples
        ``(w_T_frame (m, 4, 4), meas_p (m, 3), offset (3,) or None, meas_R (m, 3, 3) or
        None, label)`` per group: the start model's poses of the marker's frame in the
        model frame ``w``, the measured positions (metres), the known offset or None,
        the measured rotation of a marker pose, a label shared by the groups of one
        marker (its block key).
    name, source : str
        The frame and the dataset, for the error.

    Raises
    ------
    DatasetError
        When the data leave a direction of the frame or of an offset undetermined
        (too few samples, one configuration, a motion that never turns a direction);
        the message names those quantities.
    """
    labels = list(dict.fromkeys(lab for *_, offset, _, lab in tracks if offset is None))
    describe = {
        lab: f"the offset of {lab.name!r}" if lab.kind == "offset" else f"the marker {lab.name!r}"
        for lab in labels
    }
    tracks = [(np.asarray(T), np.asarray(p), o, RA, lab) for T, p, o, RA, lab in tracks]
    n_obs = sum(len(T) for T, *_ in tracks)
    poses = [(T, p, RA) for T, p, o, RA, _ in tracks if RA is not None]
    start = None
    if poses:  # a marker pose: A = X B Y (Hirsh) on its largest group
        from kinfw.identification.handeye import solve_axyb

        T, p, RA = max(poses, key=lambda x: len(x[0]))
        A = np.zeros((len(T), 4, 4))
        A[:, :3, :3], A[:, :3, 3], A[:, 3, 3] = RA, p, 1.0
        if len(T) >= 3:
            try:
                # A = X B Y with camera = meas, hand = w, base = frame, target = marker
                res = solve_axyb(camera_T_targets=A, hand_T_bases=T)
                start = res.camera_T_hand[:3, :3], res.camera_T_hand[:3, 3]
            except (ValueError, np.linalg.LinAlgError):
                start = None
    if start is None:
        start = _lifted_inverse(tracks, labels) or _lifted_forward(tracks, labels)
    if start is None:
        start = (np.eye(3), np.zeros(3))  # the Jacobian's rank gives the verdict below
    R, t = start
    offsets, rotations = _marker_values(tracks, labels, R, t)
    R, t, offsets, rotations, J, cols = _gauss_newton(tracks, labels, R, t, offsets, rotations)
    undetermined = _undetermined(J, cols, rotations, name, describe)
    if undetermined or not np.all(np.isfinite(R)):
        raise DatasetError(
            f"{source}: frame {name!r} is seen only through markers or points of unknown "
            f"offset, and these {n_obs} observations do not determine "
            + "; ".join(undetermined or (f"the pose of {name!r}",))
            + " (measure more configurations, turning every joint)"
        )
    W = np.eye(4)
    W[:3, :3], W[:3, 3] = R, t
    return W
