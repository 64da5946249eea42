"""Visual increment as a measurement of the body motion, up to the visual scale.

A frontend's similarity between two frames, projected to the ground (:mod:`fusion_vo.geometry.ground`),
is the body motion between the frames with its translation in units of the configured camera height::

    z = h(δ, k_v) + n,     h = (k_v d_x, k_v d_y, d_ψ),     n ~ N(0, Σ_vis)

with ``k_v = h_configured / h_true`` (the visual scale) and ``Σ_vis`` the frontend's covariance.
Jacobians: ``∂h/∂δ = diag(k_v, k_v, 1)``, ``∂h/∂k_v = (d_x, d_y, 0)ᵀ``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusion_vo.sensors.model import MeasurementModel, scaled_motion


@dataclass(frozen=True)
class VisualModel(MeasurementModel):
    """The visual increment (module docstring); arguments ``motion``, ``visual_scale``."""

    name: str = "camera"
    args: tuple = ("motion", "visual_scale")
    dim: int = 3
    turn_rows: tuple = (2,)

    def evaluate(self, motion, visual_scale):
        one = 1.0 if np.ndim(motion) == 1 else np.ones_like(np.asarray(visual_scale, dtype=np.float64))
        h, j_d, j_k, _ = scaled_motion(motion, visual_scale, one)
        return h, {"motion": j_d, "visual_scale": j_k}


VISUAL = VisualModel()
