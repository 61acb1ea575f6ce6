"""Hand-eye regimes of issue 13: an independent generator, the nine solvers, the tables.

Used by ``bench_handeye.py`` (sections 1, 2 and the final summary); nothing here imports
kinfw's simulation or transform helpers, so a bug there cannot hide a bug in a solver.
The solvers are called through their public API only.

Generator (metres, radians inside; one ``numpy.random.Generator`` per trial and regime,
seeded ``[seed, regime index, trial]``):

* true ``hand_T_camera`` (X): a uniformly random rotation (normalised Gaussian
  quaternion; near the half turn: a uniformly random axis and an angle
  ``180 deg - U(0, 0.3 deg)``) and a translation N(0, 5 cm) per axis;
* a reference hand pose ``base_T_hand0`` (random rotation, position (0.5, 0, 0.4) m +
  N(0, 5 cm)) whose camera sees the target origin 0.6 m ahead along its optical axis
  (random target orientation); ``base_T_target`` (Y) follows from it;
* robot poses ``base_T_hand[i]``: the reference turned by an angle U(0, m/2) about a
  uniformly random axis (in the hand frame), so every relative motion between two poses
  turns by at most m (small motions: m = 15 or 30 deg; well spread: U(0, 180 deg), any
  orientation), and shifted by U(-0.2, 0.2) m per axis; exact (the robot is the
  reference);
* camera poses ``camera_T_target[i] = inv(X) inv(base_T_hand[i]) Y``, then noisy:
  rotation ``R dR`` with ``dR`` a turn by N(0, 1 deg) about a uniformly random axis,
  translation + N(0, 2 mm) per axis;
* outlier regime: one view (random index) has its camera rotation turned by a further
  20 deg about a uniformly random axis (its translation untouched).

Errors are those of ``hand_T_camera`` for every solver (A = X B Y solvers return
``camera_T_hand``, which is inverted): rotation angle of ``R_est^T R_true`` in deg and
translation distance in mm. A solver that raises (or returns non-finite numbers) in a
trial is counted in ``raises`` and left out of that column's median and p90.
"""

from __future__ import annotations

import contextlib
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

HAND_CAMERA_SIGMA_M = 0.05
HAND_POSITION_M = np.array([0.5, 0.0, 0.4])
TARGET_DISTANCE_M = 0.6
HALF_SHIFT_M = 0.2
NOISE_ROT_DEG = 1.0
NOISE_MM = 2.0
OUTLIER_DEG = 20.0
HALF_TURN_BAND_DEG = 0.3
TIMING_VIEWS = (3, 10, 30, 100)
IDENTITY_ATOL = 1e-12


@dataclass(frozen=True, slots=True)
class Regime:
    """One row of issue 13's table: views, motion bound, outlier, half-turn X."""

    label: str
    n_views: int
    motion_deg: float  # poses turned U(0, this / 2) from one reference: relative turns <= this
    outlier: bool = False
    half_turn: bool = False
    noisy: bool = True


SPREAD = 360.0  # well spread: every pose turned U(0, 180 deg) from the reference

REGIMES = (
    Regime("well spread, 10 views", 10, SPREAD),
    Regime("small motions <= 15 deg, 10 views", 10, 15.0),
    Regime("small motions <= 30 deg, 10 views", 10, 30.0),
    Regime("small motions <= 15 deg, 30 views", 30, 15.0),
    Regime("1 of 10 poses off by 20 deg", 10, SPREAD, outlier=True),
    Regime("X within 0.3 deg of 180 deg, noisy", 10, SPREAD, half_turn=True),
    Regime("exactness: no noise, 3 views", 3, SPREAD, noisy=False),
)


# -- generator ---------------------------------------------------------------------------


def rotation_from_vector(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rodrigues: rotation matrices (n, 3, 3) from rotation vectors (n, 3), radians."""
    theta = np.linalg.norm(v, axis=1)
    k = v / np.where(theta > 0, theta, 1.0)[:, None]
    K = np.zeros((len(v), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = k[:, 2], -k[:, 1], k[:, 0]
    s, c = np.sin(theta)[:, None, None], np.cos(theta)[:, None, None]
    return np.eye(3) + s * K + (1.0 - c) * K @ K


def random_axes(rng: np.random.Generator, n: int) -> NDArray[np.float64]:
    a = rng.normal(size=(n, 3))
    return a / np.linalg.norm(a, axis=1, keepdims=True)


def random_rotations(rng: np.random.Generator, n: int) -> NDArray[np.float64]:
    """Uniformly distributed rotations (n, 3, 3) from normalised Gaussian quaternions."""
    q = rng.normal(size=(n, 4))
    w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=1,
    )


def pose(R: NDArray[np.float64], t: NDArray[np.float64]) -> NDArray[np.float64]:
    """4x4 transforms from rotations (..., 3, 3) and translations (..., 3)."""
    T = np.zeros((*R.shape[:-2], 4, 4))
    T[..., :3, :3], T[..., :3, 3], T[..., 3, 3] = R, t, 1.0
    return T


def inv(T: NDArray[np.float64]) -> NDArray[np.float64]:
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    return pose(Rt, -(Rt @ T[..., :3, 3:])[..., 0])


def angle_deg(R: NDArray[np.float64]) -> float:
    """Rotation angle of one 3x3 rotation, deg (atan2 of the skew part and the trace:
    accurate near 0 and 180 deg, unlike the arccos of the trace alone)."""
    skew = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return float(np.degrees(np.arctan2(np.linalg.norm(skew) / 2.0, (np.trace(R) - 1.0) / 2.0)))


@dataclass(frozen=True, slots=True)
class Trial:
    """One trial's data (metres): the truth and what every solver sees."""

    hand_T_camera: NDArray[np.float64]  # (4, 4) truth of X
    base_T_target: NDArray[np.float64]  # (4, 4) truth of Y
    base_T_hand: NDArray[np.float64]  # (n, 4, 4) exact robot poses
    camera_T_target: NDArray[np.float64]  # (n, 4, 4) noisy camera poses
    outlier: int = -1  # index of the outlier view, -1 if none


def make_trial(rng: np.random.Generator, regime: Regime, n_views: int | None = None) -> Trial:
    """A random setup of ``regime`` (see the module docstring); ``n_views`` overrides."""
    n = regime.n_views if n_views is None else n_views
    R = random_rotations(rng, 3)
    if regime.half_turn:
        turn = np.pi - np.radians(rng.uniform(0.0, HALF_TURN_BAND_DEG))
        R[0] = rotation_from_vector(random_axes(rng, 1) * turn)[0]
    hand_T_camera = pose(R[0], rng.normal(0.0, HAND_CAMERA_SIGMA_M, 3))
    base_T_hand0 = pose(R[1], HAND_POSITION_M + rng.normal(0.0, 0.05, 3))
    camera0_T_target = pose(R[2], np.array([0.0, 0.0, TARGET_DISTANCE_M]))
    base_T_target = base_T_hand0 @ hand_T_camera @ camera0_T_target
    angles = np.radians(rng.uniform(0.0, regime.motion_deg / 2.0, n))
    hand0_R_hand = rotation_from_vector(random_axes(rng, n) * angles[:, None])
    base_T_hand = pose(
        R[1] @ hand0_R_hand, base_T_hand0[:3, 3] + rng.uniform(-HALF_SHIFT_M, HALF_SHIFT_M, (n, 3))
    )
    camera_T_target = inv(hand_T_camera) @ inv(base_T_hand) @ base_T_target
    if regime.noisy:
        turns = np.radians(rng.normal(0.0, NOISE_ROT_DEG, n))
        dR = rotation_from_vector(random_axes(rng, n) * turns[:, None])
        camera_T_target = pose(
            camera_T_target[:, :3, :3] @ dR,
            camera_T_target[:, :3, 3] + rng.normal(0.0, 1e-3 * NOISE_MM, (n, 3)),
        )
    outlier = -1
    if regime.outlier:
        outlier = int(rng.integers(n))
        dR = rotation_from_vector(random_axes(rng, 1) * np.radians(OUTLIER_DEG))[0]
        camera_T_target[outlier, :3, :3] = camera_T_target[outlier, :3, :3] @ dR
    return Trial(hand_T_camera, base_T_target, base_T_hand, camera_T_target, outlier)


# -- solvers -----------------------------------------------------------------------------

# prepare(trial data in the chosen length unit) -> call; call() returns hand_T_camera
Solve = Callable[[NDArray[np.float64], NDArray[np.float64]], Callable[[], NDArray[np.float64]]]


@dataclass(frozen=True, slots=True)
class Solver:
    name: str  # short name used in the tables
    ours: bool
    prepare: Solve  # (base_T_hand, camera_T_target) -> call returning hand_T_camera


def _kinfw_axxb(base_T_hand, camera_T_target):
    from kinfw.identification.handeye import solve_axxb

    return lambda: (
        solve_axxb(base_T_hands=base_T_hand, camera_T_targets=camera_T_target).hand_T_camera
    )


def _kinfw_axyb(base_T_hand, camera_T_target):
    from kinfw.identification.handeye import solve_axyb

    hand_T_base = inv(base_T_hand)
    return lambda: inv(
        solve_axyb(camera_T_targets=camera_T_target, hand_T_bases=hand_T_base).camera_T_hand
    )


def _rt(T):
    return np.ascontiguousarray(T[:, :3, :3]), np.ascontiguousarray(T[:, :3, 3:])


def _cv_axxb(method_name: str) -> Solve:
    def prepare(base_T_hand, camera_T_target):
        import cv2

        method = getattr(cv2, f"CALIB_HAND_EYE_{method_name}")
        R_g2b, t_g2b = _rt(base_T_hand)
        R_t2c, t_t2c = _rt(camera_T_target)

        def call():
            R, t = cv2.calibrateHandEye(
                R_gripper2base=R_g2b,
                t_gripper2base=t_g2b,
                R_target2cam=R_t2c,
                t_target2cam=t_t2c,
                method=method,
            )
            return pose(R, np.ravel(t))  # cam2gripper = hand_T_camera

        return call

    return prepare


def _cv_rwhe(method_name: str) -> Solve:
    def prepare(base_T_hand, camera_T_target):
        import cv2

        method = getattr(cv2, f"CALIB_ROBOT_WORLD_HAND_EYE_{method_name}")
        R_w2c, t_w2c = _rt(camera_T_target)
        R_b2g, t_b2g = _rt(inv(base_T_hand))

        def call():
            _, _, R, t = cv2.calibrateRobotWorldHandEye(
                R_world2cam=R_w2c,
                t_world2cam=t_w2c,
                R_base2gripper=R_b2g,
                t_base2gripper=t_b2g,
                method=method,
            )
            return inv(pose(R, np.ravel(t)))  # gripper2cam = camera_T_hand

        return call

    return prepare


SOLVERS = (
    Solver("kinfw solve_axxb", True, _kinfw_axxb),
    Solver("kinfw solve_axyb", True, _kinfw_axyb),
    *(Solver(m, False, _cv_axxb(m)) for m in ("TSAI", "PARK", "HORAUD", "ANDREFF", "DANIILIDIS")),
    *(Solver(m, False, _cv_rwhe(m)) for m in ("SHAH", "LI")),
)


def kinfw_errors() -> tuple[type[BaseException], ...]:
    """The solvers' documented refusals (counted as raises, like any other exception)."""
    from kinfw.identification.handeye import AXYBError, HandEyeError

    return HandEyeError, AXYBError


# -- running -----------------------------------------------------------------------------


@dataclass(slots=True)
class Column:
    """One solver over the trials of one regime: errors (trials, 2) deg/mm, NaN where it
    raised; seconds per solve; raises and identity answers, messages by kind."""

    errors: NDArray[np.float64]
    seconds: NDArray[np.float64]
    raises: int = 0
    identity: int = 0
    messages: dict[str, list] = field(default_factory=dict)

    def stats(self) -> NDArray[np.float64]:
        """Median and p90 of the rotation (deg) and translation (mm) errors, (4,)."""
        ok = ~np.isnan(self.errors[:, 0])
        if not ok.any():
            return np.full(4, np.nan)
        e = self.errors[ok]
        return np.array(
            [
                np.median(e[:, 0]),
                np.percentile(e[:, 0], 90),
                np.median(e[:, 1]),
                np.percentile(e[:, 1], 90),
            ]
        )


def errors_deg_mm(est: NDArray[np.float64], true: NDArray[np.float64], mm_per_unit: float):
    return (
        angle_deg(est[:3, :3].T @ true[:3, :3]),
        mm_per_unit * float(np.linalg.norm(est[:3, 3] - true[:3, 3])),
    )


def in_unit(T: NDArray[np.float64], metres_per_unit: float) -> NDArray[np.float64]:
    out = T.copy()
    out[..., :3, 3] /= metres_per_unit
    return out


def run_regime(
    regime: Regime,
    trials: Sequence[Trial],
    solvers: Sequence[Solver] = SOLVERS,
    metres_per_unit: float = 1.0,
) -> list[Column]:
    """Every solver on every trial, round robin within a trial, one timed call each."""
    cols = [
        Column(np.full((len(trials), 2), np.nan), np.full(len(trials), np.nan)) for _ in solvers
    ]
    mm_per_unit = 1e3 * metres_per_unit
    for t, trial in enumerate(trials):
        A = in_unit(trial.base_T_hand, metres_per_unit)
        B = in_unit(trial.camera_T_target, metres_per_unit)
        truth = in_unit(trial.hand_T_camera, metres_per_unit)
        for s, col in zip(solvers, cols, strict=True):
            call = s.prepare(A, B)
            start = time.perf_counter()
            try:
                X = call()
            except Exception as exc:  # a refusal is a result: counted
                col.seconds[t] = time.perf_counter() - start
                _count(col, f"{type(exc).__name__}: {str(exc).strip().splitlines()[0]}")
                continue
            col.seconds[t] = time.perf_counter() - start
            if not np.isfinite(X).all():
                _count(col, "non-finite result")
                continue
            col.identity += int(np.abs(X - np.eye(4)).max() < IDENTITY_ATOL)
            col.errors[t] = errors_deg_mm(X, truth, mm_per_unit)
    return cols


def _count(col: Column, msg: str) -> None:
    col.raises += 1
    col.messages.setdefault(re.sub(r"\d[\d.e+-]*", "#", msg), [0, msg])[0] += 1


def time_solvers(
    trials: Sequence[Trial],
    solvers: Sequence[Solver] = SOLVERS,
    calls: int = 3,
    metres_per_unit: float = 1.0,
) -> NDArray[np.float64]:
    """Seconds per solve (len(solvers),): median over trials of each trial's median of
    ``calls`` round-robin calls, after one warm-up round; gc off; raises timed too."""
    import gc

    prepared = [
        [
            s.prepare(
                in_unit(tr.base_T_hand, metres_per_unit),
                in_unit(tr.camera_T_target, metres_per_unit),
            )
            for s in solvers
        ]
        for tr in trials
    ]
    for call in prepared[0]:
        _try(call)
    out = np.empty((len(trials), len(solvers)))
    enabled = gc.isenabled()
    gc.disable()
    try:
        for t, row in enumerate(prepared):
            secs = np.empty((calls, len(solvers)))
            for r in range(calls):
                for j, call in enumerate(row):
                    start = time.perf_counter()
                    _try(call)
                    secs[r, j] = time.perf_counter() - start
            out[t] = np.median(secs, axis=0)
    finally:
        if enabled:
            gc.enable()
    return np.median(out, axis=0)


def _try(call: Callable[[], object]) -> None:
    """Call, ignoring a raise: timing only (raises are counted in the regimes)."""
    with contextlib.suppress(Exception):
        call()


# -- tables ------------------------------------------------------------------------------

STAT_NAMES = ("rot med", "rot p90", "mm med", "mm p90")
EXACT = (1e-9, 1e-9, 1e-6, 1e-6)  # below these (deg, deg, mm, mm) an error is rounding


def ratio(x: float, best: float, k: int) -> str:
    """kinfw / best CV for statistic ``k`` as text; '~0' when both are rounding-level."""
    if not np.isfinite(x):
        return "-"
    if x < EXACT[k] and best < EXACT[k]:
        return "~0"
    return fmt(x / best) if best > 0 else "-"


def fmt(x: float) -> str:
    return "-" if not np.isfinite(x) else f"{x:.3g}"


def best_cv(solvers: Sequence[Solver], cols: Sequence[Column]) -> list[tuple[float, str]]:
    """Per statistic (rot med, rot p90, mm med, mm p90): the best OpenCV value and name."""
    out = []
    stats = {s.name: c.stats() for s, c in zip(solvers, cols, strict=True) if not s.ours}
    for k in range(4):
        name = min(stats, key=lambda m: np.inf if np.isnan(stats[m][k]) else stats[m][k])
        out.append((float(stats[name][k]), name))
    return out


def regime_rows(
    solvers: Sequence[Solver], cols: Sequence[Column], n_trials: int
) -> list[list[str]]:
    """The rows of one regime's table: every solver, best CV, kinfw / best CV ratios."""
    rows = []
    for s, c in zip(solvers, cols, strict=True):
        st = c.stats()
        rows.append(
            [
                s.name,
                *(fmt(x) for x in st),
                f"{c.raises}/{n_trials}",
                f"{c.identity}",
                f"{1e3 * np.nanmedian(c.seconds):.2f}",
            ]
        )
    best = best_cv(solvers, cols)
    rows.append(["best CV", *(f"{fmt(v)} {n[:5]}" for v, n in best), "", "", ""])
    for s, c in zip(solvers, cols, strict=True):
        if s.ours:
            st = c.stats()
            rows.append(
                [
                    f"{s.name.split()[-1]}/best",
                    *(ratio(x, b, k) for k, (x, (b, _)) in enumerate(zip(st, best, strict=True))),
                    "",
                    "",
                    "",
                ]
            )
    return rows


REGIME_HEADERS = ["solver", *STAT_NAMES, "raises", "ident", "ms med"]


def summary_cell(c: Column, n_trials: int) -> str:
    st = c.stats()
    if not np.isfinite(st[0]):
        return f"raises {c.raises}/{n_trials}"
    cell = f"{fmt(st[0])} (p90 {fmt(st[1])}) / {fmt(st[2])} mm (p90 {fmt(st[3])})"
    return cell + (f", raises {c.raises}/{n_trials}" if c.raises else "")


def summary_best_cell(solvers: Sequence[Solver], cols: Sequence[Column]) -> str:
    b = best_cv(solvers, cols)
    return (
        f"{fmt(b[0][0])} ({b[0][1]}, p90 {fmt(b[1][0])} {b[1][1]}) / "
        f"{fmt(b[2][0])} mm ({b[2][1]}, p90 {fmt(b[3][0])} {b[3][1]})"
    )
