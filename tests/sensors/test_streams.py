"""SensorStreams holds every sensor's data by its name: the built-in sensors and one registered by a user alike."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from fusion_vo.backends.streaming import message_sensor, time_ordered_messages
from fusion_vo.measurements import RangeData, TwistData, VisualIncrement
from fusion_vo.sensors.registry import Live, Sensor, registered
from fusion_vo.sensors.streams import SensorStreams


@dataclass
class _Beeps:
    t: np.ndarray

    def __len__(self) -> int:
        return len(self.t)


def _beeper() -> Sensor:
    return Sensor(name="beeper", live=Live(sample=lambda m: (m, None), samples=lambda d: [(t, float(t)) for t in d.t]))


def _twist(t0: float = 0.0) -> TwistData:
    t = t0 + np.arange(5) * 0.1
    return TwistData(t, np.full(5, 0.5), np.zeros(5), np.zeros(5))


def test_a_registered_sensor_is_held_like_a_built_in_one():
    odom = _twist()
    with registered(_beeper()):
        beeps = _Beeps(np.array([0.05, 0.25]))
        streams = SensorStreams(odom=odom, beeper=beeps, camera_height=0.3)
        assert streams["beeper"] is beeps and streams.beeper is beeps and streams.get("beeper") is beeps
        assert streams["odom"] is odom and streams.odom is odom and streams.data("odom") is odom
        assert streams.imu is None and "imu" not in streams and streams.get("gps") is None
        assert list(streams) == ["odom", "beeper"]  # the registry's order: built-in ones first
        assert streams.available() == ["odom", "beeper"]
        picked = streams.select(["odom", "beeper"])
        assert picked.beeper is beeps and picked.camera_height == 0.3
        # the data by name as before (a plugin written against SensorStreams.extra still finds its own)
        assert streams.extra == {"beeper": beeps}
        with pytest.raises(TypeError):  # a write there would be lost: it is refused
            streams.extra["beeper"] = None


def test_the_camera_answers_to_its_second_name():
    inc = VisualIncrement(0.0, 0.1, np.zeros(3), np.eye(3) * 1e-6)
    streams = SensorStreams(visual=[inc])
    assert streams["camera"] == [inc] and streams.visual == [inc] and streams.camera == [inc]
    assert streams.replace(camera=None).visual is None and streams.visual == [inc]  # a copy


def test_replace_changes_one_sensor_or_fact_and_shares_the_rest():
    odom, rng = _twist(), RangeData(np.arange(3) * 0.1, np.full(3, 0.3))
    streams = SensorStreams(odom=odom, range=rng, camera_height=0.3, range_in_visual=True)
    out = streams.replace(range=None, camera_height=0.25)
    assert out.range is None and out.odom is odom and out.camera_height == 0.25 and out.range_in_visual
    assert streams.range is rng and streams.camera_height == 0.3  # the original is unchanged
    streams.odom = None  # setting a sensor's data to None leaves it out
    assert "odom" not in streams and streams.available() == ["range"]


def test_a_misspelt_sensor_is_an_error_not_a_silent_field():
    with pytest.raises(TypeError, match="'whel' is no sensor"):
        SensorStreams(whel=_twist())
    streams = SensorStreams()
    with pytest.raises(AttributeError):
        streams.whel = _twist()
    with pytest.raises(AttributeError):
        streams.whel


def test_every_sensor_is_replayed_through_its_own_intake():
    """time_ordered_messages takes each sensor's samples from its Live intake: a registered sensor's beside the
    built-in ones, in time order, ties broken by the intakes' order (camera 0, wheels 1, ... others 4)."""
    inc = VisualIncrement(0.0, 0.1, np.zeros(3), np.eye(3) * 1e-6)
    with registered(_beeper()):
        streams = SensorStreams(visual=[inc], odom=_twist(), beeper=_Beeps(np.array([0.1, 0.25])))
        msgs = time_ordered_messages(streams, camera_delay=0.0)
        kinds = [(round(t, 3), kind) for t, kind, _ in msgs]
        assert kinds == [(0.0, "twist"), (0.1, "visual"), (0.1, "twist"), (0.1, "beeper"), (0.2, "twist"),
                         (0.25, "beeper"), (0.3, "twist"), (0.4, "twist")]
        assert [message_sensor(k) for k in ("visual", "twist", "beeper", "imu")] == ["camera", "odom", "beeper", "imu"]
        late = time_ordered_messages(streams, camera_delay=0.2)
        assert [t for t, kind, _ in late if kind == "visual"] == [pytest.approx(0.3)]
