"""The result of :func:`kinfw.identification.refine` and the units of its parameters.

:class:`RefineResult` (the joint least-squares estimate and its quality) and
:func:`parameter_unit` (the SI unit of a parameter or kinematic quantity by name), split
from :mod:`kinfw.identification`, which re-exports both.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from kinfw.identification.problem import (
    GroupResiduals,
    Identifiability,
    NoiseModel,
    RejectedObservation,
    Unknown,
)
from kinfw.model import CPCModel, Topology

__all__ = ["RefineResult", "parameter_unit"]

#: Fields whose values are angles (rad): chart tilts and rotations, CPC beta, URDF rpy.
_ANGLE_FIELDS = frozenset(
    {"b_tilt_1", "b_tilt_2", "rot_x", "rot_y", "rot_z", "beta", "roll", "pitch", "yaw"}
)
#: Fields whose values are lengths (m): CPC l, frame and point translations.
_LENGTH_FIELDS = frozenset({"l_x", "l_y", "l_z", "x", "y", "z"})
#: Fields without a unit: components of the CPC unit axis b, the motion sense.
_UNITLESS_FIELDS = frozenset({"b_x", "b_y", "b_z", "sign"})


def parameter_unit(owner: str, field: str, topology: Topology) -> str:
    """SI unit of a parameter or kinematic quantity named ``(owner, field)``.

    The parameters of a problem carry their units in their blocks
    (:attr:`RefineResult.parameter_units`, :attr:`LeastSquaresProblem.units`); this
    function names the units of the kinematic rows of :meth:`CPCModel.describe` and
    agrees with the blocks on the parameters (tested).

    Covers the names of :attr:`RefineResult.parameter_names` (the CPC chart of
    :attr:`kinfw.model.CPCModel.parameter_names`, ``("base", ...)``, ``(joint,
    "zero_offset")``, ``("target:name", ...)``, ``("frame:name", ...)``,
    ``("marker:name", ...)``, ``("offset:frame:point", ...)``) and the rows of
    :meth:`kinfw.model.CPCModel.describe`.

    Parameters
    ----------
    owner, field : str
        The parameter's name, e.g. ``("pan", "zero_offset")`` or ``("left_plate", "x")``.
    topology : Topology
        Joint names and types (``model.topology``): a revolute joint's ``zero_offset``
        is an angle, a prismatic joint's a length.

    Returns
    -------
    str
        ``"rad"``, ``"m"`` or ``"unitless"``.

    Raises
    ------
    ValueError
        For a field this function does not know, or the ``zero_offset`` of a name that
        is not a joint of ``topology``.
    """
    if field in _ANGLE_FIELDS:
        return "rad"
    if field in _LENGTH_FIELDS:
        return "m"
    if field in _UNITLESS_FIELDS:
        return "unitless"
    if field == "zero_offset":
        if owner not in topology.joint_names:
            raise ValueError(
                f"parameter ({owner!r}, 'zero_offset'): {owner!r} is not a joint "
                f"of the model; expected one of {list(topology.joint_names)}"
            )
        return "rad" if topology.revolute[topology.joint_names.index(owner)] else "m"
    raise ValueError(
        f"parameter ({owner!r}, {field!r}): unknown field; expected an angle "
        f"{sorted(_ANGLE_FIELDS)}, a length {sorted(_LENGTH_FIELDS)}, unitless "
        f"{sorted(_UNITLESS_FIELDS)} or 'zero_offset'"
    )


@dataclass(frozen=True, slots=True)
class RefineResult:
    """The joint least-squares estimate and its quality.

    Attributes
    ----------
    model : CPCModel
        Refined kinematics (end frames: every observed frame), in the model frame
        ``w``: the URDF root, or the one external measurement frame when every
        observation is in it (:attr:`model_frame`).
    model_frame : str or None
        None for the URDF root, else the external measurement frame's name.
    unknowns : tuple of Unknown
        Target poses, external frames, markers, point offsets.
    parameter_names : tuple of ParameterName
        Every estimated parameter ``(owner, field)``, in the order of ``estimate`` and
        ``covariance``.
    parameter_units : tuple of str
        SI unit of each parameter (``"rad"`` or ``"m"``), from its parameter block.
    free : ndarray of bool, shape (P,)
        The parameters estimated; the others are fixed at the start (``estimate`` 0,
        ``std`` 0), e.g. the base and the joint zero offsets with ``parameters="full"``.
    estimate : ndarray, shape (P,)
        Chart coordinates from the start (rad, m).
    covariance : ndarray, shape (P, P)
        ``sigma_hat^2 (J^T J)^+`` in SI units, on the identifiable subspace.
    noise : NoiseModel
        The whitening used (given or estimated).
    sigma_hat2 : float
        Reduced chi-square of the whitened residuals (1 when the noise model fits).
    residuals : tuple of GroupResiduals
    downweighted : tuple of (kind, frame, sample, weight)
        Observations in the fit beyond the robust loss's threshold (empty for least
        squares), with the weight they got; the rejected ones are not among them.
    identifiability : Identifiability
    iterations : int
    converged : bool
    cost : float
        Half the sum of squared whitened residuals (after robust weights).
    seconds : float
    rejected : tuple of RejectedObservation
        Observations excluded as gross errors (not in the fit; ``residuals`` and the
        noise estimate are of the others), the worst (largest ``excess``) first; their
        residuals are against this fit (against the fit that rejected them only when
        the rejection removed a whole unknown, e.g. a marker's every observation).
    rejection_note : str or None
        Why fewer observations were rejected than the threshold asked (more than the
        allowed fraction beyond it: the data may be inconsistent with the model), or
        why none could be (the rest would not determine the problem); None otherwise.
    """

    model: CPCModel
    model_frame: str | None
    unknowns: tuple[Unknown, ...]
    parameter_names: tuple[tuple[str, str], ...]
    parameter_units: tuple[str, ...]
    free: NDArray[np.bool_]
    estimate: NDArray[np.float64]
    covariance: NDArray[np.float64]
    noise: NoiseModel
    sigma_hat2: float
    residuals: tuple[GroupResiduals, ...]
    downweighted: tuple[tuple[str, str, int, float], ...]
    identifiability: Identifiability
    iterations: int
    converged: bool
    cost: float
    seconds: float = field(default=0.0)
    rejected: tuple[RejectedObservation, ...] = ()
    rejection_note: str | None = None

    @property
    def std(self) -> NDArray[np.float64]:
        """Standard deviation of each parameter (rad, m)."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))
