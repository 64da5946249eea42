"""Calibration of the sensors of a recording, writing the ``sensor.yaml`` files of its layout.

=========================  =================================================================================
:mod:`.intrinsics`         focal length, principal point and lens distortion from chessboard views
:mod:`.floor`              the camera's height, tilt and lever arm from one chessboard lying on the floor
:mod:`.lens_from_motion`   the lens distortion of an uncalibrated camera from the frames themselves
:mod:`.height`             the camera height from a straight drive of known length
:mod:`.lever_arm`          the camera's offset from the rotation centre from a turn in place
:mod:`.wheels`             wheel radii and base from ground truth or Borenstein's UMBmark squares
=========================  =================================================================================
"""
