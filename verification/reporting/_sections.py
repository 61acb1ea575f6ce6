"""The sections of a calibration report built from the pipeline's stage results: the
closed form (:class:`kinfw.identification.ClosedFormResult`), the hand-eye step
(:class:`kinfw.identification.handeye.CamerasResult`) and the joint refinement
(:class:`kinfw.identification.RefineResult`), as the typed sections of
:mod:`kinfw.records` (:func:`kinfw.verification.reporting.calibration_report` puts
them together)."""

from __future__ import annotations

import numpy as np

from kinfw.identification import ClosedFormResult, RefineResult
from kinfw.identification.handeye import CamerasResult
from kinfw.observations import kind_named
from kinfw.records import (
    CalibratedUnknown,
    CameraMount,
    ClosedFormSection,
    Correlation,
    DownweightedRow,
    ErrorValue,
    HandEyeSection,
    IdentifiabilitySummary,
    KinematicValue,
    NoiseSummary,
    NotIdentifiable,
    ParameterRow,
    RefineSection,
    RejectedRow,
    TargetEstimate,
)


def _kinematic_values(model) -> tuple[KinematicValue, ...]:
    return tuple(KinematicValue(o, n, v, unit) for o, n, v, unit in model.describe())


def closed_form_section(result: ClosedFormResult) -> ClosedFormSection:
    """The report's stage 1 section from Shih et al.'s closed form.

    Parameters
    ----------
    result : ClosedFormResult

    Returns
    -------
    ClosedFormSection
        Per joint its samples, axis-fit residual (rad) and motion per unit joint value,
        the position RMS (mm) and the canonical CPC parameters with their units.
    """
    model = result.model
    return ClosedFormSection(
        joint_names=tuple(model.topology.joint_names),
        frames=tuple(model.topology.frames),
        q0=tuple(result.q0.tolist()),
        samples_per_joint=tuple(result.group_sizes.tolist()),
        axis_residual_rad=tuple(float(v) for v in result.axis_residual_rad),
        motion_per_unit_joint_value=tuple(result.motion_scale.tolist()),
        position_rms_mm=1e3 * result.position_rms_m,
        values=_kinematic_values(model),
        n_identifiable=model.n_parameters,
    )


def hand_eye_section(result: CamerasResult) -> HandEyeSection:
    """The report's stage 2 section from the hand-eye step.

    Parameters
    ----------
    result : CamerasResult

    Returns
    -------
    HandEyeSection
        Every camera's ``hand_T_camera`` (m) with the solver's iterations and RMS
        residuals (deg, mm), and every target's ``root_T_target`` (m) with how far the
        cameras disagree on it (mm, deg).
    """
    return HandEyeSection(
        cameras=tuple(
            CameraMount(
                c.camera,
                c.target,
                c.joint,
                c.hand,
                c.hand_T_camera,
                c.n_views,
                c.solver.iterations,
                c.solver.restarts,
                c.solver.converged,
                float(np.degrees(c.solver.rms_rotation_rad)),
                1e3 * c.solver.rms_translation,
            )
            for c in result.cameras
        ),
        targets=tuple(
            TargetEstimate(t, T, 1e3 * dp, float(np.degrees(dr)))
            for (t, T), (_, dp, dr) in zip(result.root_T_targets, result.target_spread, strict=True)
        ),
    )


def _residual_values(kind: str, sizes: dict[str, float]) -> tuple[ErrorValue, ...]:
    """Per noise component of ``kind`` with a size in ``sizes`` (SI, by component
    name), that size in the component's metric: ``position_residual_mm``, ..."""
    out = []
    for c in kind_named(kind).components:
        if c.name in sizes:
            m = c.display
            out.append(ErrorValue(m.name, m.unit, "residual", m.scale * float(sizes[c.name])))
    return tuple(out)


def downweighted_rows(result: RefineResult) -> tuple[DownweightedRow, ...]:
    """The observations the robust loss down-weighted, the worst (lowest weight) first.

    Parameters
    ----------
    result : RefineResult

    Returns
    -------
    tuple of DownweightedRow
        One per down-weighted observation: ``sample`` (index into the data file's
        ``samples``, from 0), ``kind``, ``frame`` (the camera for ``target``
        observations), ``marker`` (None without one), the size of its residual in the
        metric of each noise component of its kind (a pose's position error norm, mm,
        and rotation angle, deg; an image point's reprojection error, px; a plane
        contact's height, mm; :meth:`kinfw.observations.NoiseComponent.magnitude`),
        ``weight`` (the robust loss's weight, 1 = full) and ``where`` (an image's
        corner). Sorted by weight, then sample.
    """
    rows = []
    for g in result.residuals:
        rows_g = np.flatnonzero(g.downweighted)
        components = {c.name: c for c in kind_named(g.kind).components}
        sizes = {n: components[n].magnitude(v[rows_g]) for n, v in g.components}
        rows += [
            DownweightedRow(
                int(g.sample[k]),
                g.kind,
                g.frame,
                g.marker,
                _residual_values(g.kind, {n: v[c] for n, v in sizes.items()}),
                float(g.weight[k]),
                None if g.labels is None else g.labels[k],
            )
            for c, k in enumerate(rows_g)
        ]
    rows.sort(key=lambda row: (row.weight, row.sample))
    return tuple(rows)


def rejected_rows(result: RefineResult) -> tuple[RejectedRow, ...]:
    """The observations rejected (beyond the rejection threshold), the worst (largest
    excess over it) first.

    Parameters
    ----------
    result : RefineResult

    Returns
    -------
    tuple of RejectedRow
        One per :attr:`RefineResult.rejected` entry: ``sample`` (index into the data
        file's samples, from 0), ``kind``, ``frame``, ``marker``, the size of its
        residual against the final fit in the metric of each noise component of its kind
        (as :func:`downweighted_rows`), ``excess`` (its whitened norm over the
        threshold) and ``clean_tail`` (clean data reach that far:
        :attr:`kinfw.identification.problem.RejectedObservation.clean_tail`). Sorted by
        excess, largest first, then sample.
    """
    rows = [
        RejectedRow(
            o.sample,
            o.kind,
            o.frame,
            o.marker,
            _residual_values(o.kind, {n: v for n, _, v in o.residuals}),
            o.excess,
            o.where,
            o.clean_tail,
        )
        for o in result.rejected
    ]
    rows.sort(key=lambda row: (-row.excess, row.sample))
    return tuple(rows)


def noise_summary(result: RefineResult) -> NoiseSummary:
    """The noise of the components the data has (a default sigma of a component without
    rows, the 1 mm position of pixel-only data, whitened nothing and is not reported).

    Parameters
    ----------
    result : RefineResult

    Returns
    -------
    NoiseSummary
        ``(component, sigma)`` in SI of each component with rows, and whether estimated.
    """
    present = {name for g in result.residuals for name, _ in g.components}
    return NoiseSummary(
        tuple((k, v) for k, v in result.noise.sigmas if k in present), result.noise.estimated
    )


def calibrated_unknowns(result: RefineResult) -> tuple[CalibratedUnknown, ...]:
    """The unknowns the refinement estimated (target poses, markers, point offsets,
    external frames, ...), as written in the report and the sidecar.

    Parameters
    ----------
    result : RefineResult

    Returns
    -------
    tuple of CalibratedUnknown
        ``(kind, name, value)``, value a (4, 4) pose or a (3,) point in metres, in the
        result's order.
    """
    return tuple(CalibratedUnknown(u.kind, u.name, u.value) for u in result.unknowns)


def refine_section(result: RefineResult, loss: str) -> RefineSection:
    """The report's joint least squares section.

    Parameters
    ----------
    result : RefineResult
    loss : str
        The robust loss the refinement used (``"huber"``, ...), as reported.

    Returns
    -------
    RefineSection
        Noise, reduced chi-square, convergence, every parameter's change and standard
        deviation in its block's unit, the calibrated kinematics and unknowns,
        identifiability (undefined or infinite numbers as None) and the down-weighted
        and rejected observations.
    """
    ident = result.identifiability
    return RefineSection(
        loss=loss,
        noise=noise_summary(result),
        reduced_chi_square=result.sigma_hat2,
        iterations=result.iterations,
        converged=result.converged,
        seconds=result.seconds,
        model_frame=result.model_frame,
        # units from the parameter blocks (RefineResult.parameter_units)
        parameters=tuple(
            ParameterRow(o, f, unit, not free, float(d), float(sd) if free else None)
            for (o, f), unit, free, d, sd in zip(
                result.parameter_names,
                result.parameter_units,
                result.free,
                result.estimate,
                result.std,
                strict=True,
            )
        ),
        kinematics=_kinematic_values(result.model),
        unknowns=calibrated_unknowns(result),
        identifiability=IdentifiabilitySummary(
            rank=ident.rank,
            n_parameters=ident.n_parameters,
            # strict JSON: an undefined (no parameters) or infinite value is None (null)
            condition=_finite_or_none(ident.condition),
            observability_o1=_finite_or_none(ident.observability_o1),
            not_identifiable=tuple(
                NotIdentifiable(tuple(":".join(p) for p in params), why)
                for params, why in ident.unidentifiable
            ),
            correlations=tuple(Correlation(a, b, r) for a, b, r in ident.correlations),
        ),
        downweighted=downweighted_rows(result),
        rejected=rejected_rows(result),
        rejection_note=result.rejection_note,
    )


def _finite_or_none(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None
