"""The result of :func:`kinfw.identification.refine`: :class:`RefineResult`, the joint
least-squares estimate and its quality (re-exported by :mod:`kinfw.identification`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from kinfw.identification.problem._diagnostics import (
    GroupResiduals,
    Identifiability,
    RejectedObservation,
)
from kinfw.identification.problem._noise import NoiseModel
from kinfw.identification.problem._problem import Unknown
from kinfw.model import CPCModel, ModelSpec, PriorScales


@dataclass(frozen=True, slots=True)
class RefineResult:
    """The joint least-squares estimate and its quality.

    Attributes
    ----------
    model : CPCModel
        Refined kinematics (end frames: every observed frame), in the model frame
        ``w``: the URDF root, or the one external measurement frame when every
        observation is in it (:attr:`model_frame`); the robot blocks folded in
        (base, zero offsets: :meth:`kinfw.model.RobotBlock.moved_model`). A robot block
        no CPC model holds (a joint's gear scale) is not in it: the model takes the joint
        values after that block's hook, and its estimate is in :attr:`estimate`.
    model_frame : str or None
        None for the URDF root, else the external measurement frame's name.
    unknowns : tuple of Unknown
        Target poses, external frames, markers, point offsets.
    parameter_names : tuple of ParameterName
        Every estimated parameter ``(owner, field)``, in the order of ``estimate`` and
        ``covariance``.
    parameter_units : tuple of str
        SI unit of each parameter (``"rad"``, ``"m"``, or what a block declares, e.g.
        ``"unitless"`` for a gear scale), from its parameter block
        (:attr:`kinfw.model.Block.units`, the one source of the units).
    free : ndarray of bool, shape (P,)
        The parameters estimated; the others are fixed at the start (``estimate`` 0,
        ``std`` 0), e.g. the base and the joint zero offsets with ``parameters="full"``.
    estimate : ndarray, shape (P,)
        Chart coordinates from the start, each in its parameter's unit.
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
    undetermined : float
        The size of the estimate's part along directions the data do not determine that
        the refinement could not bring back to the start (chart coordinates, m and rad;
        the unknowns' weighted by ``UNKNOWN_WEIGHT``): 0 when the model differs from the
        start only along what the data determine. Large when the fit did not converge
        on too little data (the calibration refuses it).
    noise_settled : bool
        Whether the noise estimate reached its fixed point (no sigma changed by more
        than ``NOISE_SETTLED`` of itself in the last round, after a converged round)
        before the noise rounds ran out; True when the noise was given.
    w_T_base : ndarray, shape (4, 4), or None
        The estimated rigid motion of the whole nominal robot in the model frame (the
        base block), folded into :attr:`model`; None when the parameter set left it
        fixed (``"full"``). The URDF export writes it into the root's fixed joint.
    residual_noise : NoiseModel or None
        With a stated noise (``noise`` given), the noise its residuals say: per noise
        component, the estimate of :func:`kinfw.identification.problem.estimate_noise`
        from the final residuals (robust: its median round, which neither a gross error
        nor a stated sigma far off moves), for checking the stated one
        (:func:`kinfw.identification.checks.stated_noise`); None when the noise was
        estimated.
    spec : ModelSpec
        The model spec's blocks (compliance, gear scales, couplings: ``extra_blocks``
        that are :class:`kinfw.model.SpecBlock` s) at their estimates: what stands beside
        :attr:`model`, which takes the joint values after their hooks
        (:meth:`kinfw.model.ModelSpec.joint_values`); empty without them.
    prior : PriorScales or None
        The prior's group sigmas the fit was made under, given or chosen from the data
        (``refine(choose_prior=True)``; :attr:`PriorScales.how` says which); None
        without a prior.
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
    undetermined: float = 0.0
    noise_settled: bool = True
    w_T_base: NDArray[np.float64] | None = None
    residual_noise: NoiseModel | None = None
    spec: ModelSpec = field(default_factory=ModelSpec)
    prior: PriorScales | None = None

    @property
    def std(self) -> NDArray[np.float64]:
        """Standard deviation of each parameter, in its unit."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))
