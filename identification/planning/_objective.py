"""The objective of measurement planning: the predicted held-out error of a calibration.

A calibration from configurations ``S`` estimates the free chart coordinates ``x`` of
the problem :func:`kinfw.identification.problem.build_problem` builds; to first order its
covariance is ``M(S)^-1`` with ``M(S) = sum_{i in S} J_i^T J_i`` the Fisher information
(``J_i``: the rows of the whitened Jacobian that configuration ``i`` contributes, at the
nominal model). The error it makes when it predicts the observed quantities at *other*
configurations (the test set) is ``G_t (x_hat - x)``; its mean square over the test set
is ``trace(A M^-1)`` with ``A = mean_t G_t^T G_t`` (:class:`HeldOut`). Minimising it is
I-optimal design (integrated prediction variance).

This module computes the pieces (:func:`candidate_information`, :func:`held_out`) and
optimises over a candidate pool (:func:`greedy`, :func:`exchange`); :func:`plan`
wraps them with the pool, the constraints and the plan file.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw import progress
from kinfw.camera import CameraIntrinsics
from kinfw.identification.problem import NoiseModel, build_problem
from kinfw.model import Robot
from kinfw.observations import NoiseComponent

#: Weight of the regularising prior of the design, relative to the mean information of
#: one candidate: small enough not to change a full-rank design's objective (1e-6 of a
#: candidate), large enough that the first greedy steps have an invertible matrix.
RIDGE = 1e-6


@dataclass(frozen=True, eq=False)
class Setup:
    """What is measured, how noisy, and which parameters are estimated.

    Attributes
    ----------
    frames : tuple of str
        Stage 1: frames of the robot measured by an external tracker in the root frame.
    frame_kind : {"pose", "point"}
        Stage 1: each frame's pose, or the position of its origin (a marker).
    cameras : tuple of str
        Stage 2: camera optical frames on the robot that see a fixed target.
    pixels : bool
        Stage 2 as the board's corners in pixels (else the board's pose, PnP).
    intrinsics : mapping of str to CameraIntrinsics
        Per camera (default :func:`kinfw.simulation.default_intrinsics`).
    board : str
        The target board (:func:`kinfw.camera.parse_board` spec).
    w_T_target : ndarray (4, 4) or None
        The board's pose in the root frame; None: facing the cameras at the middle of
        the joint ranges (:func:`kinfw.simulation.board_pose_facing`).
    noise_m, noise_rad : float
        Position noise per axis (m) and rotation noise angle (rad) of poses and points.
    pixel_sigma : float
        Pixel noise per image coordinate, px.
    parameters : str
        Parameter set of the calibration (``full``, ...), with its gauge.
    tracker_p : ndarray (3,) or None
        Tracker position in the root frame (stage 1); with it, a configuration is kept
        only when every measured frame's z axis is within ``max_facing_deg`` of the
        direction to the tracker.
    max_facing_deg : float
    """

    frames: tuple[str, ...] = ()
    frame_kind: str = "pose"
    cameras: tuple[str, ...] = ()
    pixels: bool = False
    intrinsics: Mapping[str, CameraIntrinsics] = field(default_factory=dict)
    board: str = "chessboard:9x6:0.04"
    w_T_target: NDArray[np.float64] | None = None
    noise_m: float = 5e-4
    noise_rad: float = float(np.radians(0.5))
    pixel_sigma: float = 0.5
    parameters: str = "full"
    tracker_p: NDArray[np.float64] | None = None
    max_facing_deg: float = 60.0

    def __post_init__(self) -> None:
        if not (self.frames or self.cameras):
            raise ValueError("Setup: give frames (stage 1) or cameras (stage 2)")
        if self.frame_kind not in ("pose", "point"):
            raise ValueError(
                f"Setup.frame_kind: expected 'pose' or 'point', got {self.frame_kind!r}"
            )
        for name in ("noise_m", "noise_rad", "pixel_sigma"):
            v = float(getattr(self, name))
            if not (np.isfinite(v) and v > 0.0):
                raise ValueError(f"Setup.{name}: expected a positive standard deviation, got {v}")

    @property
    def observed(self) -> tuple[str, ...]:
        return (*self.frames, *self.cameras)

    def noise(self) -> NoiseModel:
        return NoiseModel(self.noise_m, self.noise_rad, sigmas={"pixel": self.pixel_sigma})

    def camera_intrinsics(self) -> dict[str, CameraIntrinsics]:
        from kinfw.simulation import default_intrinsics

        return {c: self.intrinsics.get(c) or default_intrinsics(c) for c in self.cameras}

    def board_points(self) -> NDArray[np.float64]:
        from kinfw.camera import parse_board

        return parse_board(self.board).points

    def target_pose(self, robot: Robot, joint_names, q_mid: ArrayLike) -> NDArray[np.float64]:
        """``w_T_target``: the given one, or the board facing the cameras at ``q_mid``."""
        if self.w_T_target is not None:
            return np.asarray(self.w_T_target, dtype=float)
        from kinfw.simulation import board_pose_facing

        return board_pose_facing(robot, q_mid, joint_names, self.cameras, self.board_points())


def _simulate(
    robot: Robot, setup: Setup, qs: NDArray, names, w_T_target, *, as_poses: bool = False
):
    """Noise-free observations at ``qs`` (every sample kept) and the true unknowns."""
    from kinfw.simulation import simulate_at, simulate_pixels

    rng = np.random.default_rng(0)
    parts = []
    if setup.frames:
        if setup.frame_kind == "pose":
            parts.append(simulate_at(robot, qs, names, frames=setup.frames, rng=rng))
        else:
            markers = [(f, np.zeros(3)) for f in setup.frames]
            parts.append(simulate_at(robot, qs, names, markers=markers, rng=rng))
    if setup.cameras and setup.pixels and not as_poses:
        data, kept = simulate_pixels(
            robot,
            qs,
            names,
            cameras=setup.camera_intrinsics(),
            board_p=setup.board_points(),
            w_T_board=w_T_target,
            rng=rng,
            target="target",
        )
        if len(kept) != len(qs):
            raise ValueError(
                f"{len(qs) - len(kept)} of {len(qs)} configurations see no board; "
                "filter the pool first (kinfw.identification.planning.candidate_pool)"
            )
        parts.append(data)
    elif setup.cameras:
        parts.append(
            simulate_at(robot, qs, names, cameras=setup.cameras, rng=rng, w_T_target=w_T_target)
        )
    from kinfw.measurements import concatenate_measurements

    data = parts[0] if len(parts) == 1 else concatenate_measurements(*parts)
    targets = {"target": w_T_target} if setup.cameras else {}
    return data, targets


@dataclass(frozen=True, eq=False)
class CandidateInformation:
    """Each candidate's Fisher information as a low-rank factor, in scaled coordinates.

    Attributes
    ----------
    factors : ndarray, shape (n, k, p)
        ``L_i`` with ``L_i^T L_i`` the information of candidate ``i`` about the free
        parameters, each column divided by :attr:`scale`.
    scale : ndarray, shape (p,)
        Column scale (square root of the pool's mean information diagonal).
    names : tuple
        The free parameters' names (:class:`kinfw.model.ParameterName`).
    """

    factors: NDArray[np.float64]
    scale: NDArray[np.float64]
    names: tuple

    @property
    def information(self) -> NDArray[np.float64]:
        """Per candidate ``L_i^T L_i``, shape (n, p, p) (scaled)."""
        return np.einsum("nkp,nkq->npq", self.factors, self.factors)


def _per_sample_information(problem, noise: NoiseModel, n: int) -> NDArray[np.float64]:
    """Sum over each sample's observations of ``J^T J`` (whitened, free columns)."""
    free = problem.free
    p = int(free.sum())
    M = np.zeros((n, p, p))
    x0 = np.zeros(problem.n_parameters)
    for g, (_, J) in zip(problem.groups, problem.raw_residuals(x0), strict=True):
        Jw = J[:, :, free] / g.row_sigma(noise)[None, :, None]
        np.add.at(M, g.sample, np.einsum("mrp,mrq->mpq", Jw, Jw))
    return M


def candidate_information(
    robot: Robot, setup: Setup, qs: ArrayLike, joint_names, w_T_target
) -> CandidateInformation:
    """The Fisher information each configuration of ``qs`` brings to the calibration.

    The problem is the calibration's own (:func:`kinfw.identification.problem.build_problem`,
    ``setup.parameters`` and its gauge) on noise-free simulated observations of the
    nominal ``robot`` at ``qs`` (start = nominal, true target pose given), whitened by
    ``setup.noise()``; each sample's rows give its information ``J_i^T J_i``.

    Parameters
    ----------
    robot : Robot
        Nominal robot.
    setup : Setup
    qs : array_like, shape (n, J)
        Candidate configurations in ``joint_names`` order (rad, m).
    joint_names : sequence of str
    w_T_target : ndarray (4, 4)
        The target's pose (stage 2).

    Returns
    -------
    CandidateInformation
    """
    qs = np.atleast_2d(np.asarray(qs, dtype=float))
    data, targets = _simulate(robot, setup, qs, joint_names, w_T_target)
    problem = build_problem(robot, data, start=robot, targets=targets, parameters=setup.parameters)
    M = _per_sample_information(problem, setup.noise(), len(qs))
    scale = np.sqrt(np.clip(np.einsum("npp->p", M) / len(qs), 0.0, None))
    scale[scale == 0.0] = 1.0
    M = M / np.outer(scale, scale)
    w, V = np.linalg.eigh(M)  # ascending
    tol = 1e-12 * max(float(w.max(initial=0.0)), 1e-300)
    k = max(int((w > tol).sum(axis=1).max()), 1)
    w, V = np.clip(w[:, -k:], 0.0, None), V[:, :, -k:]
    factors = np.transpose(V * np.sqrt(w)[:, None, :], (0, 2, 1))  # (n, k, p)
    names = tuple(n for n, f in zip(problem.names, problem.free, strict=True) if f)
    return CandidateInformation(factors, scale, names)


@dataclass(frozen=True, eq=False)
class HeldOut:
    """The prediction error weights ``A`` at the test configurations (scaled chart), one
    per noise component of the observed quantities.

    ``trace(A C)`` of a component is the mean over test observations of the squared size
    of its error (SI: m^2 for a position, rad^2 for a rotation's small angle, ...) for a
    calibration with covariance ``C`` (scaled coordinates).

    Attributes
    ----------
    weights : tuple of (NoiseComponent, ndarray (p, p))
        In the order of the observed kinds' components; the first is the planner's
        objective (:attr:`objective`: a frame's position for every setup).
    """

    weights: tuple[tuple[NoiseComponent, NDArray[np.float64]], ...]

    @property
    def objective(self) -> tuple[NoiseComponent, NDArray[np.float64]]:
        """The component the planner minimises the error of, and its weights."""
        return self.weights[0]

    def of(self, name: str) -> NDArray[np.float64]:
        """The weights of the component ``name`` (KeyError if it is not observed)."""
        return next(A for c, A in self.weights if c.name == name)


def held_out(
    robot: Robot,
    setup: Setup,
    test_qs: ArrayLike,
    joint_names,
    w_T_target,
    info: CandidateInformation,
) -> HeldOut:
    """The held-out weights of :class:`HeldOut` at ``test_qs``.

    The observed quantities at the test configurations are the setup's own: ``w_T_frame``
    (or the frame's origin) for stage 1, ``camera_T_target`` (pose; also for a pixel
    setup) for stage 2; their Jacobian with respect to the parameters is the calibration
    problem's (unwhitened, SI), built on noise-free test observations and matched to the
    candidates' parameters by name.
    """
    test_qs = np.atleast_2d(np.asarray(test_qs, dtype=float))
    data, targets = _simulate(robot, setup, test_qs, joint_names, w_T_target, as_poses=True)
    problem = build_problem(robot, data, start=robot, targets=targets, parameters=setup.parameters)
    index = {n: k for k, n in enumerate(info.names)}
    p = len(info.names)
    A: dict[NoiseComponent, NDArray[np.float64]] = {}
    count = 0
    x0 = np.zeros(problem.n_parameters)
    for g, (_, J) in zip(problem.groups, problem.raw_residuals(x0), strict=True):
        cols = [(k, index[n]) for k, n in enumerate(problem.names) if n in index]
        G = np.zeros((*J.shape[:2], p))
        G[:, :, [c for _, c in cols]] = J[:, :, [k for k, _ in cols]]
        G /= info.scale
        row = 0
        for c in g.components:  # every component of the observed kinds
            Gc = G[:, row : row + c.rows]
            A[c] = A.get(c, np.zeros((p, p))) + np.einsum("mrp,mrq->pq", Gc, Gc)
            row += c.rows
        count += J.shape[0]
    return HeldOut(tuple((c, a / count) for c, a in A.items()))


def _inverse(M: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.linalg.inv(M)


def mean_square(
    info: CandidateInformation, A: NDArray[np.float64], chosen, *, ridge: float = 0.0
) -> float:
    """``trace(A M^-1)`` of the design ``chosen`` (indices, repeats allowed); inf when
    ``M`` is singular on a direction ``A`` weighs."""
    F = info.factors[np.asarray(chosen, dtype=np.int64)]
    M = np.einsum("nkp,nkq->pq", F, F) + ridge * np.eye(F.shape[-1])
    w, V = np.linalg.eigh(M)
    keep = w > 1e-10 * max(float(w.max(initial=0.0)), 1e-300)
    AV = V.T @ A @ V
    if np.any(np.abs(np.diag(AV))[~keep] > 1e-12 * max(np.trace(A), 1e-300)):
        return float("inf")
    return float(np.sum(np.diag(AV)[keep] / w[keep]))


def _gains(factors: NDArray, C: NDArray, A: NDArray) -> NDArray[np.float64]:
    """Decrease of ``trace(A C)`` when each candidate is added to a design with
    ``C = M^-1`` (Woodbury, vectorised over candidates):
    ``trace((I + L C L^T)^-1 L C A C L^T)``."""
    LC = factors @ C  # (n, k, p)
    k = factors.shape[1]
    S = np.eye(k) + LC @ np.transpose(factors, (0, 2, 1))
    K = LC @ A @ np.transpose(LC, (0, 2, 1))
    return np.einsum("nii->n", np.linalg.solve(S, K))


def _ridge_matrix(info: CandidateInformation) -> NDArray[np.float64]:
    return RIDGE * np.eye(info.factors.shape[-1])  # scaled: unit mean diagonal per candidate


def greedy(
    info: CandidateInformation,
    A: NDArray[np.float64],
    n: int,
    *,
    allowed: NDArray[np.bool_] | None = None,
    groups: NDArray[np.int64] | None = None,
    quota: int | None = None,
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Greedy forward selection of ``n`` distinct candidates minimising ``trace(A M^-1)``.

    Starts from the regularised information ``RIDGE I`` (so ``M`` is invertible from the
    first step: the first picks are those that determine the most weighted directions,
    a regularised D-/I-optimal seed), then adds at each step the candidate of largest
    decrease (:func:`_gains`, vectorised over candidates), updating ``M^-1`` by a
    ``p x p`` inverse.

    Parameters
    ----------
    info : CandidateInformation
    A : ndarray (p, p)
        Held-out weights (scaled chart).
    n : int
    allowed : ndarray of bool (n_candidates,), optional
    groups, quota : optional
        With both: at most ``quota`` picks per value of ``groups`` (the per-joint protocol).

    Returns
    -------
    chosen : ndarray of int64, shape (n,)
        In the order picked (each prefix is the greedy design of its size).
    objective : ndarray, shape (n,)
        ``trace(A M^-1)`` (regularised) after each pick.
    """
    N = info.factors.shape[0]
    available = np.ones(N, bool) if allowed is None else np.asarray(allowed, bool).copy()
    if n > available.sum():
        raise ValueError(f"n = {n}: only {int(available.sum())} candidates to choose from")
    M = _ridge_matrix(info)
    chosen, values = [], []
    with progress.task("plan: greedy selection", total=n, unit="picks") as bar:
        for _ in range(n):
            C = _inverse(M)
            gain = _gains(info.factors, C, A)
            gain[~available] = -np.inf
            i = int(np.argmax(gain))
            chosen.append(i)
            available[i] = False
            full = groups is not None and quota is not None
            if full and np.sum(groups[chosen] == groups[i]) >= quota:
                available[groups == groups[i]] = False
            M = M + info.factors[i].T @ info.factors[i]
            values.append(float(np.trace(A @ _inverse(M))))
            bar.advance(note=f"objective {values[-1]:.4g}")
    return np.array(chosen, np.int64), np.array(values)


def exchange(
    info: CandidateInformation,
    A: NDArray[np.float64],
    chosen: ArrayLike,
    *,
    allowed: NDArray[np.bool_] | None = None,
    groups: NDArray[np.int64] | None = None,
    max_passes: int = 20,
) -> tuple[NDArray[np.int64], float, int]:
    """Fedorov exchange: swap a chosen candidate for an unchosen one while that lowers
    ``trace(A M^-1)``; passes over the design until no swap improves.

    For each design point in turn, the design without it (``C = (M - F_s)^-1``) and the
    best candidate to add back (:func:`_gains`) are computed; the swap is made when it
    lowers the objective by more than a relative 1e-12. The objective never increases.
    With ``groups``, a point is only swapped within its group (per-joint quotas kept).

    Returns
    -------
    chosen : ndarray of int64
    objective : float
        Final ``trace(A M^-1)`` (regularised, as :func:`greedy`).
    swaps : int
    """
    chosen = np.array(chosen, np.int64)
    N = info.factors.shape[0]
    base = np.ones(N, bool) if allowed is None else np.asarray(allowed, bool)
    F = info.factors
    M = _ridge_matrix(info) + np.einsum("nkp,nkq->pq", F[chosen], F[chosen])
    current = float(np.trace(A @ _inverse(M)))
    swaps = 0
    with progress.task("plan: exchange", unit="pass") as bar:
        for _ in range(max_passes):
            improved = False
            for s in range(len(chosen)):
                i = chosen[s]
                Mm = M - F[i].T @ F[i]
                C = _inverse(Mm)
                free = base.copy()
                free[chosen] = False
                if groups is not None:
                    free &= groups == groups[i]
                if not free.any():
                    continue
                gain = _gains(F, C, A)
                gain[~free] = -np.inf
                j = int(np.argmax(gain))
                value = float(np.trace(A @ C)) - gain[j]
                if value < current * (1.0 - 1e-12):
                    chosen[s] = j
                    M = Mm + F[j].T @ F[j]
                    current = float(np.trace(A @ _inverse(M)))
                    swaps += 1
                    improved = True
            bar.advance(note=f"objective {current:.4g}, {swaps} swaps")
            if not improved:
                break
    return chosen, current, swaps
