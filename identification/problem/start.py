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

from kinfw.blocks import Block, BlockKey, RigidFrameBlock
from kinfw.cpc import CPCModel
from kinfw.measurements import DatasetError, Measurements
from kinfw.observations import StartContext, kind_of
from kinfw.transforms import average_transform

__all__ = ["estimate_unknowns", "express_in", "start_context"]


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
    closed-form estimate (the kinds' root-pose estimates averaged, or their point pairs
    registered)."""
    from kinfw.cpc import ZeroGeometry, cpc_from_geometry, geometry_from_cpc
    from kinfw.registration import register_points

    groups = list(measurements.all_groups())
    if meas_T_root is None:
        start = start_context(model, q_all, {}, None)
        est = [e for g in groups if (e := kind_of(g).root_pose_estimates(g, start)) is not None]
        if est:
            meas_T_root = average_transform(np.concatenate(est))
        else:
            pairs = [p for g in groups if (p := kind_of(g).root_point_pairs(g, start))]
            if not pairs:
                raise DatasetError(
                    f"{measurements.source}: everything is measured in {name!r} through "
                    "markers or points of unknown offset; give at least one point offset "
                    "(or a marker-free pose) so that the frame can be placed"
                )
            meas_T_root = register_points(
                np.concatenate([p[0] for p in pairs]), np.concatenate([p[1] for p in pairs])
            )
    geo = geometry_from_cpc(model)
    R, p = meas_T_root[:3, :3], meas_T_root[:3, 3]
    moved = ZeroGeometry(
        geo.topology, geo.axes @ R.T, geo.points @ R.T + p, meas_T_root @ geo.w_T_frames
    )
    return cpc_from_geometry(moved, sign=model.sign)


def estimate_unknowns(
    measurements: Measurements,
    groups: list[Any],
    model0: CPCModel,
    q_all: NDArray,
    model_frame: str | None,
    given: dict[BlockKey, NDArray],
) -> tuple[list[Block], list[tuple[BlockKey, str]]]:
    """Every unknown block with its start value, in closed form (or as ``given``).

    External measurement frames first (from the kinds' root-pose estimates), then the
    blocks the groups request (:meth:`ObservationKind.unknowns`), merged by key. Returns
    the blocks and a description of each one estimated from these data.
    """
    start = start_context(model0, q_all, {}, model_frame)
    blocks: list[Block] = []
    fitted: list[tuple[BlockKey, str]] = []
    meas_T_w: dict[str, NDArray] = {}
    external = sorted({kind_of(g).measured_in(g) for g in groups} - {None, model_frame})
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
            if not est:
                raise DatasetError(
                    f"{measurements.source}: frame {name!r} is observed only through markers "
                    "or points; give some marker-free pose observations in it, or measure "
                    "everything in it (then the model is expressed in it)"
                )
            meas_T_w[name] = average_transform(np.concatenate(est))
            fitted.append(
                (key, f"pose of the root link in {name!r} (from {sum(map(len, est))} poses)")
            )
        blocks.append(RigidFrameBlock(key, start=meas_T_w[name]))
    start = start_context(model0, q_all, meas_T_w, model_frame)
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
