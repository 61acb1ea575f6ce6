"""The experiments of Hirsh, DeSouza & Kak (2001), section 5, in simulation: Figs. 3 and 4.

The paper's test program, with kinfw's solver of ``A[i] = X @ B[i] @ Y``
(:func:`kinfw.identification.handeye.solve_axyb`, ``refine=False``: the paper's iteration alone):

1. an arbitrary true pair: the hand-eye ``X = c_T_e`` and the base-world ``Y = b_T_w``,
   each a uniformly random rotation (Haar) with a translation uniform in a cube
   (+-0.1 m for ``X``, +-1 m for ``Y``);
2. ``n`` hand poses ``b_T_e[i]``: a rotation about a uniformly random axis by an angle
   uniform in ``[0, hand_rotation_deg]`` and a position uniform in a cube of half-width
   ``hand_translation_m``; the robot gives ``B[i] = e_i_T_b`` (their inverses);
3. the theoretical camera calibrations ``A[i] = c_i_T_w = X B[i] Y`` (the paper's eqs. 4-6)
   and, for Fig. 4, noise as the paper: "rotating each c_iH_w by one degree about random
   axes", i.e. each ``A[i]`` turned by exactly ``noise_deg`` about its own uniformly random
   axis (:func:`kinfw.verification.papers.rotations_about_random_axes`; in the frame
   ``w``, so the translation is unchanged);
4. the iteration from the paper's initial guess, the identity for ``Y`` (section 3), and
   per iteration the error of the estimate of ``Y`` (and of ``X``) against the truth.

Error measure. The paper converts the estimate of ``b_H_w`` and the truth to quaternions
and reads the error from their dot product (section 5). We report the rotation angle
between them, ``2 acos(|<q_est, q_true>|)`` in degrees
(:func:`kinfw.verification.papers.quaternion_angle`), which is the angle of
``R_true^T R_est``; the 4-D angle between the two vectors is half of it.
It is evaluated as ``4 atan2(|q_est - q_true|, |q_est + q_true|)`` (signs aligned), equal
to the ``acos`` form but accurate below 1e-8 rad (``acos`` of a dot product stalls at
~1e-6 deg), so that Fig. 3 shows the error falling to where the solver stops: steps below
its tolerance of 1e-12 rad, i.e. errors of ~1e-11 deg. The history of a run that stops
before the last recorded iteration is padded with its last value.

What sets the speed. The solver's docstring shows that the paper's alternation is the
power iteration for the top singular pair of a 4x4 matrix ``N`` built from the data: the
error shrinks by ``(sigma_2 / sigma_1)^2`` per iteration. For noise-free data that factor
depends only on the spread of the hand rotations: with few views or small rotations it
is close to 1 and the iteration is slow (:meth:`HirshResult.convergence_factors` records
it per trial). The paper does not say how its hand poses were chosen.

Defaults. Hand rotations up to 180 degrees (the paper's test program has no camera that
must see a target, so any hand orientation is fair) and 100 recorded iterations: with 3
random views the median shrink factor is ~0.8 per iteration, so 30 iterations stop the
3-view curves half-way (noise-free median ~0.2 deg; with noise still above the 1-degree
line), while 100 show every number of views at its fixed point. Rotations up to 90
degrees (``hand_rotation_deg=90``) make the iteration slower still (3 views: ~0.95).

Random numbers. Every trial has its own ``numpy.random.Generator`` seeded with
``(seed, noise in micro-degrees, views, trial)``: a trial's result does not depend on
which other views or trials are run. It draws the truth, the hand poses, the noise and
the solver's random restarts, in that order.

Statistics over trials are the median and the interquartile range (the paper shows one
curve per number of views, without saying over how many trials).

Steps 1-3 and the error measure are in :mod:`kinfw.verification.papers`; the table,
the figure and the command line in :mod:`kinfw.verification.papers`.

References
----------
R. L. Hirsh, G. N. DeSouza, A. C. Kak, "An iterative approach to the hand-eye and
base-world calibration problem", ICRA 2001, sections 3-5, Figs. 3 and 4.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from kinfw.identification.handeye import AXYBError, convergence_factor, solve_axyb
from kinfw.verification.evaluation import check_count, run_trials
from kinfw.verification.papers._hirsh_problem import (
    draw_problem,
    quaternion_angle,
    rotate_about_random_axes,
)
from kinfw.verification.studies import arrays_from, freeze, json_list, json_lists, readonly

log = logging.getLogger(__name__)


#: Numbers of views (camera calibrations) of the paper's Figs. 3 and 4.
PAPER_VIEWS = (3, 5, 10)


#: Rotation noise of Fig. 4: each ``A[i]`` turned by one degree about a random axis.
PAPER_NOISE_DEG = 1.0


#: Error (deg) at which a noise-free run counts as converged in the tables.
CONVERGED_DEG = 1e-6


#: The solver's own iteration cap (its default) when ``iterations`` is smaller: a
#: slow trial still ends at the iteration's fixed point, and the recorded history is cut
#: at ``iterations``.
SOLVER_MAX_ITERATIONS = 1000


# -- the study --------------------------------------------------------------------------


def _trial_rng(seed: int, noise_deg: float, views: int, trial: int) -> np.random.Generator:
    """The generator of one trial (module docstring: random numbers)."""
    return np.random.default_rng([seed, round(noise_deg * 1e6), views, trial])


def _nan_quantiles(values: NDArray[np.float64], q: Sequence[float]) -> NDArray[np.float64]:
    """Quantiles over trials (axis 1) ignoring failed trials (NaN); NaN if all failed."""
    out = np.full((len(q), values.shape[0], *values.shape[2:]), np.nan)
    for v in range(values.shape[0]):
        if np.isfinite(values[v]).any():
            out[:, v] = np.nanquantile(values[v], q, axis=0)
    return out


#: The per-trial arrays of :class:`HirshResult`, in the order its JSON lists them, and
#: their dtypes.
_TRIAL_ARRAYS = {
    "initial_y_error_deg": float,
    "y_error_deg": float,
    "x_error_deg": float,
    "solved_y_error_deg": float,
    "solved_x_error_deg": float,
    "solved_y_translation_error_m": float,
    "solver_iterations": np.int64,
    "converged": bool,
    "restarts": np.int64,
    "convergence_factors": float,
    "failed": bool,
}


@dataclass(frozen=True, slots=True)
class HirshResult:
    """Error of the paper's iteration versus iteration (Hirsh et al. Fig. 3 or Fig. 4).

    Attributes
    ----------
    views : ndarray of int64, shape (V,)
        Numbers of views (camera calibrations).
    noise_deg : float
        Rotation noise on each ``A[i]``, degrees (exactly this angle, random axis).
    seed : int
        Base seed (module docstring).
    hand_rotation_deg : float
        Largest rotation angle of the random hand poses, degrees.
    hand_translation_m : float
        Half-width of the cube of hand positions, metres.
    initial_y_error_deg : ndarray, shape (V, T)
        Error of the initial guess (identity) for ``Y``, degrees: iteration 0.
    y_error_deg : ndarray, shape (V, T, K)
        Per views, trial and iteration 1..K: rotation error of the estimate of ``Y =
        b_T_w`` against the truth, the paper's measure (:func:`quaternion_angle`),
        degrees. Runs that stop early repeat their last value; NaN for a failed trial.
    x_error_deg : ndarray, shape (V, T, K)
        The same for ``X = c_T_e``.
    solved_y_error_deg, solved_x_error_deg : ndarray, shape (V, T)
        Rotation errors of the solver's answer (the iteration run to its tolerance or
        ``SOLVER_MAX_ITERATIONS``), degrees.
    solved_y_translation_error_m : ndarray, shape (V, T)
        Distance between the solver's and the true translation of ``Y``, metres.
    solver_iterations : ndarray of int64, shape (V, T)
        The solver's iteration count (rotation plus translation alternation; -1 failed).
    converged, restarts : ndarray, shape (V, T)
        The solver's convergence flag and its random restarts (the paper's 180-degree
        stall).
    convergence_factors : ndarray, shape (V, T)
        ``(sigma_2 / sigma_1)^2`` of the data's iteration matrix: the error's shrink
        factor per iteration (module docstring).
    failed : ndarray of bool, shape (V, T)
        The solver raised :class:`kinfw.identification.handeye.AXYBError` (errors are NaN).
    """

    views: NDArray[np.int64]
    noise_deg: float
    seed: int
    hand_rotation_deg: float
    hand_translation_m: float
    initial_y_error_deg: NDArray[np.float64]
    y_error_deg: NDArray[np.float64]
    x_error_deg: NDArray[np.float64]
    solved_y_error_deg: NDArray[np.float64]
    solved_x_error_deg: NDArray[np.float64]
    solved_y_translation_error_m: NDArray[np.float64]
    solver_iterations: NDArray[np.int64]
    converged: NDArray[np.bool_]
    restarts: NDArray[np.int64]
    convergence_factors: NDArray[np.float64]
    failed: NDArray[np.bool_]

    @property
    def trials(self) -> int:
        return int(self.y_error_deg.shape[1])

    @property
    def iterations(self) -> int:
        return int(self.y_error_deg.shape[2])

    @property
    def y_curve_deg(self) -> NDArray[np.float64]:
        """Error of ``Y`` at iterations 0..K (0 = initial guess), shape (V, T, K + 1)."""
        return np.concatenate([self.initial_y_error_deg[..., None], self.y_error_deg], axis=2)

    @property
    def y_median_deg(self) -> NDArray[np.float64]:
        """Median over trials of :attr:`y_curve_deg`, shape (V, K + 1)."""
        return _nan_quantiles(self.y_curve_deg, [0.5])[0]

    @property
    def y_quartiles_deg(self) -> NDArray[np.float64]:
        """First and third quartiles over trials of :attr:`y_curve_deg`, (2, V, K + 1)."""
        return _nan_quantiles(self.y_curve_deg, [0.25, 0.75])

    @property
    def x_median_deg(self) -> NDArray[np.float64]:
        """Median over trials of :attr:`x_error_deg` (iterations 1..K), shape (V, K)."""
        return _nan_quantiles(self.x_error_deg, [0.5])[0]

    def iterations_to_reach(self, threshold_deg: float = CONVERGED_DEG) -> NDArray[np.float64]:
        """Per views and trial, the first iteration whose ``Y`` error is at most
        ``threshold_deg`` (0 = the initial guess); ``inf`` if none of the K does, NaN for a
        failed trial. Shape (V, T)."""
        curve = self.y_curve_deg
        below = curve <= threshold_deg
        out = np.where(below.any(axis=2), np.argmax(below, axis=2), np.inf)
        return np.where(self.failed, np.nan, out)

    def median_iterations_to_reach(
        self, threshold_deg: float = CONVERGED_DEG
    ) -> NDArray[np.float64]:
        """Median over trials of :meth:`iterations_to_reach`, shape (V,) (``inf``: more
        than half the trials did not get there within K iterations)."""
        its = self.iterations_to_reach(threshold_deg)
        return np.array(
            [np.median(row[~np.isnan(row)]) if (~np.isnan(row)).any() else np.nan for row in its]
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: set-up, raw per-trial errors (degrees, metres) and the summary."""
        return {
            "study": (
                "Hirsh, DeSouza & Kak 2001, Fig. 3"
                if self.noise_deg == 0.0
                else "Hirsh, DeSouza & Kak 2001, Fig. 4"
            )
            + " (simulation)",
            "views": self.views.tolist(),
            "noise_deg": self.noise_deg,
            "seed": self.seed,
            "hand_rotation_deg": self.hand_rotation_deg,
            "hand_translation_m": self.hand_translation_m,
            "trials": self.trials,
            "iterations": self.iterations,
            **json_lists(self, _TRIAL_ARRAYS, strict=True),
            "summary": {
                **json_lists(
                    self, ("y_median_deg", "y_quartiles_deg", "x_median_deg"), strict=True
                ),
                # null: not reached within the recorded iterations
                "median_iterations_to_1e-6_deg": json_list(
                    self.median_iterations_to_reach(CONVERGED_DEG)
                ),
            },
        }

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> HirshResult:
        """The result written by :meth:`to_dict` (the summary is recomputed)."""
        return cls(
            views=readonly(doc["views"], np.int64),
            noise_deg=float(doc["noise_deg"]),
            seed=int(doc["seed"]),
            hand_rotation_deg=float(doc["hand_rotation_deg"]),
            hand_translation_m=float(doc["hand_translation_m"]),
            **arrays_from(doc, _TRIAL_ARRAYS, writeable=False),
        )


def _padded(values: NDArray[np.float64], k: int) -> NDArray[np.float64]:
    """The first ``k`` values, the last one repeated when there are fewer."""
    values = values[:k]
    return np.concatenate([values, np.full(k - len(values), values[-1])])


def _hirsh_trial(
    seed: int,
    noise_deg: float,
    n: int,
    t: int,
    k: int,
    hand_rotation_deg: float,
    hand_translation_m: float,
) -> tuple:
    """Trial ``t`` with ``n`` views of :func:`hirsh_study` (a task: module level,
    picklable arguments): the convergence factor, the initial Y error and, unless the
    solver failed (None), the recorded errors and the solver's outcome."""
    rng = _trial_rng(seed, noise_deg, n, t)
    p = draw_problem(
        rng, n, hand_rotation_deg=hand_rotation_deg, hand_translation_m=hand_translation_m
    )
    c_T_ws = p.c_T_ws
    if noise_deg > 0.0:
        c_T_ws = rotate_about_random_axes(c_T_ws, rng, np.radians(noise_deg))
    factor = convergence_factor(camera_T_targets=c_T_ws, hand_T_bases=p.e_T_bs)
    initial = np.degrees(quaternion_angle(np.eye(3), p.b_T_w[:3, :3]))
    try:
        res = solve_axyb(
            camera_T_targets=c_T_ws,
            hand_T_bases=p.e_T_bs,
            base_T_target_guess=np.eye(4),
            refine=False,
            record_history=True,
            rng=rng,
            max_iterations=max(k, SOLVER_MAX_ITERATIONS),
        )
    except AXYBError as err:
        log.warning("hirsh: %d views, trial %d: the solver failed: %s", n, t, err)
        return factor, initial, None
    return (
        factor,
        initial,
        (
            _padded(
                np.degrees(quaternion_angle(res.base_T_target_history[:, :3, :3], p.b_T_w[:3, :3])),
                k,
            ),
            _padded(
                np.degrees(quaternion_angle(res.camera_T_hand_history[:, :3, :3], p.c_T_e[:3, :3])),
                k,
            ),
            np.degrees(quaternion_angle(res.base_T_target[:3, :3], p.b_T_w[:3, :3])),
            np.degrees(quaternion_angle(res.camera_T_hand[:3, :3], p.c_T_e[:3, :3])),
            np.linalg.norm(res.base_T_target[:3, 3] - p.b_T_w[:3, 3]),
            res.iterations,
            res.restarts,
            res.converged,
        ),
    )


def _trial_arrays(
    cells: Sequence[tuple[int, int]], results: Iterable[tuple], shape: tuple[int, int], k: int
) -> dict[str, NDArray]:
    """The per-trial arrays of :class:`HirshResult` (keyed as ``_TRIAL_ARRAYS``), shape
    ``(V, T)`` or ``(V, T, k)``, filled from the outcomes of :func:`_hirsh_trial` at
    ``cells`` (views index, trial); a failed trial keeps NaN errors and -1 iterations."""
    a: dict[str, NDArray] = {
        "initial_y_error_deg": np.full(shape, np.nan),
        "y_error_deg": np.full((*shape, k), np.nan),
        "x_error_deg": np.full((*shape, k), np.nan),
        "solved_y_error_deg": np.full(shape, np.nan),
        "solved_x_error_deg": np.full(shape, np.nan),
        "solved_y_translation_error_m": np.full(shape, np.nan),
        "solver_iterations": np.full(shape, -1, dtype=np.int64),
        "converged": np.zeros(shape, dtype=bool),
        "restarts": np.zeros(shape, dtype=np.int64),
        "convergence_factors": np.full(shape, np.nan),
        "failed": np.zeros(shape, dtype=bool),
    }
    solved_names = (
        "y_error_deg",
        "x_error_deg",
        "solved_y_error_deg",
        "solved_x_error_deg",
        "solved_y_translation_error_m",
        "solver_iterations",
        "restarts",
        "converged",
    )
    for (v, t), (factor, init, solved) in zip(cells, results, strict=True):
        a["convergence_factors"][v, t], a["initial_y_error_deg"][v, t] = factor, init
        if solved is None:
            a["failed"][v, t] = True
            continue
        for name, value in zip(solved_names, solved, strict=True):
            a[name][v, t] = value
    return a


def hirsh_study(
    *,
    views: Iterable[int] = PAPER_VIEWS,
    noise_deg: float = 0.0,
    trials: int = 50,
    iterations: int = 100,
    seed: int = 0,
    hand_rotation_deg: float = 180.0,
    hand_translation_m: float = 0.5,
    executor: Executor | None = None,
) -> HirshResult:
    """Hirsh et al. (2001) Fig. 3 (``noise_deg = 0``) or Fig. 4 (``noise_deg = 1``).

    For each number of views, ``trials`` random problems (module docstring, steps 1-3);
    each is solved by the paper's iteration from the identity for ``Y``
    (``solve_axyb(camera_T_targets=A, hand_T_bases=B, base_T_target_guess=I,
    refine=False, record_history=True)``) and the error of each iterate is recorded
    against the truth.

    Parameters
    ----------
    views : iterable of int, optional
        Numbers of views (each >= 3, the paper's minimum).
    noise_deg : float, optional
        Rotation noise: each ``A[i]`` is turned by exactly this angle (degrees) about its
        own random axis. The paper's Fig. 4: 1.
    trials : int, optional
        Random problems per number of views.
    iterations : int, optional
        Iterations recorded (the solver itself runs on to its tolerance, up to
        ``SOLVER_MAX_ITERATIONS``, for :attr:`HirshResult.solved_y_error_deg`).
    seed : int, optional
        Base seed (module docstring).
    hand_rotation_deg : float, optional
        Largest rotation angle of a hand pose (angles uniform up to it), degrees. The
        spread of the hand rotations sets the speed of the iteration (module docstring).
    hand_translation_m : float, optional
        Half-width of the cube of hand positions, metres.
    executor : concurrent.futures.Executor, optional
        Run the trials as its tasks (:func:`kinfw.verification.studies._common.run_trials`); default
        serially here. The numbers do not depend on it (each trial seeds its own).

    Returns
    -------
    HirshResult
    """
    vs = np.array([check_count(v, "views", 3) for v in views], dtype=np.int64)
    if not vs.size:
        raise ValueError("views: expected at least one number of views")
    noise_deg = float(noise_deg)
    if not (np.isfinite(noise_deg) and 0.0 <= noise_deg <= 180.0):
        raise ValueError(f"noise_deg: expected an angle in [0, 180] degrees, got {noise_deg}")
    trials = check_count(trials, "trials", 1)
    k = check_count(iterations, "iterations", 1)
    cells = [(v, t) for v in range(len(vs)) for t in range(trials)]
    results = run_trials(
        _hirsh_trial,
        [
            (seed, noise_deg, int(vs[v]), t, k, hand_rotation_deg, hand_translation_m)
            for v, t in cells
        ],
        executor=executor,
    )
    arrays = _trial_arrays(cells, results, (len(vs), trials), k)
    for v, n in enumerate(vs):
        log.info(
            "hirsh: noise %g deg, %d views: median Y error after %d iterations %.3g deg",
            noise_deg,
            n,
            k,
            np.nanmedian(arrays["y_error_deg"][v, :, -1]),
        )
    freeze(vs, *arrays.values())
    return HirshResult(
        views=vs,
        noise_deg=noise_deg,
        seed=int(seed),
        hand_rotation_deg=float(hand_rotation_deg),
        hand_translation_m=float(hand_translation_m),
        **arrays,
    )
