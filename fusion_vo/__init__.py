"""fusion-vo: a downward-looking ground camera as an odometer, fused with wheel encoders and an IMU.

Data flows one way::

    recording -> frontend -> ground geometry -> time-ordered measurements -> backend
              -> trajectories -> evaluation and plots

Subpackages
-----------
recording   reading (and writing) the sequence folder layout
geometry    SE(2) algebra, camera model, ground geometry (pixel similarity -> body motion)
sensors     wheel-encoder and IMU models
backends    EKF (filterpy) and factor graph (GTSAM)
evaluation  trajectory metrics (evo), plots, reports
simulation  generated recordings over photographed floor textures
calibration camera intrinsics, camera pose over the floor, lever arm, wheels
cli         the ``fusion-vo`` command
"""

__version__ = "0.1.0"
