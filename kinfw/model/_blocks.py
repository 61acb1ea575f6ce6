"""Parameter blocks: the kinds of unknown an estimation problem is made of.

A block is a frozen dataclass that knows its key, the name and SI unit of each entry,
its start value, which entries are free, and its value at chart coordinates ``d`` (its
slice of the problem's vector ``x``, zero at the start) in numpy and in CasADi:

- :class:`RigidFrameBlock`: a rigid frame in the chart of :mod:`kinfw.geometry` (6 entries
  ``rot_x..z`` rad, ``x..z`` m) - a target, a marker, an external frame;
- :class:`PointBlock`: a point (3 entries ``x, y, z`` m) - an unknown point offset.

Blocks of the robot's own kinematics are :class:`RobotBlock` s: besides their value they
say how they enter the forward kinematics (hooks on the joint values before the CPC
model, on the end-frame poses after it, and on a numeric CPC model), so the problem
finds them by this role and key, never by position:

- :class:`CPCBlock` (key :data:`CPC_KEY`): the identifiable CPC parameters of the whole
  tree (axis tilts ``b_tilt_1/2`` rad, offsets ``l_x/l_y`` m, tool ``rot_x..z`` rad and
  ``x..z`` m): the forward kinematics itself;
- :class:`BaseBlock`: the base, a rigid frame before the whole model;
- :class:`ZeroOffsetBlock`: one zero offset per joint (rad revolute, m prismatic), added
  to the joint values;
- any block an application defines (a joint's gear scale:
  ``tests/identification/problem/test_robot_block.py``),
  passed to :func:`kinfw.identification.refine` (``extra_blocks``).

Parameters are named by typed keys (:class:`ParameterName`, :class:`BlockKey`); nothing
parses a name back from a string.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import rigid_from_chart, rigid_from_chart_casadi

if TYPE_CHECKING:
    from kinfw.model._cpc import CPCModel
    from kinfw.model._loads import BlockSamples

_RIGID_FIELDS = ("rot_x", "rot_y", "rot_z", "x", "y", "z")
_RIGID_UNITS = ("rad", "rad", "rad", "m", "m", "m")


class ParameterName(NamedTuple):
    """One estimated number: its owner (a joint, an end frame, or a block such as
    ``"target:board"``) and field (``"b_tilt_1"``, ``"rot_x"``, ``"zero_offset"``...).
    Equal to the plain tuple ``(owner, field)``."""

    owner: str
    field: str


@dataclass(frozen=True, slots=True)
class BlockKey:
    """Identity of a block: its kind (``"cpc"``, ``"base"``, ``"zero_offset"``,
    ``"target"``, ``"frame"``, ``"marker"``, ``"offset"``, or a new kind's own) and name."""

    kind: str
    name: str = ""

    def __str__(self) -> str:
        return f"{self.kind}:{self.name}" if self.name else self.kind


CPC_KEY = BlockKey("cpc")
"""The key of the problem's :class:`CPCBlock`."""


def _free_mask(free: ArrayLike | None, size: int) -> NDArray[np.bool_]:
    mask = np.ones(size, bool) if free is None else np.array(free, dtype=bool)
    if mask.shape != (size,):
        raise ValueError(f"free: expected shape ({size},), got {mask.shape}")
    mask.flags.writeable = False
    return mask


@dataclass(frozen=True, slots=True)
class Block:
    """Base of all blocks (see the module docstring).

    Attributes
    ----------
    key : BlockKey
    free : ndarray of bool, shape (size,)
        Entries estimated; the others stay at the start (gauge or user choice).
    """

    key: BlockKey
    free: NDArray[np.bool_] = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        object.__setattr__(self, "free", _free_mask(self.free, self.size))

    @property
    def fields(self) -> tuple[str, ...]:
        raise NotImplementedError

    @property
    def units(self) -> tuple[str, ...]:
        """SI unit of each entry (``"rad"``, ``"m"``, ``"unitless"``...): the one source
        of the parameters' units (:attr:`kinfw.identification.RefineResult.parameter_units`)."""
        raise NotImplementedError

    @property
    def size(self) -> int:
        return len(self.fields)

    @property
    def owner(self) -> str:
        """Display owner of the entries (the key as ``kind:name``)."""
        return str(self.key)

    @property
    def names(self) -> tuple[ParameterName, ...]:
        return tuple(ParameterName(self.owner, f) for f in self.fields)

    def with_free(self, free: ArrayLike) -> Block:
        """The same block with another free mask."""
        from dataclasses import replace

        return replace(self, free=np.asarray(free, dtype=bool))

    def constants(self) -> NDArray[np.float64]:
        """The numbers of the block's start that its CasADi value takes as an input (so
        that one graph serves every start); empty by default."""
        return np.zeros(0)

    def numpy_value(self, d: NDArray[np.float64]) -> Any:
        """The block's value at chart coordinates ``d`` (size,)."""
        raise NotImplementedError

    def casadi_value(self, d: Any, c: Any = None) -> Any:
        """The same as a CasADi expression of ``d`` (SX or MX, size entries), with the
        start from ``c`` (symbols of :meth:`constants`) or, when None, embedded."""
        raise NotImplementedError

    def describe(self) -> str:
        return f"{self.key.kind} {self.key.name!r}"

    def undetermined(
        self, d: NDArray[np.float64], covariance: NDArray[np.float64]
    ) -> tuple[tuple[tuple[ParameterName, ...], str], ...]:
        """Entries the fit left poorly determined though the Jacobian has full rank
        (``d`` the estimate's chart coordinates, ``covariance`` the block's (size, size)
        covariance): ``((names, why), ...)``, added to the identifiability report.
        None by default (the rank test of the diagnostics decides)."""
        return ()


@dataclass(frozen=True, slots=True)
class RobotBlock(Block):
    """A block of the robot's kinematics (not an unknown of an observation kind).

    The problem finds robot blocks by this role and their key, and predicts the end
    frames' poses at the joint readings ``q`` (model joint order) as

    1. ``q' = joint_values_k(... joint_values_1(q))``: :meth:`casadi_joint_values` of
       every robot block, in the problem's order (the CPC chart, the base, the extra
       blocks, the zero offsets: ``q' = (1 + s) q + z`` with a gear scale ``s``);
    2. ``w_T_e = FK(q')``: the CPC model of the :class:`CPCBlock` at its chart
       coordinates (:func:`kinfw.model.cpc_fk_function`);
    3. ``w_T_e = frame_poses_k(... frame_poses_1(w_T_e))``: :meth:`casadi_frame_poses`
       of every robot block (the base multiplies on the left).

    Every hook must be the identity at the block's start (``d = 0``), so that the start
    model is the CPC block's. :meth:`moved_model` is the numeric side (the result's
    model, :meth:`kinfw.identification.problem.LeastSquaresProblem.model_at`) and
    :meth:`free_for` the free mask by parameter set. A hook may embed numbers of the
    block's key (a joint's name) but takes its start values through ``c``
    (:meth:`~Block.constants`): the CasADi graph is cached by the blocks' types, keys
    and sizes.
    """

    def free_for(self, parameters: str | tuple[str, ...]) -> NDArray[np.bool_]:
        """The entries estimated under a parameter set of
        :func:`kinfw.identification.refine` (``"full"``, ``"offsets"``, ``"frames"``,
        ``"none"`` or a mask of joints), for a block given to it (``extra_blocks``).

        Default: the block's own :attr:`free` with ``"full"``, none with the smaller
        sets (they keep the nominal joints). The built-in blocks' masks depend on the
        data too; :func:`kinfw.identification.problem.robot_blocks` sets them.
        """
        return self.free.copy() if parameters == "full" else np.zeros(self.size, bool)

    #: Where the block's joint hook acts: ``"readings"`` (a map of the encoder readings,
    #: before the joint zero offsets: a gear scale, a coupling) or ``"deflection"`` (on the
    #: physical joint values, after the offsets: a joint's compliance under load).
    stage: ClassVar[str] = "readings"

    def for_data(self, context: BlockSamples) -> RobotBlock:
        """The block as the problem uses it on these data (``context``: the robot, the
        model's joints, the readings, payloads and gravity): its free mask narrowed to
        what the data determine, or a clear error when they cannot (a compliance on links
        without inertias). Default: unchanged."""
        return self

    def sample_width(self, joint_names: tuple[str, ...]) -> int:
        """Numbers per sample the hooks take besides the readings (see
        :meth:`sample_inputs`); 0 by default."""
        return 0

    def sample_inputs(self, context: BlockSamples) -> NDArray[np.float64]:
        """The per-sample numbers (n, :meth:`sample_width`) the CasADi hook takes as ``s``
        (a sample's gravity torque and its derivative), computed once per problem with
        numpy and Pinocchio from the robot and the samples of ``context``."""
        return np.zeros((len(context.qs), 0))

    def casadi_joint_values(
        self, q: Any, d: Any, c: Any, joint_names: tuple[str, ...], s: Any = None
    ) -> Any:
        """The joint values the forward kinematics takes: ``q`` (SX, (J,), rad and m,
        in the order of ``joint_names``) changed by the block at chart coordinates
        ``d`` (SX, (size,)) with its constants ``c`` and its per-sample inputs ``s``
        (SX, (:meth:`sample_width`,)). Default: ``q`` unchanged."""
        return q

    def joint_values(
        self, q: NDArray[np.float64], context: BlockSamples, d: NDArray[np.float64] | None = None
    ) -> NDArray[np.float64]:
        """The numeric side of :meth:`casadi_joint_values`: joint values ``q`` (n, J) of
        ``context``'s joints changed by the block at ``d`` (default its start), for the
        samples of ``context``. Default: the CasADi hook evaluated numerically."""
        import casadi as ca

        d = np.zeros(self.size) if d is None else np.asarray(d, dtype=float)
        names = context.joint_names
        q_sym = ca.SX.sym("q", len(names))
        s_sym = ca.SX.sym("s", self.sample_width(names))
        c_sym = ca.SX.sym("c", len(self.constants()))
        d_sym = ca.SX.sym("d", self.size)
        f = ca.Function(
            "joint_values",
            [q_sym, s_sym, d_sym, c_sym],
            [self.casadi_joint_values(q_sym, d_sym, c_sym, names, s_sym)],
        ).map(len(q))
        out = f(np.asarray(q, dtype=float).T, self.sample_inputs(context).T, d, self.constants())
        return np.asarray(out).T.reshape(np.shape(q))

    def readings(
        self, q: NDArray[np.float64], context: BlockSamples, tol: float = 1e-13
    ) -> NDArray[np.float64]:
        """The inverse of :meth:`joint_values` at the block's start: the readings that
        give the joint values ``q`` (n, J) (a joint command with the deflection
        compensated). ``context.qs`` is ignored: the block's inputs are evaluated at
        each iterate. Default: the fixed point ``r = r - (joint_values(r) - q)``, which
        converges for a map close to the identity (every shipped block)."""
        r = np.array(q, dtype=float)
        for _ in range(100):
            step = self.joint_values(r, context.at(r)) - q
            r -= step
            if np.abs(step).max(initial=0.0) < tol:
                return r
        raise ValueError(f"{self.describe()}: the readings for these joint values do not converge")

    def casadi_frame_poses(self, w_T_frames: dict[str, Any], d: Any, c: Any) -> dict[str, Any]:
        """The end frames' poses after the forward kinematics (SX (4, 4) by frame name,
        metres) changed by the block at ``d``. Default: unchanged."""
        return w_T_frames

    def moved_model(self, model: CPCModel, d: NDArray[np.float64]) -> CPCModel:
        """The numeric CPC model ``model`` with the block at chart coordinates ``d``
        (size,) folded in: its forward kinematics at the joint readings is the
        problem's prediction through this block's hooks.

        A block whose effect no CPC model holds (a joint's gear scale) returns
        ``model``: the result's model is then the kinematics of the joint values after
        its hook, and the block's estimate stands beside it (by name in
        :attr:`kinfw.identification.RefineResult.parameter_names`).
        """
        raise NotImplementedError(
            f"{type(self).__name__}: moved_model: fold the block into a CPC model, or "
            "return the model unchanged when the block's effect is not a CPC geometry"
        )


@dataclass(frozen=True, slots=True)
class RigidFrameBlock(Block):
    """A rigid frame ``start [cayley(d[:3] / 2) | d[3:]]`` (:mod:`kinfw.geometry`).

    Attributes
    ----------
    start : ndarray, shape (4, 4)
        Start pose (metres).
    """

    start: NDArray[np.float64] = field(default_factory=lambda: np.eye(4))

    @property
    def fields(self) -> tuple[str, ...]:
        return _RIGID_FIELDS

    @property
    def units(self) -> tuple[str, ...]:
        return _RIGID_UNITS

    @staticmethod
    def from_estimates(key: BlockKey, estimates: NDArray[np.float64]) -> RigidFrameBlock:
        """The chordal mean of per-sample pose estimates (k, 4, 4) as the start."""
        from kinfw.geometry import average_transform

        return RigidFrameBlock(key, start=average_transform(estimates))

    def constants(self) -> NDArray[np.float64]:
        """The start's rotation (9, column-major) and position (3)."""
        return np.concatenate([self.start[:3, :3].T.reshape(9), self.start[:3, 3]])

    def numpy_value(self, d: NDArray[np.float64]) -> NDArray[np.float64]:
        return rigid_from_chart(self.start, d)

    def casadi_value(self, d: Any, c: Any = None) -> Any:
        if c is None:
            return rigid_from_chart_casadi(self.start, d)
        import casadi as ca

        return rigid_from_chart_casadi((ca.reshape(c[0:9], 3, 3), c[9:12]), d)

    def coordinates(self, T: ArrayLike) -> NDArray[np.float64]:
        """Chart coordinates (6,) of a pose ``T`` (4, 4): the inverse of the value."""
        from kinfw.geometry import chart_from_rigid

        return chart_from_rigid(self.start, T)


@dataclass(frozen=True, slots=True)
class PointBlock(Block):
    """A point ``start + d`` (metres).

    Attributes
    ----------
    start : ndarray, shape (3,)
    """

    start: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))

    @property
    def fields(self) -> tuple[str, ...]:
        return ("x", "y", "z")

    @property
    def units(self) -> tuple[str, ...]:
        return ("m", "m", "m")

    @staticmethod
    def from_estimates(key: BlockKey, estimates: NDArray[np.float64]) -> PointBlock:
        """The mean of per-sample point estimates (k, 3) as the start."""
        return PointBlock(key, start=np.asarray(estimates, dtype=float).mean(axis=0))

    def constants(self) -> NDArray[np.float64]:
        return np.asarray(self.start, dtype=float)

    def numpy_value(self, d: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.start + d

    def casadi_value(self, d: Any, c: Any = None) -> Any:
        import casadi as ca

        start = ca.DM(self.start) if c is None else c[0:3]
        return start + ca.vertcat(d[0], d[1], d[2])

    def coordinates(self, p: ArrayLike) -> NDArray[np.float64]:
        return np.asarray(p, dtype=float) - self.start


@dataclass(frozen=True, slots=True)
class CPCBlock(RobotBlock):
    """The identifiable CPC parameters of a tree (:meth:`kinfw.model.CPCModel.perturbed`):
    the forward kinematics of the problem (key :data:`CPC_KEY`), whose value at ``d`` is
    the model the other robot blocks move (:meth:`RobotBlock.moved_model`).

    Attributes
    ----------
    model : CPCModel
        The chart's origin. Its value at ``d`` is ``model.perturbed(d)``; in CasADi the
        FK of :func:`kinfw.model.cpc_fk_function` takes ``d`` directly.
    """

    model: CPCModel = None  # type: ignore[assignment]

    def __post_init__(self) -> None:
        if self.model is None:
            raise ValueError("CPCBlock: model is required")
        Block.__post_init__(self)

    @property
    def fields(self) -> tuple[str, ...]:
        return tuple(f for _, f in self.model.parameter_names)

    @property
    def names(self) -> tuple[ParameterName, ...]:
        return tuple(ParameterName(o, f) for o, f in self.model.parameter_names)

    @property
    def units(self) -> tuple[str, ...]:
        return tuple("rad" if f.startswith(("b_tilt", "rot")) else "m" for f in self.fields)

    @property
    def size(self) -> int:
        return self.model.n_parameters

    def constants(self) -> NDArray[np.float64]:
        """The reference model's numbers (:func:`kinfw.model.cpc_reference_vector`)."""
        from kinfw.model._cpc_casadi import cpc_reference_vector

        return cpc_reference_vector(self.model)

    def numpy_value(self, d: NDArray[np.float64]) -> CPCModel:
        return self.model.perturbed(d)

    def casadi_value(self, d: Any, c: Any = None) -> Any:
        """The chart coordinates themselves: the forward kinematics
        (:func:`kinfw.model.cpc_fk_function`) takes them with the constants."""
        return d

    def describe(self) -> str:
        return "CPC parameters"


@dataclass(frozen=True, slots=True)
class ZeroOffsetBlock(RobotBlock):
    """One zero offset per joint: the model is evaluated at ``q + d``.

    Attributes
    ----------
    joint_names : tuple of str
        The model's joints, in its order.
    revolute : tuple of bool
        Per joint: offsets in rad (revolute) or m (prismatic).
    """

    joint_names: tuple[str, ...] = ()
    revolute: tuple[bool, ...] = ()

    @property
    def fields(self) -> tuple[str, ...]:
        return ("zero_offset",) * len(self.joint_names)

    @property
    def names(self) -> tuple[ParameterName, ...]:
        return tuple(ParameterName(j, "zero_offset") for j in self.joint_names)

    @property
    def units(self) -> tuple[str, ...]:
        return tuple("rad" if r else "m" for r in self.revolute)

    @property
    def size(self) -> int:
        return len(self.joint_names)

    def numpy_value(self, d: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(d, dtype=float)

    def casadi_value(self, d: Any, c: Any = None) -> Any:
        return d

    def _check_joints(self, joint_names: tuple[str, ...]) -> None:
        if tuple(joint_names) != self.joint_names:
            raise ValueError(
                f"ZeroOffsetBlock: joints {list(self.joint_names)}, the model's are "
                f"{list(joint_names)}"
            )

    def casadi_joint_values(
        self, q: Any, d: Any, c: Any, joint_names: tuple[str, ...], s: Any = None
    ) -> Any:
        self._check_joints(joint_names)
        return q + d

    def moved_model(self, model: CPCModel, d: NDArray[np.float64]) -> CPCModel:
        """FK(q + d) as a CPC model: every joint pre-moved by its offset (the geometry at
        ``q = 0`` of the offset model is the original geometry at ``q = d``)."""
        from kinfw.model._cpc import ZeroGeometry, cpc_from_geometry

        self._check_joints(model.topology.joint_names)
        if not np.any(d):
            return model
        moved = model.joint_frames(d)[0]
        geometry = ZeroGeometry(
            model.topology,
            moved[:, :3, 2] * model.sign[:, None],
            moved[:, :3, 3].copy(),
            model.frame_poses(d),
        )
        return cpc_from_geometry(geometry, sign=model.sign)

    def describe(self) -> str:
        return "joint zero offsets"


@dataclass(frozen=True, slots=True)
class BaseBlock(RobotBlock, RigidFrameBlock):
    """The base: a rigid frame ``w_T_base`` (chart of :class:`RigidFrameBlock`) before
    the whole model, ``w_T_e = w_T_base FK(q)``."""

    def casadi_frame_poses(self, w_T_frames: dict[str, Any], d: Any, c: Any) -> dict[str, Any]:
        w_T_base = self.casadi_value(d, c)
        return {f: w_T_base @ T for f, T in w_T_frames.items()}

    def moved_model(self, model: CPCModel, d: NDArray[np.float64]) -> CPCModel:
        """The model's screw axes and end frames moved by the base, canonical again."""
        from kinfw.model._cpc import ZeroGeometry, cpc_from_geometry, geometry_from_cpc

        w_T_base = self.numpy_value(d)
        if np.array_equal(w_T_base, np.eye(4)):
            return model
        R, t = w_T_base[:3, :3], w_T_base[:3, 3]
        geometry = geometry_from_cpc(model)
        moved = ZeroGeometry(
            geometry.topology,
            geometry.axes @ R.T,
            geometry.points @ R.T + t,
            w_T_base @ geometry.w_T_frames,
        )
        return cpc_from_geometry(moved, sign=model.sign)


@dataclass(frozen=True, slots=True)
class SpecBlock(RobotBlock):
    """A robot block a model spec names (``--model compliance``, ``gear-scale:JOINT``...):
    registered by name (:func:`kinfw.model.register_block`), rebuilt from its text
    (:meth:`from_spec`, :attr:`spec`) and its values (:attr:`start`), so that a sidecar
    records it and verify, reach, view and export re-apply it.

    Its value is ``start + d``: a calibrated block is the spec's block started at the
    estimate (:meth:`with_start`), its hooks the same graph at other constants. What no
    URDF holds stands beside the model (:meth:`moved_model` returns it unchanged).

    Attributes
    ----------
    start : ndarray, shape (size,)
        The value at chart coordinates zero (default zeros: the rigid, URDF model).
    """

    start: NDArray[np.float64] = field(default=None)  # type: ignore[assignment]

    #: The spec's name (the text before ``:``), unique in the registry.
    block_name: ClassVar[str] = ""

    def __post_init__(self) -> None:
        RobotBlock.__post_init__(self)
        start = np.zeros(self.size) if self.start is None else np.array(self.start, float)
        if start.shape != (self.size,):
            raise ValueError(
                f"{self.spec}: start: expected shape ({self.size},), got {start.shape}"
            )
        start.flags.writeable = False
        object.__setattr__(self, "start", start)

    @classmethod
    def from_spec(cls, argument: str) -> SpecBlock:
        """The block of the spec text ``NAME:ARGUMENT`` (``argument`` after the colon,
        empty without one); a ValueError saying the expected form otherwise."""
        raise NotImplementedError

    @property
    def argument(self) -> str:
        """The text after ``NAME:`` that :meth:`from_spec` rebuilds the block from."""
        return self.key.name

    @property
    def spec(self) -> str:
        """The spec text: ``NAME`` or ``NAME:ARGUMENT``."""
        return f"{self.block_name}:{self.argument}" if self.argument else self.block_name

    def with_start(self, values: ArrayLike) -> SpecBlock:
        """The same block started at ``values`` (size,): a calibrated block."""
        from dataclasses import replace

        return replace(self, start=np.asarray(values, dtype=float))

    def free_for(self, parameters: str | tuple[str, ...]) -> NDArray[np.bool_]:
        """Named by the user: estimated under every parameter set but ``"none"``."""
        return self.free.copy() if parameters != "none" else np.zeros(self.size, bool)

    def constants(self) -> NDArray[np.float64]:
        return self.start.copy()

    def numpy_value(self, d: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.start + np.asarray(d, dtype=float)

    def casadi_value(self, d: Any, c: Any = None) -> Any:
        return (self.start if c is None else c) + d

    def moved_model(self, model: CPCModel, d: NDArray[np.float64]) -> CPCModel:
        """Unchanged: no CPC model (no URDF) holds the block; it stands beside the model."""
        return model

    def describe(self) -> str:
        return self.spec
