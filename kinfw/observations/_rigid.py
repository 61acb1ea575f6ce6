"""Observation kinds whose measurement is a rigid transform (``pose``, ``target``).

They share the numeric side: the measured value is one 4x4 transform per observation in
the group's single row field, the prediction is :meth:`RigidTransformKind.predicted_transforms`
(the numpy twin of the kind's CasADi residual), and the simulated noise is the paper's
(Shih et al. 1992, Fig. 10): N(0, σ_p) per position axis and a rotation by an N(0, σ_r)
angle about a uniformly random axis.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from kinfw.observations._base import ObservationKind, pose_rows
from kinfw.observations._numeric import (
    NumericContext,
    perturb_transforms,
    transforms_from_pose_rows,
)


class RigidTransformKind(ObservationKind):
    """Base of kinds that measure a transform held in their one row field (``row_fields[0]``,
    shape (m, 4, 4)); subclasses give :meth:`predicted_transforms`."""

    bulk_keys = ("xyz", "quat_xyzw")

    def parse_many(self, reader, observations):
        """The rows ``[x, y, z (m), qx, qy, qz, qw]`` of many observations at once."""
        from kinfw.observations._pose import read_quaternions

        xyz = reader.numbers_many([o.get("xyz") for o in observations], 3)
        if xyz is None:
            return None
        quats = read_quaternions(reader, [o.get("quat_xyzw") for o in observations])
        if quats is None:
            return None
        return np.concatenate([xyz / 1000.0 if reader.length_unit == "mm" else xyz, quats], axis=1)

    def predicted_transforms(self, group, model: NumericContext) -> NDArray:
        """Predicted measured transforms (m, 4, 4), as the kind's residual forms them."""
        raise NotImplementedError

    def predict(self, group, model: NumericContext):
        return pose_rows(self.predicted_transforms(group, model))

    def with_data(self, group, rows):
        return replace(group, **{self.row_fields[0]: transforms_from_pose_rows(rows)})

    def simulate(self, group, model: NumericContext, rng, sigmas):
        """Position noise N(0, sigmas["position"]) per axis in the measured transform's
        frame, a rotation by N(0, sigmas["rotation"]) about a uniformly random axis."""
        noisy = perturb_transforms(
            self.predicted_transforms(group, model),
            rng,
            float(sigmas["position"]),
            float(sigmas["rotation"]),
        )
        return replace(group, **{self.row_fields[0]: noisy})
