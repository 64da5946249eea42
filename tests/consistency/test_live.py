"""The IMU mounting check in streaming fusion, on the samples seen so far."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_mounting import ON_ITS_SIDE, mounted

from ahead_job import ahead_jobs

from fusion_vo.backends import FusionConfig
from fusion_vo.backends.streaming import streaming_for, time_ordered_messages
from fusion_vo.sensors.imu import quat_to_matrix
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams

sys.path.insert(0, str(Path(__file__).parents[1] / "backends"))
from backend_synth import streams_of  # noqa: E402


@pytest.fixture(scope="module")
def streams():
    """15 s of camera, wheels and an IMU whose accelerometer reads gravity, as stated."""
    return streams_of(synthetic_streams(SyntheticOptions(duration=15.0), seed=3)).select(["camera", "wheel", "imu"])


def stream(streams, config: FusionConfig | None = None, backend: str = "ekf"):
    fusion = streaming_for(streams, backend, config or FusionConfig())
    fusion.feed(time_ordered_messages(streams))
    return fusion.finish()


@pytest.fixture(scope="module")
def unbroken(streams):
    return stream(streams)


def test_valid_stream_is_fused_as_without_the_check(streams, unbroken):
    off = FusionConfig(consistency={"check": False})
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


def _corrected_mid_stream() -> dict:
    """30 s with no gravity, the IMU on its side, streamed by the EKF: the live check's note, and the RMS position
    error of the track and of the track streamed with the IMU mounted as stated."""
    made = synthetic_streams(SyntheticOptions(duration=30.0, ahrs_sigma=0.01), seed=3)
    right = streams_of(made).select(["camera", "wheel", "imu"])
    right = right.replace(imu=dataclasses.replace(right.imu, accel=np.zeros_like(right.imu.accel)))
    imu = right.imu
    q = Rotation.from_matrix(quat_to_matrix(imu.orientation) @ ON_ITS_SIDE).as_quat()[:, [3, 0, 1, 2]]
    turned = right.replace(imu=dataclasses.replace(imu, gyro=imu.gyro @ ON_ITS_SIDE, orientation=q))

    def rms(result):
        track = result.trajectories["ekf"]
        truth = np.column_stack([np.interp(track.t, made.truth.t, made.truth.xyyaw[:, i]) for i in range(2)])
        return float(np.sqrt(np.mean(np.sum((track.xyyaw[:, :2] - truth) ** 2, axis=1))))

    result = stream(turned)
    return {"notes": result.notes, "rms": rms(result), "rms_as_stated": rms(stream(right))}


AHEAD = {"corrected_mid_stream": _corrected_mid_stream}
BACKGROUND_COMMANDS, BACKGROUND_JOBS = ahead_jobs(__file__)


def test_correction_mid_stream_replaces_the_bias_and_realigns_the_ahrs(made_ahead):
    """No gravity to decide at once: the gyro's axis decides after about 5 s, when the EKF has fused the gyro
    read about the wrong axis (and an AHRS heading read through the wrong mounting). The bias the check's fit
    gives and the AHRS aligned from its first orientation bring the track back to the unbroken one's."""
    made = made_ahead("corrected_mid_stream")
    (note,) = [n for n in made["notes"] if n.startswith("live check from")]
    assert 2.0 < float(note.split("t=")[1].split(":")[0]) < 15.0  # decided mid-stream, by the gyro
    assert made["rms"] < 5 * made["rms_as_stated"] + 0.02, made["rms"]
