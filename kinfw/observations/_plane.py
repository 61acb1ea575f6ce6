"""``"plane"``: a point on the robot touches a fixed plane of unknown pose.

A probe (a fingertip, a touch probe, a pointer) rigidly attached to URDF frame ``frame``
touches a fixed plane (a table). The observation is the probe's signed distance from the
plane, 0 for a contact; the residual is ``measured - predicted`` distance, one row in
metres (noise component ``"distance"``).

Errors read as the contact's ``height`` above or below the plane (mm, per contact) and a
group's ``tilt`` (deg): the angle between the model's plane and the plane the contacts
say it is, from the heights' slope across the plane (:meth:`PlaneKind.errors`).

The plane is an unknown block (:class:`PlaneBlock`): a unit normal ``n`` and an offset
``d``, the plane ``{x : n . x = d}`` in the frame it is fixed to (``measured_in``: any
URDF frame, e.g. the foot a humanoid stands on; default the URDF root), the normal
pointing towards that frame's origin at the start (the origin lies at the positive
distance ``-d``). Contacts of several frames (two arms, a tool on a shared torso) that
name one plane share its unknown and calibrate together. The probe's offset in
``frame`` is given (``offset``) or estimated, one unknown per ``(frame, marker)``, the
same block as a ``point`` observation of that marker
(:func:`kinfw.observations.offset_key`): a tracked probe that also touches a table is
one point.

What plane contacts cannot determine
-------------------------------------
A rigid motion of the plane within itself (two translations, the rotation about its
normal) changes no distance: the block has no such coordinates (3 entries, not a rigid
frame's 6). With the robot's kinematics free, distances of 0 are also unchanged by

- a rigid motion of the whole world (robot and planes together): 6 directions, the
  same as for any data without an external reference (with ``measured_in`` a frame of
  the robot: the joints above the common ancestor of the probe's and the plane's frames,
  and the frame's own mounting);
- a common scale of every length (the links, the probe offset and the planes' offsets):
  a contact stays a contact, so plane contacts alone never fix the robot's size. One
  known length fixes it: a ``point`` observation in the root frame, a given probe
  ``offset``, a prismatic joint;
- with the probe's orientation fixed over the contacts, the probe offset's components
  that the frame's motion never turns towards the normal.

The identifiability report counts these directions and lists the parameters each of its
null vectors involves; it does not name them (its null basis mixes the world motion and
the scale), so ``docs/measurements.md`` lists them for the user. The refinement leaves
the robot at its start (the nominal URDF) along all of them
(:func:`kinfw.identification.refine`): the exported URDF changes only along what the
contacts determine.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.model import Block, BlockKey
from kinfw.observations._base import (
    Metric,
    MetricErrors,
    NoiseComponent,
    UnknownRequest,
    data_array,
    sample_array,
)
from kinfw.observations._contexts import StartContext, SymbolicContext
from kinfw.observations._numeric import Drawing, MissingValue, NumericContext, node_name
from kinfw.observations._probe import ProbeContactKind, check_probe

DISTANCE = NoiseComponent("distance", 1, "m", metric=Metric("height", "mm", 1e3))
"""A contact's signed distance error, m; it reads as its height off the plane, mm."""

TILT = Metric("tilt", "deg", float(np.degrees(1.0)), ".4f", per_observation=False)
"""A group's tilt (:meth:`PlaneKind.errors`), deg."""


def plane_key(name: str) -> BlockKey:
    """The block of the plane ``name``."""
    return BlockKey("plane", name)


# -- the plane's parameter block -----------------------------------------------------------


def tangent_basis(n: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Two unit vectors ``(u, v)`` with ``(u, v, n)`` a right-handed orthonormal basis.

    Deterministic in ``n`` (3,) unit: ``u`` is the world axis least aligned with ``n``,
    made orthogonal to it.
    """
    n = np.asarray(n, dtype=float)
    a = np.eye(3)[int(np.argmin(np.abs(n)))]
    u = a - (a @ n) * n
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


@dataclass(frozen=True, slots=True)
class PlaneBlock(Block):
    """A plane ``{x : n . x = d}``: value ``(n, d)`` (4,), ``n`` unit, ``d`` metres.

    Chart (3 entries ``rot_x, rot_y`` rad, ``offset`` m): the normal is the start's
    normal turned by the Cayley rotation of ``(rot_x, rot_y, 0) / 2`` in the start's
    tangent basis ``(u, v, n0)`` (:func:`tangent_basis`), the offset ``d0 + offset``::

        a = (rot_x, rot_y) / 2,  c = 2 / (1 + |a|^2)
        n = c a_y u - c a_x v + (1 - c |a|^2) n0

    ``n`` is a unit vector for every ``d`` (the stereographic projection from ``-n0``):
    minimal, smooth and one to one on every normal but ``-n0``; at zero, ``(rot_x,
    rot_y)`` is the small rotation of the normal about ``u`` and ``v`` (rad). The plane's
    rotation about its normal and its translations within itself change no point's
    distance from it: the chart has no coordinates for them (the gauge is fixed by
    construction).

    Attributes
    ----------
    start : ndarray, shape (4,)
        Start ``(n0, d0)``: unit normal and offset (metres), in the model frame.
    """

    start: NDArray[np.float64] = field(default_factory=lambda: np.array([0.0, 0.0, 1.0, 0.0]))

    def __post_init__(self) -> None:
        start = data_array(self.start, (4,), f"PlaneBlock({self.key}).start")
        norm = float(np.linalg.norm(start[:3]))
        if abs(norm - 1.0) > 1e-9:
            raise ValueError(f"PlaneBlock({self.key}).start: the normal must be a unit vector")
        object.__setattr__(self, "start", start)
        Block.__post_init__(self)

    @property
    def fields(self) -> tuple[str, ...]:
        return ("rot_x", "rot_y", "offset")

    @property
    def units(self) -> tuple[str, ...]:
        return ("rad", "rad", "m")

    @staticmethod
    def from_estimates(key: BlockKey, estimates: NDArray[np.float64]) -> PlaneBlock:
        """The mean of per-group plane estimates ``(n, d)`` (k, 4), signs aligned with
        the first, normalised."""
        est = np.asarray(estimates, dtype=float).reshape(-1, 4)
        est = est * np.where(est[:, :3] @ est[0, :3] < 0.0, -1.0, 1.0)[:, None]
        mean = est.mean(axis=0)
        return PlaneBlock(key, start=mean / np.linalg.norm(mean[:3]))

    def constants(self) -> NDArray[np.float64]:
        """The start's tangent basis ``u, v``, normal ``n0`` and offset ``d0`` (10)."""
        u, v = tangent_basis(self.start[:3])
        return np.concatenate([u, v, self.start])

    def numpy_value(self, d: NDArray[np.float64]) -> NDArray[np.float64]:
        c = self.constants()
        return np.asarray(_plane_from_chart(c[0:3], c[3:6], c[6:9], c[9], d[0], d[1], d[2]))

    def casadi_value(self, d: Any, c: Any = None) -> Any:
        import casadi as ca

        c = ca.DM(self.constants()) if c is None else c
        n, off = _plane_from_chart(c[0:3], c[3:6], c[6:9], c[9], d[0], d[1], d[2])
        return ca.vertcat(n, off)

    def coordinates(self, plane: ArrayLike) -> NDArray[np.float64]:
        """Chart coordinates (3,) of a plane ``(n, d)`` (4,) (undefined at ``n = -n0``)."""
        plane = np.asarray(plane, dtype=float)
        n, off = plane[:3] / np.linalg.norm(plane[:3]), plane[3] / np.linalg.norm(plane[:3])
        u, v = tangent_basis(self.start[:3])
        k = 1.0 + n @ self.start[:3]  # = c = 2 / (1 + |a|^2)
        return np.array([-2.0 * (n @ v) / k, 2.0 * (n @ u) / k, off - self.start[3]])

    def describe(self) -> str:
        return f"plane {self.key.name!r}"


def _plane_from_chart(u: Any, v: Any, n0: Any, d0: Any, rx: Any, ry: Any, off: Any) -> Any:
    """``(n, d)`` of the chart (numpy (3,) and float, or CasADi): see :class:`PlaneBlock`."""
    ax, ay = 0.5 * rx, 0.5 * ry
    r2 = ax * ax + ay * ay
    c = 2.0 / (1.0 + r2)
    n = (c * ay) * u - (c * ax) * v + (1.0 - c * r2) * n0
    if isinstance(n, np.ndarray):
        return np.append(n, d0 + off)
    return n, d0 + off


def fit_plane(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """Total least-squares plane ``(n, d)`` (4,) through points (k, 3) (SVD), ``d <= 0``
    (the origin on the normal's side)."""
    centroid = points.mean(axis=0)
    n = np.linalg.svd(points - centroid, full_matrices=False)[2][-1]
    d = float(n @ centroid)
    return np.append(n, d) * (-1.0 if d > 0.0 else 1.0)


def lifted_probe_offset(
    R: NDArray[np.float64], t: NDArray[np.float64]
) -> NDArray[np.float64] | None:
    """Probe offset ``o`` (3,) of contacts ``n . (R_i o + t_i) = d`` in closed form.

    The constraint is linear in ``(n o^T, n, d)`` once ``n^T R_i o`` is written
    ``<R_i, n o^T>``: 13 homogeneous unknowns, the null vector of the contacts' rows by
    SVD, scaled to ``|n| = 1``; then ``o = (n o^T)^T n``. None when the rows leave more
    than one null direction (fewer than 13 contacts, or the frame's orientation too
    little varied to tell the offset from the plane).
    """
    A = np.concatenate([R.reshape(len(R), 9), t, -np.ones((len(R), 1))], axis=1)
    if len(A) < 13:
        return None
    scale = np.linalg.norm(A, axis=0)
    _, s, Vt = np.linalg.svd(A / scale, full_matrices=False)
    if s[-2] <= 1e-6 * s[0]:
        return None
    z = Vt[-1] / scale
    n = z[9:12]
    if np.linalg.norm(n) == 0.0:
        return None
    M = z[:9].reshape(3, 3) / np.linalg.norm(n)
    return M.T @ (n / np.linalg.norm(n))


# -- the observations ------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, eq=False)
class PlaneContacts:
    """``plane`` observations that share ``(frame, plane, offset, marker, measured_in)``.

    Attributes
    ----------
    frame : str
        URDF frame the probe is rigidly attached to.
    sample : ndarray of int64, shape (m,)
        Index into :attr:`Measurements.qs` of each contact's sample.
    distance_m : ndarray, shape (m,)
        Measured signed distance of the probe from the plane, metres (0 for a contact).
    plane : str
        Name of the plane (one unknown per name).
    offset : ndarray, shape (3,), or None
        ``frame_p_probe`` in metres when given; None when estimated.
    marker : str or None
        Name of the probe (its offset is unknown; excludes ``offset``).
    measured_in : str or None
        URDF frame the plane is fixed to; None is the URDF root link.
    """

    kind: ClassVar[str] = "plane"
    frame: str
    sample: NDArray[np.int64]
    distance_m: NDArray[np.float64]
    plane: str = "plane"
    offset: NDArray[np.float64] | None = None
    marker: str | None = None
    measured_in: str | None = None

    def __post_init__(self) -> None:
        name = f"PlaneContacts(frame={self.frame!r}, plane={self.plane!r})"
        sample = sample_array(self.sample, f"{name}.sample")
        object.__setattr__(self, "sample", sample)
        object.__setattr__(
            self, "distance_m", data_array(self.distance_m, (len(sample),), f"{name}.distance_m")
        )
        check_probe(self, name)

    def __repr__(self) -> str:
        offset = None if self.offset is None else self.offset.tolist()
        return (
            f"PlaneContacts(frame={self.frame!r}, plane={self.plane!r}, marker="
            f"{self.marker!r}, offset={offset}, measured_in={self.measured_in!r}, "
            f"m={len(self.sample)})"
        )


class PlaneKind(ProbeContactKind):
    """``{"frame": f, "kind": "plane", "plane": name}``, optional ``offset`` or
    ``marker``, ``distance`` (default 0) and ``measured_in`` (the URDF frame the plane is
    fixed to; default the root; a file's top-level ``measured_in`` does not apply).
    Residual: signed distance (1, m)."""

    name = "plane"
    entity_field = "plane"
    entity_min = 3  # its normal (2) and offset
    group_type = PlaneContacts
    row_fields = ("distance_m",)
    components = (DISTANCE,)
    file_keys = ("plane", "distance", *ProbeContactKind.probe_keys)

    # -- file edge
    def parse(self, reader, obs, at, frame):
        probe = self.probe_fields(reader, obs, at)
        distance = 0.0
        if "distance" in obs:  # absent: on the surface; null is refused
            distance = reader.number(
                obs, "distance", at, "the probe's signed distance from the plane (a length)"
            )
        plane = reader.optional_string(obs, "plane", at) or "plane"
        return (("frame", frame), ("plane", plane), *probe), reader.lengths([distance])

    def group_from_rows(self, key, sample, rows):
        return PlaneContacts(sample=sample, distance_m=rows[:, 0], **dict(key))

    def to_dicts(self, group, top_measured_in):
        return self.contact_dicts(
            group,
            {"plane": group.plane},
            [{"distance": d} if d != 0.0 else {} for d in group.distance_m.tolist()],
        )

    # -- estimation
    def unknowns(self, group, start: StartContext):
        """Closed form: the probe offset of the lifted linear system
        (:func:`lifted_probe_offset`; the frame's origin when it is not determined),
        then the plane through the start model's probe points (SVD, :func:`fit_plane`),
        in the frame the plane is fixed to."""
        T = start.meas_T(group.measured_in, group.frame, group.sample)
        R, t = T[:, :3, :3], T[:, :3, 3]
        o = group.offset
        if o is None:
            o = lifted_probe_offset(R, t)
            o = np.zeros(3) if o is None else o
        # the probe at its measured distance: shift along the first fit's normal
        plane = fit_plane(R @ o + t)
        points = R @ o + t - group.distance_m[:, None] * plane[:3]
        return (
            *self.offset_request(group, o, "plane contacts"),
            UnknownRequest(
                plane_key(group.plane),
                fit_plane(points)[None],
                PlaneBlock.from_estimates,
                f"plane {group.plane!r} (touched by {group.frame!r})",
            ),
        )

    def trained_unknowns(self, group):
        """The plane and an unknown probe offset: held-out contacts are scored by their
        distance from the trained plane."""
        return (plane_key(group.plane), *self.probe_unknowns(group))

    def data(self, group):
        return group.distance_m[:, None]

    def residual(self, group, model: SymbolicContext, m):
        ca = model.ca
        p = self.symbolic_probe(group, model)
        plane = model.value(plane_key(group.plane))
        return m[0] - (ca.dot(plane[0:3], p) - plane[3])

    # -- errors: height per contact, the group's tilt
    @property
    def metrics(self):
        return (DISTANCE.display, TILT)

    def errors(self, group, rows, model: NumericContext):
        """Each contact's height off the plane (the distance error's size, mm) and the
        group's tilt (deg).

        The tilt is the angle between the model's plane and the plane the contacts lie
        on: with ``h_i`` the distance errors (``measured - predicted``) and ``(a_i,
        b_i)`` the predicted probe points in the plane's tangent basis
        (:func:`tangent_basis`), the least-squares plane ``h = h_0 + g_a a + g_b b``
        tilts by ``arctan(|(g_a, g_b)|)``. NaN with fewer than 3 contacts, contacts on a
        line, or a model without the plane's or the probe's value.
        """
        (height,) = super().errors(group, rows, model)
        tilt = np.nan
        try:
            p = self.probe(group, model)
            plane = model.value(plane_key(group.plane))
        except MissingValue:
            p = None
        if p is not None and len(p) >= 3:
            u, v = tangent_basis(plane[:3] / np.linalg.norm(plane[:3]))
            A = np.column_stack([np.ones(len(p)), p @ u, p @ v])
            if np.linalg.matrix_rank(A) == 3:
                slope = np.linalg.lstsq(A, rows[:, 0], rcond=None)[0][1:]
                tilt = float(np.arctan(np.linalg.norm(slope)))
        return (height, MetricErrors(TILT, np.asarray(tilt)))

    # -- numpy prediction, simulation (the default: Gaussian distance noise), drawing
    def predict(self, group, model: NumericContext):
        """Signed distance (m, 1) of the probe from the plane, metres."""
        plane = model.value(plane_key(group.plane))
        return (self.probe(group, model) @ plane[:3] - plane[3])[:, None]

    def drawing(self, group, model: NumericContext):
        """Measured: the point at the measured distance from the plane on the normal
        through the predicted probe (the contact point on the plane for a distance 0);
        predicted: the probe."""
        plane = model.value(plane_key(group.plane))
        p = self.probe(group, model)
        predicted = p @ plane[:3] - plane[3]
        return Drawing(
            node_name("planes", group.frame, group.plane, marker=group.marker),
            self.in_model_frame(
                group, model, p + (group.distance_m - predicted)[:, None] * plane[:3]
            ),
            None,
            self.in_model_frame(group, model, p),
        )
