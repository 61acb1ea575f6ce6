"""``"sphere"``: a probe on the robot touches a fixed ball (a tooling ball) of unknown
centre.

A probe on URDF frame ``frame`` (:class:`~kinfw.observations._probe.ProbeContactKind`:
given ``offset`` or unknown, ``marker``) touches a ball of radius ``r`` fixed in the
frame ``measured_in`` (default the URDF root). The observation is the probe's signed
distance from the ball's surface, 0 for a contact; the residual is one row in metres,
``measured - predicted`` with

    predicted = |p - c| - r,

``p`` the probe and ``c`` the centre, both in ``measured_in``. Its noise component is the
plane contacts' ``"distance"`` (:data:`~kinfw.observations.DISTANCE`): a contact's error
reads as its height off the surface (mm).

The ball is an unknown block per name (key :func:`sphere_key`): its centre (a
:class:`~kinfw.model.PointBlock`) when the file gives the radius (``radius``, metres:
every contact of one ball gives the same or none), else the centre and the radius
(:class:`SphereBlock`).

What ball contacts cannot determine: the rigid motion of the whole world (robot and ball
together: a translation moves the centre with the robot, a rotation about the centre
changes no distance), and with the radius unknown a common scale of every length (a
contact stays a contact when everything grows; a given radius fixes it). The
identifiability report names the world motion; the refinement leaves both at the
nominal (:func:`kinfw.identification.refine`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.model import Block, BlockKey, PointBlock
from kinfw.observations._base import UnknownRequest, data_array, sample_array
from kinfw.observations._contexts import StartContext, SymbolicContext
from kinfw.observations._numeric import Drawing, NumericContext, node_name
from kinfw.observations._plane import DISTANCE
from kinfw.observations._probe import ProbeContactKind, check_probe


def sphere_key(name: str) -> BlockKey:
    """The block of the ball ``name``."""
    return BlockKey("sphere", name)


@dataclass(frozen=True, slots=True)
class SphereBlock(Block):
    """A ball of unknown centre and radius: value ``(c, r)`` (4,), metres; chart ``start
    + d`` (fields ``x, y, z, radius``).

    Attributes
    ----------
    start : ndarray, shape (4,)
        Start centre (metres, in the frame the ball is fixed to) and radius (metres).
    """

    start: NDArray[np.float64] = field(default_factory=lambda: np.zeros(4))

    @property
    def fields(self) -> tuple[str, ...]:
        return ("x", "y", "z", "radius")

    @property
    def units(self) -> tuple[str, ...]:
        return ("m", "m", "m", "m")

    @staticmethod
    def from_estimates(key: BlockKey, estimates: NDArray[np.float64]) -> SphereBlock:
        """The mean of per-group estimates ``(c, r)`` (k, 4) as the start."""
        return SphereBlock(key, start=np.asarray(estimates, dtype=float).reshape(-1, 4).mean(0))

    def constants(self) -> NDArray[np.float64]:
        return np.asarray(self.start, dtype=float)

    def numpy_value(self, d: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.start + d

    def casadi_value(self, d: Any, c: Any = None) -> Any:
        import casadi as ca

        start = ca.DM(self.start) if c is None else c[0:4]
        return start + ca.vertcat(d[0], d[1], d[2], d[3])

    def coordinates(self, value: ArrayLike) -> NDArray[np.float64]:
        return np.asarray(value, dtype=float) - self.start

    def describe(self) -> str:
        return f"ball {self.key.name!r}"


def fit_sphere(points: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """Algebraic least-squares sphere ``(c, r)`` (4,) through points (k, 3), metres:
    ``|p|^2 = 2 c . p + (r^2 - |c|^2)`` is linear in ``c`` and ``r^2 - |c|^2``. None for
    fewer than 4 points or points on a plane (no sphere through them is determined)."""
    points = np.asarray(points, dtype=float)
    if len(points) < 4:
        return None
    A = np.column_stack([2.0 * points, np.ones(len(points))])
    s = np.linalg.svd(A, compute_uv=False)
    if s[-1] <= 1e-9 * s[0]:
        return None
    z = np.linalg.lstsq(A, np.einsum("ni,ni->n", points, points), rcond=None)[0]
    c = z[:3]
    return np.append(c, np.sqrt(max(z[3] + c @ c, 0.0)))


def lifted_sphere_probe(
    R: NDArray[np.float64], t: NDArray[np.float64]
) -> NDArray[np.float64] | None:
    """Probe offset ``o`` (3,) of contacts ``|R_i o + t_i - c| = r`` in closed form.

    Squared, a contact is ``2 t_i^T R_i o - 2 t_i . c - 2 <R_i, c o^T> + k = -|t_i|^2``
    with ``k = |o|^2 + |c|^2 - r^2``: linear in ``(o, c, c o^T, k)``, 16 unknowns, solved
    by least squares (columns scaled). None with fewer than 16 contacts or when the rows
    leave a direction undetermined (the frame's orientation too little varied).
    """
    n = len(R)
    if n < 16:
        return None
    A = np.concatenate(
        [
            2.0 * np.einsum("nji,nj->ni", R, t),
            -2.0 * t,
            -2.0 * R.reshape(n, 9),
            np.ones((n, 1)),
        ],
        axis=1,
    )
    scale = np.linalg.norm(A, axis=0)
    scale = np.where(scale > 0.0, scale, 1.0)
    s = np.linalg.svd(A / scale, compute_uv=False)
    if s[-1] <= 1e-8 * s[0]:
        return None
    z = np.linalg.lstsq(A / scale, -np.einsum("ni,ni->n", t, t), rcond=None)[0] / scale
    return z[:3]


@dataclass(frozen=True, slots=True, eq=False)
class SphereContacts:
    """``sphere`` observations that share ``(frame, sphere, radius, offset, marker,
    measured_in)``.

    Attributes
    ----------
    frame : str
        URDF frame the probe is rigidly attached to.
    sample : ndarray of int64, shape (m,)
        Index into :attr:`Measurements.qs` of each contact's sample.
    distance_m : ndarray, shape (m,)
        Measured signed distance of the probe from the ball's surface, metres (0 for a
        contact).
    sphere : str
        Name of the ball (one unknown per name).
    radius : float or None
        The ball's radius in metres when given; None when estimated.
    offset : ndarray, shape (3,), or None
        ``frame_p_probe`` in metres when given; None when estimated.
    marker : str or None
        Name of the probe (its offset is unknown; excludes ``offset``).
    measured_in : str or None
        URDF frame the ball is fixed to; None is the URDF root link.
    """

    kind: ClassVar[str] = "sphere"
    frame: str
    sample: NDArray[np.int64]
    distance_m: NDArray[np.float64]
    sphere: str = "ball"
    radius: float | None = None
    offset: NDArray[np.float64] | None = None
    marker: str | None = None
    measured_in: str | None = None

    def __post_init__(self) -> None:
        name = f"SphereContacts(frame={self.frame!r}, sphere={self.sphere!r})"
        sample = sample_array(self.sample, f"{name}.sample")
        object.__setattr__(self, "sample", sample)
        object.__setattr__(
            self, "distance_m", data_array(self.distance_m, (len(sample),), f"{name}.distance_m")
        )
        if self.radius is not None:
            radius = float(self.radius)
            if not (np.isfinite(radius) and radius >= 0.0):
                raise ValueError(f"{name}.radius: expected a length >= 0, got {self.radius!r}")
            object.__setattr__(self, "radius", radius)
        check_probe(self, name)

    def __repr__(self) -> str:
        offset = None if self.offset is None else self.offset.tolist()
        return (
            f"SphereContacts(frame={self.frame!r}, sphere={self.sphere!r}, radius="
            f"{self.radius!r}, marker={self.marker!r}, offset={offset}, measured_in="
            f"{self.measured_in!r}, m={len(self.sample)})"
        )


class SphereKind(ProbeContactKind):
    """``{"frame": f, "kind": "sphere", "sphere": name}``, optional ``radius`` (metres,
    or a length in the file's unit), ``offset`` or ``marker``, ``distance`` (default 0)
    and ``measured_in`` (the URDF frame the ball is fixed to; default the root).
    Residual: signed distance from the surface (1, m)."""

    name = "sphere"
    entity_field = "sphere"
    entity_min = 3  # its centre
    group_type = SphereContacts
    row_fields = ("distance_m",)
    components = (DISTANCE,)
    file_keys = ("sphere", "radius", "distance", *ProbeContactKind.probe_keys)

    # -- file edge
    def parse(self, reader, obs, at, frame):
        probe = self.probe_fields(reader, obs, at)
        distance = 0.0
        if "distance" in obs:  # absent: on the surface; null is refused
            distance = reader.number(
                obs, "distance", at, "the probe's signed distance from the ball (a length)"
            )
        radius = None
        if obs.get("radius") is not None:
            radius = reader.lengths(
                [reader.number(obs, "radius", at, "the ball's radius (a length)")]
            )[0]
            if radius < 0.0:
                raise reader.error(f"{at}.radius", f"a radius is >= 0, got {radius!r}")
        sphere = reader.optional_string(obs, "sphere", at) or "ball"
        key = (("frame", frame), ("sphere", sphere), ("radius", radius), *probe)
        return key, reader.lengths([distance])

    def group_from_rows(self, key, sample, rows):
        return SphereContacts(sample=sample, distance_m=rows[:, 0], **dict(key))

    def to_dicts(self, group, top_measured_in):
        return self.contact_dicts(
            group,
            {"sphere": group.sphere, **({} if group.radius is None else {"radius": group.radius})},
            [{"distance": d} if d != 0.0 else {} for d in group.distance_m.tolist()],
        )

    # -- estimation
    def unknowns(self, group, start: StartContext):
        """Closed form: the probe offset of the lifted linear system
        (:func:`lifted_sphere_probe`; the frame's origin when it is not determined),
        then the ball through the start model's probe points (:func:`fit_sphere`; with a
        given radius the centre only; the probes' mean when no sphere is determined), in
        the frame the ball is fixed to."""
        T = start.meas_T(group.measured_in, group.frame, group.sample)
        R, t = T[:, :3, :3], T[:, :3, 3]
        o = group.offset
        if o is None:
            o = lifted_sphere_probe(R, t)
            o = np.zeros(3) if o is None else o
        p = R @ o + t
        ball = fit_sphere(p)
        if ball is None:
            ball = np.append(p.mean(axis=0), 0.0 if group.radius is None else group.radius)
        if group.radius is None:
            estimate, block = ball, SphereBlock.from_estimates
        else:
            estimate, block = ball[:3], PointBlock.from_estimates
        return (
            *self.offset_request(group, o, "ball contacts"),
            UnknownRequest(
                sphere_key(group.sphere),
                estimate[None],
                block,
                f"ball {group.sphere!r} (touched by {group.frame!r})",
            ),
        )

    def trained_unknowns(self, group):
        """The ball and an unknown probe offset: held-out contacts are scored by their
        distance from the trained ball."""
        return (sphere_key(group.sphere), *self.probe_unknowns(group))

    def data(self, group):
        return group.distance_m[:, None]

    def residual(self, group, model: SymbolicContext, m):
        ca = model.ca
        p = self.symbolic_probe(group, model)
        ball = model.value(sphere_key(group.sphere))
        radius = ball[3] if group.radius is None else group.radius
        return m[0] - (ca.norm_2(p - ball[0:3]) - radius)

    # -- numpy prediction, simulation (the default: Gaussian distance noise), drawing
    def _ball(self, group, model: NumericContext) -> tuple[NDArray[np.float64], float]:
        """The ball's centre (3,) and radius, metres."""
        ball = model.value(sphere_key(group.sphere))
        return ball[:3], float(ball[3] if group.radius is None else group.radius)

    def predict(self, group, model: NumericContext):
        """Signed distance (m, 1) of the probe from the ball's surface, metres."""
        c, r = self._ball(group, model)
        return (np.linalg.norm(self.probe(group, model) - c, axis=1) - r)[:, None]

    def drawing(self, group, model: NumericContext):
        """Measured: the point at the measured distance from the surface on the ray from
        the centre through the predicted probe (the contact point on the ball for a
        distance 0); predicted: the probe."""
        c, r = self._ball(group, model)
        p = self.probe(group, model)
        ray = (p - c) / np.linalg.norm(p - c, axis=1, keepdims=True)
        return Drawing(
            node_name("spheres", group.frame, group.sphere, marker=group.marker),
            self.in_model_frame(group, model, c + (r + group.distance_m)[:, None] * ray),
            None,
            self.in_model_frame(group, model, p),
        )
