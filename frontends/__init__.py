"""Visual frontends: a grey image in, the frame-to-frame similarity and its quality out.

A frontend knows nothing about robots, filters or metres. It is given images one at a time with their
timestamps and returns a :class:`FrameMotion` describing how the image content moved since the previous
frame, as a non-reflective similarity (rotation, translation, scale) in *rectified* pixel coordinates.
The optional :class:`PointMap` passed to a frontend maps raw (distorted) pixel positions to those
rectified coordinates, so lens distortion and camera tilt are handled on points, not on whole images.

Available frontends
-------------------
KltFrontend      pyramidal Lucas-Kanade tracking with track-and-replenish (``frontends.klt``)
FeatureFrontend  corners + descriptors + matching (``frontends.features``)
DirectFrontend   whole-image photometric alignment, coarse to fine (``frontends.direct``)
"""

from frontends.base import FrameMotion, IdentityMap, MotionStatus, PointMap

__all__ = ["FrameMotion", "IdentityMap", "MotionStatus", "PointMap", "make_frontend"]


def make_frontend(name: str, config: dict | None = None, point_map: PointMap | None = None):
    """Build a frontend by name (``"klt"``, ``"features"`` or ``"direct"``) from a plain config mapping."""
    if name == "klt":
        from frontends.klt import KltConfig, KltFrontend

        return KltFrontend(KltConfig.from_dict(config or {}), point_map=point_map)
    if name in ("features", "feature"):
        from frontends.features import FeatureConfig, FeatureFrontend

        return FeatureFrontend(FeatureConfig.from_dict(config or {}), point_map=point_map)
    if name == "direct":
        from frontends.direct import DirectConfig, DirectFrontend

        return DirectFrontend(DirectConfig.from_dict(config or {}), point_map=point_map)
    raise ValueError(f"unknown frontend {name!r} (choose 'klt', 'features' or 'direct')")
