"""Fusion backends: an EKF (filterpy) and a factor graph (GTSAM) over the same measurements.

Entry points
------------
:func:`run_backends`    a recording plus visual odometry -> :class:`FusionResult` (what ``fusion-vo run`` calls)
:func:`fuse`            the same from :class:`SensorStreams` in memory
:class:`StreamingFusion` add measurements as they arrive, read the current estimate
:class:`FusionConfig`   every option, with documented defaults (``FusionConfig.from_dict``)

Modules
-------
timeline   streams of different rates -> one grid of node times and per-interval measurements
pauses     a pause in every stream: the estimate split there, its pieces fused on their own and chained
monitor    heading sources checked against each other; a component that contradicts the others is dropped
ekf        planar EKF with gating and a Rauch–Tung–Striebel smoother
graph      GTSAM factor graph: batch Levenberg–Marquardt, iSAM2, fixed-lag smoother
streaming  the incremental interface with a reorder buffer for late measurements
"""

from fusion_vo.backends.batch import (
    BACKENDS, backend_names, fuse, run_backends, streams_from_recording, wheel_dead_reckoning,
)
from fusion_vo.backends.config import EkfConfig, FusionConfig, GraphConfig
from fusion_vo.backends.result import FusionResult, SensorCount
from fusion_vo.backends.streaming import Estimate, StreamingFusion
from fusion_vo.backends.timeline import SENSORS, Intervals, SensorStreams, build_intervals

__all__ = [
    "BACKENDS", "SENSORS", "EkfConfig", "Estimate", "FusionConfig", "FusionResult", "GraphConfig", "Intervals",
    "SensorCount", "SensorStreams", "StreamingFusion", "backend_names", "build_intervals", "fuse", "run_backends",
    "streams_from_recording",
    "wheel_dead_reckoning",
]
