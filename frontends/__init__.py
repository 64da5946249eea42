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

Each frontend's settings are one pydantic model (``KltConfig``, ``FeatureConfig``, ``DirectConfig``; see
:mod:`frontends.config`): every option with its default, range, unit and description. The package
imports nothing of ``fusion_vo``.
"""

from frontends.base import FrameMotion, IdentityMap, MotionStatus, PointMap
from frontends.direct import DirectConfig, DirectFrontend
from frontends.features import FeatureConfig, FeatureFrontend
from frontends.klt import KltConfig, KltFrontend

__all__ = ["FRONTENDS", "FrameMotion", "IdentityMap", "MotionStatus", "PointMap", "make_frontend"]

#: the frontends by name: their settings model and class
FRONTENDS = {"klt": (KltConfig, KltFrontend), "features": (FeatureConfig, FeatureFrontend),
             "direct": (DirectConfig, DirectFrontend)}


def make_frontend(name: str, config: dict | None = None, point_map: PointMap | None = None):
    """Build a frontend by name (``"klt"``, ``"features"`` or ``"direct"``) from a plain config mapping.

    Raises
    ------
    ValueError
        For an unknown name, or (:class:`frontends.config.ConfigError`) a setting that cannot work.
    """
    if name == "feature":
        name = "features"
    if name not in FRONTENDS:
        raise ValueError(f"unknown frontend {name!r} (choose 'klt', 'features' or 'direct')")
    settings, frontend = FRONTENDS[name]
    return frontend(settings.from_dict(config or {}), point_map=point_map)
