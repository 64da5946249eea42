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

import lazy_loader

# the submodules load on first use: a camera-only run that only writes results (``result``) does not
# pay for filterpy, scipy.stats or GTSAM (``graph``, ``online_graph``: what the modules of this package reach
# GTSAM through)
__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "batch": ["BACKENDS", "backend_names", "fuse", "run_backends", "streams_from_recording", "dead_reckoning",
              "wheel_dead_reckoning"],
    "config": ["EkfConfig", "FusionConfig", "GraphConfig"],
    "graph": ["run_graph"],
    "online_graph": ["OnlineGraph"],
    "result": ["FusionResult", "SensorCount"],
    "streaming": ["Estimate", "StreamingFusion"],
    "timeline": ["SENSORS", "Intervals", "SensorStreams", "build_intervals"],
})
