"""What happened to one sensor's measurements on their way into an estimate."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class SensorCount:
    """What happened to one sensor's measurements.

    Attributes
    ----------
    used : int
        Measurements (or node intervals) that entered the estimate.
    gated : int
        Rejected: non-finite, physically impossible (spikes, tick jumps) or outside the Mahalanobis gate.
    late : int
        Arrived after the reorder window had passed their time (streaming) and could not be applied.
    reordered : int
        Arrived out of order but within the window, and were applied in time order.
    missing : int
        Node intervals the sensor did not cover (stream stopped, gaps, failed frames).
    """

    used: int = 0
    gated: int = 0
    late: int = 0
    reordered: int = 0
    missing: int = 0

    def as_dict(self) -> dict:
        return dict(self.__dict__)
