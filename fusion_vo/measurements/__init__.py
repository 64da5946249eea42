"""Time-ordered measurements: the data that flows from the recording and the ground geometry into the backends.

:mod:`~fusion_vo.measurements.samples`  the measurements themselves (per sample and per stream);
:mod:`~fusion_vo.measurements.limits`   the physical range of each kind of number (beyond it: an input error);
:mod:`~fusion_vo.measurements.counts`   what happened to each sensor's measurements (:class:`SensorCount`);
:mod:`~fusion_vo.measurements.grid`     putting streams of different rates in time order and onto node times.
"""

from fusion_vo.measurements.counts import SensorCount
from fusion_vo.measurements.limits import (MAX_ACCELERATION, MAX_ANGULAR_RATE, MAX_CAMERA_HEIGHT_M, MAX_POSITION_M,
                                          MAX_RANGE_M, MAX_SPEED)
from fusion_vo.measurements.samples import (
    VisualIncrement,
    WheelTicks,
    TwistSample,
    ImuSample,
    RangeSample,
    GpsFix,
    WheelConfig,
    WheelData,
    ImuData,
    TwistData,
    RangeData,
    PoseData,
    GpsData,
)

__all__ = ["MAX_ACCELERATION", "MAX_ANGULAR_RATE", "MAX_CAMERA_HEIGHT_M", "MAX_POSITION_M", "MAX_RANGE_M", "MAX_SPEED",
           "SensorCount", "VisualIncrement", "WheelTicks", "TwistSample", "ImuSample", "RangeSample", "GpsFix", "WheelConfig", "WheelData", "ImuData", "TwistData", "RangeData", "PoseData", "GpsData"]
