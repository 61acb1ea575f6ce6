"""``"point"``: the position of a point rigidly attached to a URDF frame."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from kinfw.model import BlockKey, PointBlock
from kinfw.observations._base import (
    POSITION,
    ObservationKind,
    UnknownRequest,
    data_array,
    sample_array,
)
from kinfw.observations._contexts import StartContext, SymbolicContext
from kinfw.observations._numeric import Drawing, NumericContext, node_name, predicted_or_missing


def offset_key(frame: str, marker: str | None) -> BlockKey:
    """The block of an unknown point offset: one per (frame, marker or 'point')."""
    return BlockKey("offset", f"{frame}:{marker or 'point'}")


def read_offset_or_marker(
    reader: Any, obs: dict[str, Any], at: str
) -> tuple[tuple[float, float, float] | None, str | None]:
    """A file observation's point on its frame: the known ``offset`` (metres) or the
    ``marker`` naming an unknown one (both None: an unknown offset), never both."""
    offset = None
    if obs.get("offset") is not None:
        offset = tuple(reader.lengths(reader.numbers(obs["offset"], 3, f"{at}.offset")))
    marker = reader.optional_string(obs, "marker", at)
    if marker is not None and offset is not None:
        raise reader.error(
            f"{at}.offset",
            f"an offset and a marker ({marker!r}) exclude each other: a marker's offset is "
            "unknown and estimated; drop the marker to use a known offset",
        )
    return offset, marker


@dataclass(frozen=True, slots=True, eq=False)
class PointObservations:
    """All ``point`` observations that share ``(frame, marker, measured_in, offset)``.

    Attributes
    ----------
    frame : str
        URDF frame the point is rigidly attached to.
    sample : ndarray of int64, shape (m,)
        Index into :attr:`Measurements.qs` of each observation's sample.
    meas_p_point : ndarray, shape (m, 3)
        Position of the point in the measurement frame, metres.
    offset : ndarray, shape (3,), or None
        ``frame_p_point``, the point in ``frame`` (metres), when the file gives it; None
        when it is unknown and estimated.
    marker : str or None
        Name of the marker (its offset is unknown; excludes ``offset``).
    measured_in : str or None
        Measurement frame; None is the URDF root link.
    """

    kind: ClassVar[str] = "point"
    frame: str
    sample: NDArray[np.int64]
    meas_p_point: NDArray[np.float64]
    offset: NDArray[np.float64] | None = None
    marker: str | None = None
    measured_in: str | None = None

    def __post_init__(self) -> None:
        name = f"PointObservations(frame={self.frame!r})"
        sample = sample_array(self.sample, f"{name}.sample")
        p = data_array(self.meas_p_point, (len(sample), 3), f"{name}.meas_p_point")
        object.__setattr__(self, "sample", sample)
        object.__setattr__(self, "meas_p_point", p)
        if self.offset is not None:
            offset = data_array(self.offset, (3,), f"{name}.offset")
            object.__setattr__(self, "offset", offset)

    def __repr__(self) -> str:
        offset = None if self.offset is None else self.offset.tolist()
        return (
            f"PointObservations(frame={self.frame!r}, marker={self.marker!r}, "
            f"measured_in={self.measured_in!r}, offset={offset}, m={len(self.sample)})"
        )

    @property
    def _key(self) -> tuple[Any, ...]:
        return PointKind().key(self)


class PointKind(ObservationKind):
    """``"point"``: ``xyz`` of a point on ``frame`` in the measurement frame; its
    ``offset`` in ``frame`` is given or estimated (one unknown per frame and marker).
    Residual: position (3, m)."""

    name = "point"
    group_type = PointObservations
    row_fields = ("meas_p_point",)
    components = (POSITION,)
    measurements_field = "points"
    has_measured_in = True
    file_keys = ("xyz", "offset", "marker", "measured_in")

    def parse(self, reader, obs, at, frame):
        xyz = reader.numbers(reader.get(obs, "xyz", at, "3 numbers [x, y, z]"), 3, f"{at}.xyz")
        reader.not_allowed(obs, "target", at, self.name, "only 'target' observations name a target")
        reader.not_allowed(
            obs,
            "quat_xyzw",
            at,
            self.name,
            "a point has a position only; use kind 'pose' for a pose",
        )
        offset, marker = read_offset_or_marker(reader, obs, at)
        measured_in = reader.optional_string(obs, "measured_in", at) or reader.default_measured_in
        key = (
            ("frame", frame),
            ("offset", offset),
            ("marker", marker),
            ("measured_in", measured_in),
        )
        return key, reader.lengths(xyz)

    def group_from_rows(self, key, sample, rows):
        return PointObservations(sample=sample, meas_p_point=rows, **dict(key))

    def to_dicts(self, group, top_measured_in):
        more = {
            k: v
            for k, v in (
                ("offset", None if group.offset is None else group.offset.tolist()),
                ("marker", group.marker),
                (
                    "measured_in",
                    None if group.measured_in == top_measured_in else group.measured_in,
                ),
            )
            if v is not None
        }
        return [
            {"frame": group.frame, "kind": "point", "xyz": xyz, **more}
            for xyz in group.meas_p_point.tolist()
        ]

    def frames(self, group):
        return (group.frame,)

    def direct_frames(self, group):
        return (group.frame,) if group.offset is not None else ()

    def marker_tracks(self, group, start: StartContext):
        """For placing an external frame seen only through markers
        (:func:`kinfw.identification.problem.frame_from_markers`): the frame's start
        poses in the model frame, the measured positions, the known offset (or None),
        no measured rotation, and the offset's block key."""
        return (
            start.w_T(group.frame, group.sample),
            group.meas_p_point,
            group.offset,
            None,
            offset_key(group.frame, group.marker),
        )

    def unknowns(self, group, start: StartContext):
        if group.offset is not None:
            return ()
        T = start.meas_T(group.measured_in, group.frame, group.sample)
        # least-squares offset of each sample: R_i^T (m_i - p_i); the block takes the mean
        estimates = np.einsum("nji,nj->ni", T[:, :3, :3], group.meas_p_point - T[:, :3, 3])
        who = repr(group.marker) if group.marker else f"on {group.frame!r}"
        return (
            UnknownRequest(
                offset_key(group.frame, group.marker),
                estimates,
                PointBlock.from_estimates,
                f"offset of point {who} on {group.frame!r}",
            ),
        )

    def data(self, group):
        return np.asarray(group.meas_p_point)

    def residual(self, group, model: SymbolicContext, m):
        T = model.meas_T(group.measured_in, group.frame)
        o = (
            model.ca.DM(group.offset)
            if group.offset is not None
            else model.value(offset_key(group.frame, group.marker))
        )
        return m - (T[0:3, 0:3] @ o + T[0:3, 3])

    # -- numpy prediction, simulation (the default: Gaussian position noise), drawing
    def _offset(self, group, model: NumericContext):
        return (
            group.offset
            if group.offset is not None
            else model.value(offset_key(group.frame, group.marker))
        )

    def predict(self, group, model: NumericContext):
        T = model.meas_T(group.measured_in, group.frame, group.sample)
        return T[:, :3, :3] @ self._offset(group, model) + T[:, :3, 3]

    def drawing(self, group, model: NumericContext):
        w_T_meas = model.w_T_meas_at(group.measured_in, group.sample)
        w_p = np.einsum("nij,nj->ni", w_T_meas[:, :3, :3], group.meas_p_point) + w_T_meas[:, :3, 3]

        def predicted():
            T = model.w_T(group.frame, group.sample)
            return T[:, :3, :3] @ self._offset(group, model) + T[:, :3, 3]

        predicted, missing = predicted_or_missing(predicted)
        return Drawing(
            node_name("points", group.frame, marker=group.marker),
            w_p,
            None,
            predicted,
            missing=missing,
        )
