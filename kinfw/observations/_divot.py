"""``"divot"``: a probe on the robot placed repeatedly on one fixed point (a cone, a
divot, a pivot), the point known or unknown.

A probe on URDF frame ``frame`` (:class:`~kinfw.observations._probe.ProbeContactKind`:
given ``offset`` or unknown, ``marker``) is placed on a point ``c`` fixed in the frame
``measured_in`` (default the URDF root), in any orientation the robot reaches. The
observation is where the tip was measured relative to the point (``gap``, 3 numbers,
metres in the axes of ``measured_in``; 0 for a contact); the residual is three rows in
metres, ``measured - predicted`` with

    predicted = p - c,

``p`` the probe in ``measured_in``. Its noise component is ``"placement"``
(:data:`PLACEMENT`, one sigma per axis): a contact's error reads as its placement error
(mm, and per axis).

The point is given (``centre``, metres) or an unknown block per name (key
:func:`divot_key`, a :class:`~kinfw.model.PointBlock`).

What one point cannot determine with the point unknown: the rigid motion of the whole
world (a translation moves the point with the robot; a rotation about the point leaves
the probe on it) and a common scale of every length (a given ``centre`` away from the
root, a given probe offset, or a second point at a known distance fixes it). The
identifiability report names the world motion; the refinement leaves both at the
nominal (:func:`kinfw.identification.refine`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from kinfw.model import BlockKey, PointBlock
from kinfw.observations._base import (
    Metric,
    NoiseComponent,
    UnknownRequest,
    data_array,
    sample_array,
)
from kinfw.observations._contexts import StartContext, SymbolicContext
from kinfw.observations._numeric import Drawing, NumericContext, node_name
from kinfw.observations._probe import ProbeContactKind, check_probe

PLACEMENT = NoiseComponent("placement", 3, "m", metric=Metric("placement", "mm", 1e3, axes="xyz"))
"""A point contact's placement error, m per axis; it reads in mm."""


def divot_key(name: str) -> BlockKey:
    """The block of the fixed point ``name``."""
    return BlockKey("divot", name)


def pivot_calibration(
    R: NDArray[np.float64],
    t: NDArray[np.float64],
    *,
    offset: NDArray[np.float64] | None = None,
    centre: NDArray[np.float64] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The probe offset ``o`` (3,) and the point ``c`` (3,) of contacts ``R_i o + t_i =
    c`` by linear least squares (pivot calibration); a given ``offset`` or ``centre`` is
    kept.

    ``[R_i, -I] (o, c) = -t_i``: 3 rows per contact, solved for the unknown columns. With
    the offset unknown and the frame's orientation too little varied the solution is the
    least-norm one (its undetermined part is zero).
    """
    n = len(R)
    o = np.zeros(3) if offset is None else np.asarray(offset, dtype=float)
    c = np.zeros(3) if centre is None else np.asarray(centre, dtype=float)
    blocks, rhs = [], -t - R @ o + c  # the known parts moved to the right-hand side
    if offset is None:
        blocks.append(R)
    if centre is None:
        blocks.append(np.broadcast_to(-np.eye(3), (n, 3, 3)))
    if not blocks:
        return o, c
    A = np.concatenate(blocks, axis=2).reshape(3 * n, -1)
    z = np.linalg.lstsq(A, rhs.reshape(-1), rcond=None)[0]
    if offset is None:
        o, z = z[:3], z[3:]
    if centre is None:
        c = z[:3]
    return o, c


@dataclass(frozen=True, slots=True, eq=False)
class DivotContacts:
    """``divot`` observations that share ``(frame, divot, centre, offset, marker,
    measured_in)``.

    Attributes
    ----------
    frame : str
        URDF frame the probe is rigidly attached to.
    sample : ndarray of int64, shape (m,)
        Index into :attr:`Measurements.qs` of each contact's sample.
    gap_m : ndarray, shape (m, 3)
        Measured position of the probe relative to the point, in the axes of
        ``measured_in``, metres (0 for a contact).
    divot : str
        Name of the point (one unknown per name unless ``centre`` is given).
    centre : ndarray, shape (3,), or None
        The point in ``measured_in`` in metres when given; None when estimated.
    offset : ndarray, shape (3,), or None
        ``frame_p_probe`` in metres when given; None when estimated.
    marker : str or None
        Name of the probe (its offset is unknown; excludes ``offset``).
    measured_in : str or None
        URDF frame the point is fixed to; None is the URDF root link.
    """

    kind: ClassVar[str] = "divot"
    frame: str
    sample: NDArray[np.int64]
    gap_m: NDArray[np.float64]
    divot: str = "divot"
    centre: NDArray[np.float64] | None = None
    offset: NDArray[np.float64] | None = None
    marker: str | None = None
    measured_in: str | None = None

    def __post_init__(self) -> None:
        name = f"DivotContacts(frame={self.frame!r}, divot={self.divot!r})"
        sample = sample_array(self.sample, f"{name}.sample")
        object.__setattr__(self, "sample", sample)
        object.__setattr__(self, "gap_m", data_array(self.gap_m, (len(sample), 3), f"{name}.gap_m"))
        if self.centre is not None:
            object.__setattr__(self, "centre", data_array(self.centre, (3,), f"{name}.centre"))
        check_probe(self, name)

    def __repr__(self) -> str:
        def listed(a):
            return None if a is None else a.tolist()

        return (
            f"DivotContacts(frame={self.frame!r}, divot={self.divot!r}, centre="
            f"{listed(self.centre)}, marker={self.marker!r}, offset={listed(self.offset)}, "
            f"measured_in={self.measured_in!r}, m={len(self.sample)})"
        )


class DivotKind(ProbeContactKind):
    """``{"frame": f, "kind": "divot", "divot": name}``, optional ``centre`` (3 lengths:
    the point is known), ``offset`` or ``marker``, ``gap`` (3 lengths, default 0) and
    ``measured_in`` (the URDF frame the point is fixed to; default the root).
    Residual: the probe's placement error (3, m)."""

    name = "divot"
    entity_field = "divot"
    entity_min = 3  # the point and the probe's offset apart
    group_type = DivotContacts
    row_fields = ("gap_m",)
    components = (PLACEMENT,)
    file_keys = ("divot", "centre", "gap", *ProbeContactKind.probe_keys)

    # -- file edge
    def parse(self, reader, obs, at, frame):
        probe = self.probe_fields(reader, obs, at)
        gap = [0.0, 0.0, 0.0]
        if obs.get("gap") is not None:
            gap = reader.lengths(reader.numbers(obs["gap"], 3, f"{at}.gap"))
        centre = None
        if obs.get("centre") is not None:
            centre = tuple(reader.lengths(reader.numbers(obs["centre"], 3, f"{at}.centre")))
        divot = reader.optional_string(obs, "divot", at) or "divot"
        key = (("frame", frame), ("divot", divot), ("centre", centre), *probe)
        return key, list(gap)

    def group_from_rows(self, key, sample, rows):
        return DivotContacts(sample=sample, gap_m=rows, **dict(key))

    def to_dicts(self, group, top_measured_in):
        return self.contact_dicts(
            group,
            {
                "divot": group.divot,
                **({} if group.centre is None else {"centre": group.centre.tolist()}),
            },
            [{"gap": gap} if any(gap) else {} for gap in group.gap_m.tolist()],
        )

    # -- estimation
    def unknowns(self, group, start: StartContext):
        """Closed form: the probe offset and the point by linear least squares
        (:func:`pivot_calibration`) on the start model's poses, in the frame the point
        is fixed to."""
        T = start.meas_T(group.measured_in, group.frame, group.sample)
        o, c = pivot_calibration(
            T[:, :3, :3], T[:, :3, 3] - group.gap_m, offset=group.offset, centre=group.centre
        )
        point = ()
        if group.centre is None:
            point = (
                UnknownRequest(
                    divot_key(group.divot),
                    c[None],
                    PointBlock.from_estimates,
                    f"point {group.divot!r} (touched by {group.frame!r})",
                ),
            )
        return (*self.offset_request(group, o, "point contacts"), *point)

    def trained_unknowns(self, group):
        """An unknown point and probe offset: held-out contacts are scored by their
        placement error at the trained point."""
        point = () if group.centre is not None else (divot_key(group.divot),)
        return (*point, *self.probe_unknowns(group))

    def data(self, group):
        return np.asarray(group.gap_m)

    def residual(self, group, model: SymbolicContext, m):
        c = (
            model.ca.DM(group.centre)
            if group.centre is not None
            else model.value(divot_key(group.divot))
        )
        return m - (self.symbolic_probe(group, model) - c)

    # -- numpy prediction, simulation (the default: Gaussian rows), drawing
    def _centre(self, group, model: NumericContext) -> NDArray[np.float64]:
        return group.centre if group.centre is not None else model.value(divot_key(group.divot))

    def predict(self, group, model: NumericContext):
        """The probe relative to the point (m, 3), metres."""
        return self.probe(group, model) - self._centre(group, model)

    def drawing(self, group, model: NumericContext):
        """Measured: the point plus the measured gap; predicted: the probe."""
        c = self._centre(group, model)
        return Drawing(
            node_name("divots", group.frame, group.divot, marker=group.marker),
            self.in_model_frame(group, model, c + group.gap_m),
            None,
            self.in_model_frame(group, model, self.probe(group, model)),
        )
