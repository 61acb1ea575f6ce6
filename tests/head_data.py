"""Simulated plate poses of the IIS head (shared by the cross-validation and rejection
tests)."""

import numpy as np

from kinfw.simulation import random_configurations, simulate_at

PLATES = ("left_plate", "right_plate")


def plate_data(truth, n, seed, noise_m=0.5e-3, noise_rad=0.005):
    """Both plates' poses at ``n`` random configurations of ``truth``, with noise."""
    rng = np.random.default_rng(seed)
    names = truth.topology(PLATES).joint_names
    qs = random_configurations(*truth.joint_limits(names), n, rng, fraction=0.8)
    return simulate_at(
        truth, qs, names, frames=PLATES, rng=rng, noise_m=noise_m, noise_rad=noise_rad
    )
