"""The IMU mounting check in streaming fusion, on the samples seen so far."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from test_mounting import ON_ITS_SIDE, mounted

from fusion_vo.backends import FusionConfig
from fusion_vo.backends.streaming import streaming_for, time_ordered_messages
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams

sys.path.insert(0, str(Path(__file__).parents[1] / "backends"))
from backend_synth import streams_of  # noqa: E402


@pytest.fixture(scope="module")
def streams():
    """15 s of camera, wheels and an IMU whose accelerometer reads gravity, as stated."""
    return streams_of(synthetic_streams(SyntheticOptions(duration=15.0), seed=3)).select(["camera", "wheel", "imu"])


def stream(streams, config: FusionConfig | None = None, backend: str = "ekf"):
    fusion = streaming_for(streams, backend, config or FusionConfig())
    for _, kind, message in time_ordered_messages(streams):
        getattr(fusion, f"add_{kind}")(message)
    return fusion.finish()


@pytest.fixture(scope="module")
def unbroken(streams):
    return stream(streams)


def test_valid_stream_is_fused_as_without_the_check(streams, unbroken):
    off = FusionConfig()
    off.consistency.check = False
    np.testing.assert_array_equal(unbroken.trajectories["ekf"].xyyaw, stream(streams, off).trajectories["ekf"].xyyaw)
    assert [f["decision"] for f in unbroken.consistency] == ["kept"]  # once the gyro's axis was seen


@pytest.mark.parametrize("backend", ["ekf", "gtsam"])
def test_imu_on_its_side_is_read_with_the_mounting_found_at_once(streams, unbroken, backend):
    result = stream(mounted(streams, ON_ITS_SIDE), backend=backend)
    (note,) = [n for n in result.notes if n.startswith("live check from")]
    assert "imu0/sensor.yaml: T_BS contradicts the data" in note
    name = "ekf" if backend == "ekf" else "gtsam_online"
    reference = unbroken if backend == "ekf" else stream(streams, backend=backend)
    np.testing.assert_allclose(result.trajectories[name].xyyaw[:, :2], reference.trajectories[name].xyyaw[:, :2],
                               atol=1e-6)


def test_imu_whose_gyro_and_gravity_disagree_is_left_out(streams, unbroken):
    """Without gravity to decide at once, the gyro's axis decides once the drive has turned; gravity then
    contradicts it and the IMU's later samples are left out (counted as gated)."""
    result = stream(mounted(streams, ON_ITS_SIDE, accel=False))
    (note,) = [n for n in result.notes if n.startswith("live check from")]
    assert "the IMU is left out of this run" in note
    counts = result.counts["ekf"]["gyro"]
    assert counts.gated > 0.5 * len(streams.imu.t), counts
