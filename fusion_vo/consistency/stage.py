"""The consistency checks in order, on the streams a run will fuse.

1. the IMU's mounting (:mod:`~fusion_vo.consistency.mounting`), against the camera's turn, else the wheels'
   or the odometry's: every later check reads the gyro through it;
2. the wheels (:mod:`~fusion_vo.consistency.wheels`): the encoders' signs and an odometry twist's ``wz``
   sign against the gyro's turn (else the camera's), the twist's velocity frame;
3. the clocks (:mod:`~fusion_vo.consistency.clocks`), with the signs and the mounting right;
4. the camera's and the wheels' scales (:mod:`~fusion_vo.consistency.scale`), on streams on one clock.

Each check returns a :class:`~fusion_vo.consistency.finding.Finding` and the streams (and, for the scale, the
configuration) to fuse. A check that fails on data it cannot handle (a singular fit) is reported as
undecided and changes nothing: the checks never make a run fail.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass, field

import numpy as np

from fusion_vo.consistency import mounting
from fusion_vo.consistency.clocks import check_clocks
from fusion_vo.consistency.finding import CORRECTED, KEPT, REFUSED, UNDECIDED, Finding
from fusion_vo.consistency.scale import check_scale
from fusion_vo.consistency.signals import body_turn, camera_steps, motion_reference
from fusion_vo.consistency.wheels import check_encoder_signs, check_twist_frame, check_twist_sign

logger = logging.getLogger(__name__)


@dataclass
class Checked:
    """The streams and configuration to fuse after the checks, and what each check found."""

    streams: object
    config: object
    findings: list[Finding] = field(default_factory=list)

    @property
    def notes(self) -> list[str]:
        """The sentences of the checks that did not simply agree, for the run's notes."""
        return [f.sentence for f in self.findings if f.decision != KEPT and f.sentence]

    def as_dicts(self) -> list[dict]:
        return [f.as_dict() for f in self.findings]


def check_streams(streams, config) -> Checked:
    """Run the checks (module docstring) on ``streams`` (:class:`~fusion_vo.sensors.streams.SensorStreams`)
    with ``config`` (:class:`~fusion_vo.backends.config.FusionConfig`; ``config.consistency.check`` false
    skips them)."""
    if not config.consistency.check:
        return Checked(streams, config)
    out = Checked(streams, config)
    for step in (_mounting, _wheels, _clocks, _scale):
        try:
            step(out)
        except (ValueError, ZeroDivisionError, IndexError, np.linalg.LinAlgError) as exc:
            name = step.__name__.strip("_")
            logger.warning("consistency check of the %s could not be made: %s", name, exc)
            out.findings.append(Finding(name, "", UNDECIDED, f"the {name} check could not be made ({exc}); the "
                                        "streams are used as stated"))
    for f in out.findings:
        f.log()
    return out


def _mounting(out: Checked) -> None:
    streams, config = out.streams, out.config
    if streams.imu is None or len(streams.imu) < 3:
        return
    ref = motion_reference(streams, config.max_gap)
    est = mounting.estimate(streams.imu, ref, config.consistency, config.max_gap, config.max_odom_delay)
    finding = mounting.decide(streams.imu, est, config.consistency)
    out.findings.append(finding)
    if finding.decision == CORRECTED:
        T = np.array(streams.imu.T_BS, dtype=np.float64)
        T[:3, :3] = est.R_BS
        out.streams = streams.replace(imu=dataclasses.replace(streams.imu, T_BS=T))
    elif finding.decision == REFUSED:
        out.streams = streams.replace(imu=None)


def _wheels(out: Checked) -> None:
    streams, config = out.streams, out.config
    if streams.imu is not None and len(streams.imu) >= 3:
        reference, name = body_turn(streams.imu), "gyro"
    else:
        reference, name = camera_steps(streams.visual), "camera"
    if streams.wheel is not None and len(streams.wheel) >= 3 and reference is not None:
        finding, wheel = check_encoder_signs(streams.wheel, reference, name, config.consistency, config.max_gap)
        out.findings.append(finding)
        streams = streams.replace(wheel=wheel)
    if streams.odom is not None and len(streams.odom) >= 3:
        if reference is not None:
            finding, odom = check_twist_sign(streams.odom, reference, name, config.consistency, config.max_gap)
            out.findings.append(finding)
            streams = streams.replace(odom=odom)
        finding, odom = check_twist_frame(streams.odom, camera_steps(streams.visual), config.max_gap)
        out.findings.append(finding)
        streams = streams.replace(odom=odom)
    out.streams = streams


def _clocks(out: Checked) -> None:
    findings, out.streams = check_clocks(out.streams, out.config.max_odom_delay)
    out.findings += findings


def _scale(out: Checked) -> None:
    finding, out.streams, out.config = check_scale(out.streams, out.config, out.config.max_gap)
    if finding is not None:
        out.findings.append(finding)
