"""A compass defined outside the library: everything a new sensor needs, in this file alone.

``COMPASS_SENSOR`` is an absolute heading; ``NORTH_COMPASS_SENSOR`` one whose north is not the start frame's,
turned so that its first readings give the initial heading (an offset it finds once and carries, as the IMU's AHRS
does); ``OFFSET_COMPASS_SENSOR`` a heading with an unknown constant
offset (a magnetometer's declination or mounting error), which it adds to both backends as a state
variable (``compass_offset``), reads from a recording's ``compass0/data.csv`` (``#timestamp [ns],yaw [rad]``)
and takes live through ``StreamingFusion.add("compass", CompassSample(t, yaw))``.

Nothing here registers on import (the tests register inside ``registry.registered``); ``register_offset_compass``
is what the ``fusion_vo.sensors`` entry point of a package would name.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from pydantic import Field

from fusion_vo.backends.result import SensorCount
from fusion_vo.config.base import Section, Sigma
from fusion_vo.geometry import se2
from fusion_vo.sensors import registry
from fusion_vo.sensors.model import MeasurementModel
from fusion_vo.sensors.readings import Readings
from fusion_vo.sensors.registry import Carry, Live, Sensor, State, Step


@dataclass
class CompassData:
    """Headings [rad] at times ``t`` [s]."""

    t: np.ndarray
    yaw: np.ndarray

    def __len__(self) -> int:
        return len(self.t)


@dataclass
class CompassSample:
    """One live heading."""

    t: float
    yaw: float


class CompassNoise(Section):
    """Compass noise (its configuration section, ``fusion: {compass: {sigma: ...}}``)."""

    sigma: Sigma = Field(0.02, description="Standard deviation of one heading [rad].")


@dataclass(frozen=True)
class CompassModel(MeasurementModel):
    """``h = ψ``: the pose's heading."""

    name: str = "compass"
    args: tuple = ("heading",)
    dim: int = 1
    angle_rows: tuple = (0,)

    def evaluate(self, heading):
        h = np.asarray(heading, dtype=np.float64)
        return h, {"heading": np.ones(h.shape + (1,))}


@dataclass(frozen=True)
class OffsetCompassModel(MeasurementModel):
    """``h = ψ + o``: the heading plus the compass's own offset, a state it adds (``compass_offset``)."""

    name: str = "compass"
    args: tuple = ("heading", "compass_offset")
    dim: int = 1
    angle_rows: tuple = (0,)

    def evaluate(self, heading, compass_offset):
        h = np.asarray(heading, dtype=np.float64) + np.asarray(compass_offset, dtype=np.float64)
        one = np.ones(h.shape + (1,))
        return h, {"heading": one, "compass_offset": one.copy()}


COMPASS = CompassModel()
OFFSET_COMPASS = OffsetCompassModel()


# --------------------------------------------------------------------------- hooks
def compass_intervals(iv, streams, config, counts):
    """Headings at the nodes within ``max_gap`` of a reading (``iv.extra["compass"]``)."""
    data = streams["compass"]
    T = iv.t
    j = np.clip(np.searchsorted(data.t, T), 1, len(data.t) - 1)
    near = np.minimum(np.abs(data.t[j] - T), np.abs(data.t[j - 1] - T)) <= config.max_gap
    iv.extra["compass"] = (near, se2.wrap_angle(np.interp(T, data.t, np.unwrap(data.yaw))))
    counts.setdefault("compass", SensorCount()).used += int(near.sum())


def compass_readings(model):
    """The headings at the nodes as readings of ``model`` (``σ²`` of ``fusion: {compass: {sigma}}``)."""
    def readings(iv, config):
        if "compass" not in iv.extra:
            return []
        ok, yaw = iv.extra["compass"]
        n = np.flatnonzero(ok)
        return [Readings("compass", model, n, n, yaw[n], config.section("compass").sigma ** 2)]
    return readings


def read_compass(recording) -> CompassData:
    """``compass0/data.csv`` of a recording: ``timestamp [ns], yaw [rad]`` per row, with the checks every stream's
    rows get (:meth:`fusion_vo.recording.Recording.table`)."""
    tab, _ = recording.table("compass0", 1, "compass", "heading [rad]")
    return CompassData(tab.t, tab.values[:, 0])


COMPASS_SENSOR = Sensor(name="compass", where="compass0/", config=("compass", CompassNoise),
                        intervals=Step(100, compass_intervals), readings=compass_readings(COMPASS))


# --------------------------------------------------------------------------- its heading, for the monitor
def compass_change(iv, config):
    """The heading change over each node interval with a heading at both ends, and its variance (none of its own
    per interval: its two ends' noise is the window's)."""
    if "compass" not in iv.extra:
        return None
    near, yaw = iv.extra["compass"]
    return near[:-1] & near[1:], se2.wrap_angle(np.diff(yaw)), np.zeros(len(iv.dt))


def compass_drop(iv, bad, agrees) -> None:
    """The headings at the ends of the intervals the monitor dropped are not used."""
    near, yaw = iv.extra["compass"]
    drop = np.zeros(len(iv.t), bool)
    drop[1:] |= bad
    iv.extra["compass"] = (near & ~drop, yaw)


def compass_clear(iv) -> None:
    if "compass" in iv.extra:
        iv.extra["compass"] = (np.zeros(len(iv.t), bool), iv.extra["compass"][1])


#: the compass as an absolute heading the monitor judges against the gyro, the wheels and the camera
COMPASS_HEADING = registry.HeadingSource(
    "compass", "compass heading", rank=35, change=compass_change, drop=compass_drop, absolute=True,
    window=lambda iv, config: lambda span, theta: 2.0 * config.section("compass").sigma ** 2,
    heading=lambda iv: iv.extra["compass"], kept=lambda iv: iv.extra["compass"][0][1:], clear=compass_clear)

#: the compass's live intake: ``StreamingFusion.add("compass", CompassSample(t, yaw))``
COMPASS_LIVE = Live(sample=lambda m: (m.t, float(m.yaw)),
                    data=lambda t, rows, fusion: CompassData(t, np.array(rows, dtype=np.float64)),
                    samples=lambda data: ((t, CompassSample(t, y)) for t, y in zip(data.t, data.yaw)))

#: the compass with its heading checked by the monitor, in a batch run and live
CHECKED_COMPASS_SENSOR = dataclasses.replace(COMPASS_SENSOR, heading=(COMPASS_HEADING,), live=COMPASS_LIVE)

#: the compass with an unknown constant offset, estimated by both backends (prior 0 ± 0.5 rad)
OFFSET_COMPASS_SENSOR = dataclasses.replace(
    COMPASS_SENSOR, folder="compass0", read=read_compass,
    states=(State("compass_offset", initial=0.0, sigma=0.5),),
    readings=compass_readings(OFFSET_COMPASS), live=COMPASS_LIVE,
)


# --------------------------------------------------------------------------- a value it finds once
#: the span [s] of the first readings whose mean heading is the initial one (:func:`north_compass_intervals`)
NORTH_WINDOW = 0.5


def north_compass_intervals(iv, streams, config, counts):
    """Headings at the nodes turned so that the first ones are the initial heading: the offset between the compass's
    north and the start frame, the circular mean of its readings over :data:`NORTH_WINDOW` from the first node it
    covers minus the initial heading, is found once and carried (``iv.carry["compass"]``)."""
    compass_intervals(iv, streams, config, counts)
    near, yaw = iv.extra["compass"]
    offset = iv.carry.get("compass")
    if offset is None and near.any():
        data = streams["compass"]
        t0 = iv.t[np.argmax(near)]
        first = (data.t >= t0 - 1e-9) & (data.t <= t0 + NORTH_WINDOW)
        if first.any():
            mean = float(np.angle(np.mean(np.exp(1j * data.yaw[first]))))
            offset = iv.carry["compass"] = mean - float(config.initial_pose[2])
    if offset is None:  # (no reading to align it by: none used)
        iv.extra["compass"] = (np.zeros_like(near), yaw)
    else:
        iv.extra["compass"] = (near, se2.wrap_angle(yaw - offset))


def turn_north_compass(iv, yaw: float) -> None:
    """Its headings once the world frame is turned by ``yaw``."""
    near, heading = iv.extra["compass"]
    iv.extra["compass"] = (near, se2.wrap_angle(heading + yaw))


#: the north compass: an absolute heading whose offset to the start frame it finds from its first readings
NORTH_COMPASS_SENSOR = dataclasses.replace(
    COMPASS_SENSOR, intervals=Step(100, north_compass_intervals), live=COMPASS_LIVE, turn=turn_north_compass,
    carry=Carry(turn=lambda offset, yaw: offset - yaw, ahead=lambda rows: NORTH_WINDOW if rows else 0.0),
)


def register_offset_compass() -> None:
    """What a package's ``fusion_vo.sensors`` entry point names: registers the offset compass."""
    registry.register(OFFSET_COMPASS_SENSOR)
