"""The IMU mounting check in streaming use, on the samples seen so far.

:class:`~fusion_vo.backends.streaming.StreamingFusion` hands every sample to :class:`LiveMounting` as it
arrives. Once the IMU has been seen for ``MIN_SPAN`` seconds (and ``MIN_SAMPLES`` samples), the batch check
(:mod:`fusion_vo.consistency.mounting`) runs on the samples of the last ``SPAN`` seconds (the gyro against the
camera's increments, else the wheels' ticks, else the odometry twist), and again every ``RETRY`` seconds until
it decides: the stated mounting agrees (nothing changes), the data say what it is (the IMU's samples from then
on are read with the estimated ``T_BS``; so are those buffered and not yet fused), or they contradict it
without saying what is right (the IMU's later samples are left out). A quarter of a second is enough for
gravity, which decides alone while the drive has not yet turned: with an accelerometer that measures gravity,
a wrong mounting is corrected within the first third of a second (ten samples at 30 Hz), before the filter has
learned much from it. Such a decision is provisional: the check goes on (with the corrected mounting as the
stated one) until the gyro's axis has been seen, which confirms it or, disagreeing with gravity, leaves the
IMU out. Without gravity the check waits for the turns the gyro's axis needs, and the IMU is fused as stated
until then: the live heading monitor
(:mod:`fusion_vo.backends.live_monitor`) drops a gyro that contradicts the other heading sources meanwhile,
but what the backends learned from it stays. At a correction the EKF's gyro bias is therefore replaced by
the one the check's fit gives (``MountingEstimate.gyro_bias``), the AHRS heading aligned again as from its
first orientation, and the heading monitor restarted; iSAM2 keeps its bias. What this gives on
robot_localization's Husky log imported without its IMU transform, with and without the accelerometer, is
in docs/consistency.md (``python benchmarks/contradictions.py``, section 1); ``tests/consistency/test_live.py``
holds a generated drive with an AHRS and no gravity, corrected after 5 s, within five times the error of the
IMU stated right. The other checks need the whole drive (a ratio over straight stretches, signs
and frames against a reference) and are batch only; an odometry twist's delay is estimated causally by
:class:`~fusion_vo.sensors.sync.TwistDelay`.
"""

from __future__ import annotations

import logging
import math
from types import SimpleNamespace

import numpy as np

from fusion_vo.consistency import mounting
from fusion_vo.consistency.finding import CORRECTED, KEPT, REFUSED, UNDECIDED, Finding
from fusion_vo.consistency.signals import motion_reference
from fusion_vo.measurements import ImuData, TwistData, WheelData
from fusion_vo.sensors.imu import ahrs_heading

logger = logging.getLogger(__name__)

MIN_SPAN = 0.25  # [s]
RETRY = 5.0  # [s]
MIN_SAMPLES = 10  # IMU samples before the first check
SPAN = 120.0  # [s]


class LiveMounting:
    """Collects the IMU's and the reference's samples and decides once (module docstring).

    Parameters
    ----------
    T_BS : ndarray (4, 4)
        The stated mounting.
    config : FusionConfig
        ``consistency``, ``max_gap`` and ``max_odom_delay`` are used.
    wheel_config : WheelConfig or None
        The encoders' calibration, when the reference may be the wheels' ticks.
    """

    def __init__(self, T_BS: np.ndarray, config, wheel_config=None):
        self.T_BS = np.asarray(T_BS, dtype=np.float64)
        self.config = config
        self.wheel_config = wheel_config
        self.imu: list[tuple] = []
        self.camera: list = []
        self.wheel: list[tuple] = []
        self.odom: list[tuple] = []
        self.first_orientation: np.ndarray | None = None  # the IMU's first AHRS orientation (w, x, y, z)
        self.gyro_bias: tuple[float, float] | None = None  # the bias about the axis the last check found, σ
        self._start: float | None = None
        self._next: float | None = None
        self.finding: Finding | None = None

    def observe(self, sensor: str, t: float, payload) -> tuple[Finding, np.ndarray | None, bool] | None:
        """Record one sample (as :meth:`StreamingFusion.add` reads it); returns ``(finding, T_BS, final)`` when
        the check has just decided (``T_BS`` the mounting to use from now on, None to leave the IMU out when
        refused, the stated one when kept; ``final`` when the gyro's axis was part of the decision, after which
        nothing more is checked), else None."""
        try:
            t = float(t)
            if sensor == "imu":
                gyro, accel = (np.asarray(v, dtype=np.float64).reshape(3) for v in payload[:2])
                row = (t, *gyro, *accel)
                if np.all(np.isfinite(row)):
                    self.imu.append(row)
                if self.first_orientation is None and payload[2] is not None and np.all(np.isfinite(payload[2])):
                    self.first_orientation = np.asarray(payload[2], dtype=np.float64).copy()
            elif sensor == "camera":
                if payload.ok and np.all(np.isfinite(payload.delta)):
                    self.camera.append(payload)
            elif sensor == "wheel" and self.wheel_config is not None:
                self.wheel.append((t, int(payload[0]), int(payload[1])))
            elif sensor == "odom":
                row = (t, *(float(x) for x in payload))
                if np.all(np.isfinite(row)):
                    self.odom.append(row)
            else:
                return None
        except (TypeError, ValueError, IndexError, AttributeError):
            return None
        if not self.imu or not np.isfinite(t):  # (gravity needs no reference; the gyro's axis does)
            return None
        if self._start is None:
            self._start = t
            self._next = t + MIN_SPAN
        if t < self._next or len(self.imu) < MIN_SAMPLES:
            return None
        self._next = t + RETRY
        return self._check(t)

    def _check(self, now: float) -> tuple[Finding, np.ndarray | None] | None:
        # the window ends at the newest IMU sample: a sample of another sensor stamped far ahead (a clock an
        # hour off, which the stream rejects) empties no window
        lo = min(now, max(r[0] for r in self.imu)) - SPAN
        self.imu = [r for r in self.imu if r[0] >= lo]
        self.camera = [v for v in self.camera if v.t0 >= lo]
        self.wheel = [r for r in self.wheel if r[0] >= lo]
        self.odom = [r for r in self.odom if r[0] >= lo]
        if len(self.imu) < MIN_SAMPLES:
            return None
        imu = np.array(sorted(self.imu))
        data = ImuData(imu[:, 0], imu[:, 1:4], imu[:, 4:7], None, self.T_BS)
        streams = SimpleNamespace(visual=sorted(self.camera, key=lambda v: v.t1) or None, wheel=None, odom=None)
        if len(self.wheel) >= 3:
            w = np.array(sorted(self.wheel), dtype=np.float64)
            streams.wheel = WheelData(w[:, 0], w[:, 1].astype(np.int64), w[:, 2].astype(np.int64), self.wheel_config)
        if len(self.odom) >= 3:
            o = np.array(sorted(self.odom))
            streams.odom = TwistData(o[:, 0], o[:, 1], o[:, 2], o[:, 3])
        cfg = self.config
        try:
            est = mounting.estimate(data, motion_reference(streams, cfg.max_gap), cfg.consistency, cfg.max_gap,
                                    cfg.max_odom_delay)
            finding = mounting.decide(data, est, cfg.consistency)
        except (ValueError, ZeroDivisionError, IndexError, np.linalg.LinAlgError) as exc:
            logger.info("live IMU mounting check not made at t=%.2f: %s", now, exc)
            return None
        final = est.gyro_z is not None and est.gyro_fit >= cfg.consistency.mounting_min_fit
        if finding.decision == UNDECIDED or (finding.decision == KEPT and not final):
            return None  # (gravity alone agreeing: the gyro's axis is still to be seen)
        self.finding = finding
        finding.estimate["decided_at"] = round(now, 3)
        self.gyro_bias = (est.gyro_bias, est.gyro_bias_sigma) if est.gyro_bias is not None else None
        if finding.decision == CORRECTED:
            T = self.T_BS.copy()
            T[:3, :3] = est.R_BS
            self.T_BS = T  # checked from now on as the mounting stated
            return finding, T, final
        return finding, (None if finding.decision == REFUSED else self.T_BS), final or finding.decision == REFUSED

    def body_rates(self, T_BS: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Times and body yaw rates of the IMU samples still held, read with ``T_BS``."""
        imu = np.array(sorted(self.imu)).reshape(-1, 7)
        return imu[:, 0], imu[:, 1:4] @ np.asarray(T_BS, dtype=np.float64)[2, :3]


def aligned_offset(T_BS: np.ndarray, orientation, heading: float) -> float | None:
    """The AHRS heading offset that makes the AHRS orientation ``orientation`` (``w, x, y, z`` of the IMU),
    read through the mounting ``T_BS``, give the body heading ``heading`` [rad]; None for an unusable one."""
    q = np.asarray(orientation, dtype=np.float64).reshape(1, 4)
    found = ahrs_heading(ImuData(np.zeros(1), np.zeros((1, 3)), np.zeros((1, 3)), q, np.asarray(T_BS)))
    if found is None or not found.valid[0]:
        return None
    return float(math.remainder(float(found.yaw[0]) - float(heading), 2.0 * math.pi))
