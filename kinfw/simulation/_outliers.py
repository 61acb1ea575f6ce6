"""Gross errors planted in measurements: a random fraction of the pose and target
observations moved by a fixed distance and turned by a fixed angle
(:func:`plant_outliers`), for the robustness study (:mod:`kinfw.verification.studies`) and the
tests of robust losses, rejection and noise estimation.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from kinfw.geometry import matrix_from_rotation_vector
from kinfw.measurements import Measurements


def _unit_vectors(rng: np.random.Generator, n: int) -> NDArray[np.float64]:
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def plant_outliers(
    data: Measurements,
    rng: np.random.Generator,
    *,
    fraction: float,
    distance_m: float,
    angle_rad: float,
) -> tuple[Measurements, frozenset[tuple[str, str, int]]]:
    """Corrupt a random ``fraction`` of the pose and target observations.

    Each chosen observation (one sample of one pose or target group) has its position
    moved by ``distance_m`` in a uniformly random direction (in the measurement frame)
    and its orientation turned by ``angle_rad`` about a uniformly random axis (on the
    measured frame's side).

    Returns
    -------
    corrupted : Measurements
    planted : frozenset of (kind, frame, sample)
        The corrupted observations, keyed as ``refine``'s ``downweighted``.
    """
    if not 0.0 <= fraction <= 1.0:
        raise ValueError(f"fraction: expected 0 <= fraction <= 1, got {fraction}")
    groups = [("pose", g.frame, g.sample, g.meas_T_frame) for g in data.poses] + [
        ("target", g.camera, g.sample, g.camera_T_target) for g in data.targets
    ]
    index = [(k, r) for k, (_, _, sample, _) in enumerate(groups) for r in range(len(sample))]
    n = round(fraction * len(index)) if fraction > 0.0 else 0
    n = max(n, 1) if fraction > 0.0 else 0
    chosen = rng.choice(len(index), size=n, replace=False)
    arrays = [T.copy() for _, _, _, T in groups]
    dps = distance_m * _unit_vectors(rng, n)
    dRs = matrix_from_rotation_vector(angle_rad * _unit_vectors(rng, n))
    planted = set()
    for c, dp, dR in zip(chosen, dps, dRs, strict=True):
        k, r = index[c]
        arrays[k][r, :3, 3] += dp
        arrays[k][r, :3, :3] = arrays[k][r, :3, :3] @ dR
        kind, frame, sample, _ = groups[k]
        planted.add((kind, frame, int(sample[r])))
    n_poses = len(data.poses)
    poses = tuple(replace(g, meas_T_frame=arrays[k]) for k, g in enumerate(data.poses))
    targets = tuple(
        replace(g, camera_T_target=arrays[n_poses + k]) for k, g in enumerate(data.targets)
    )
    corrupted = replace(
        data, poses=poses, targets=targets, source=f"{data.source} + {n} planted outliers"
    )
    return corrupted, frozenset(planted)
