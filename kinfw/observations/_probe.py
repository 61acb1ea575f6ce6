"""What the contact kinds (``plane``, ``sphere``, ``divot``) share: a probe on the robot.

A probe (a fingertip, a touch probe, a pointer) is rigidly attached to URDF frame
``frame`` at ``offset`` (given, metres) or at an unknown offset (``marker``: one unknown
per ``(frame, marker)``, the same block as a ``point`` observation of that marker,
:func:`kinfw.observations.offset_key`). It touches something fixed in the frame
``measured_in`` (any URDF frame, e.g. the foot a humanoid stands on; default the URDF
root; a file's top-level ``measured_in`` does not apply). :class:`ProbeContactKind` is the
part of each kind that reads and writes these fields, names the frames and places the
probe (symbolic and numeric); the kinds add what is touched.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from kinfw.model import BlockKey, PointBlock
from kinfw.observations._base import ObservationKind, UnknownRequest, data_array
from kinfw.observations._contexts import SymbolicContext
from kinfw.observations._numeric import NumericContext
from kinfw.observations._point import offset_key, read_offset_or_marker


def check_probe(group: Any, name: str) -> None:
    """Check a contact group's probe fields in its ``__post_init__`` (``name`` its repr
    for messages): a given ``offset`` is 3 finite lengths (stored read-only), and it
    excludes a ``marker``."""
    if group.offset is not None:
        object.__setattr__(group, "offset", data_array(group.offset, (3,), f"{name}.offset"))
        if group.marker is not None:
            raise ValueError(f"{name}: an offset and a marker exclude each other")


class ProbeContactKind(ObservationKind):
    """Base of the kinds whose observation is a probe on ``frame`` touching something
    fixed in ``measured_in``: their groups have ``frame``, ``offset`` ((3,) m, or None),
    ``marker`` and ``measured_in``."""

    has_measured_in = True
    #: The probe's keys (:meth:`probe_fields`); each kind adds what it touches.
    probe_keys = ("offset", "marker", "measured_in")

    # -- file edge
    def probe_fields(
        self, reader: Any, obs: dict[str, Any], at: str
    ) -> tuple[tuple[str, Any], ...]:
        """The probe's key fields of a file observation: ``offset`` (a tuple in metres, or
        None), ``marker`` and ``measured_in``; a target, a position or a quaternion is
        refused, as an offset together with a marker."""
        for key in ("xyz", "quat_xyzw"):
            reader.not_allowed(
                obs, key, at, self.name, "a contact measures its distance, no position"
            )
        reader.not_allowed(obs, "target", at, self.name, "only 'target' observations name a target")
        offset, marker = read_offset_or_marker(reader, obs, at)
        measured_in = reader.optional_string(obs, "measured_in", at)
        return (("offset", offset), ("marker", marker), ("measured_in", measured_in))

    def contact_dicts(
        self, group: Any, touched: dict[str, Any], measured: list[dict[str, Any]]
    ) -> list[dict[str, Any]]:
        """One file observation per contact: the frame, the kind, what is touched
        (``touched``: its name, a given radius), the probe's fields that are set, then
        the contact's own ``measured`` values (left out where they are 0)."""
        probe = {
            k: v
            for k, v in (
                ("offset", None if group.offset is None else group.offset.tolist()),
                ("marker", group.marker),
                ("measured_in", group.measured_in),
            )
            if v is not None
        }
        return [
            {"frame": group.frame, "kind": self.name, **touched, **probe, **row} for row in measured
        ]

    # -- structure
    def frames(self, group):
        return (group.frame,)

    def direct_frames(self, group):
        """With a given offset the frame's tool transform is estimated (it carries the
        probe, as for a ``point`` of known offset); with an unknown one the offset does
        and the tool stays nominal."""
        return (group.frame,) if group.offset is not None else ()

    # -- the probe
    def offset_request(
        self, group: Any, estimate: NDArray[np.float64], what: str
    ) -> tuple[UnknownRequest, ...]:
        """The unknown probe offset's request with its start ``estimate`` (3,) (none for a
        given offset); ``what`` names the contacts (``"plane contacts"``)."""
        if group.offset is not None:
            return ()
        who = repr(group.marker) if group.marker else "probe"
        return (
            UnknownRequest(
                offset_key(group.frame, group.marker),
                np.asarray(estimate, dtype=float)[None],
                PointBlock.from_estimates,
                f"offset of {who} on {group.frame!r} ({what})",
            ),
        )

    def probe_unknowns(self, group: Any) -> tuple[BlockKey, ...]:
        """The probe's unknown offset, if it has one."""
        return () if group.offset is not None else (offset_key(group.frame, group.marker),)

    def symbolic_probe(self, group: Any, model: SymbolicContext) -> Any:
        """The probe (SX 3x1) in the frame ``measured_in``, metres."""
        T = model.meas_T(group.measured_in, group.frame)
        o = (
            model.ca.DM(group.offset)
            if group.offset is not None
            else model.value(offset_key(group.frame, group.marker))
        )
        return T[0:3, 0:3] @ o + T[0:3, 3]

    def probe(self, group: Any, model: NumericContext) -> NDArray[np.float64]:
        """The probe (m, 3) in the frame ``measured_in`` at the group's samples, metres."""
        T = model.meas_T(group.measured_in, group.frame, group.sample)
        o = (
            group.offset
            if group.offset is not None
            else model.value(offset_key(group.frame, group.marker))
        )
        return T[:, :3, :3] @ o + T[:, :3, 3]

    def in_model_frame(
        self, group: Any, model: NumericContext, meas_p: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """Points (m, 3) given in ``measured_in`` at the group's samples, in the model
        frame (for the view)."""
        w_T_meas = model.w_T_meas_at(group.measured_in, group.sample)
        return np.einsum("nij,nj->ni", w_T_meas[:, :3, :3], meas_p) + w_T_meas[:, :3, 3]
