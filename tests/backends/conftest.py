"""Shared synthetic recordings for the backend tests (generated, never read from disk)."""

import pytest
from backend_synth import streams_of

from fusion_vo.backends import FusionConfig, fuse
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams


@pytest.fixture(scope="session")
def calibrated_error():
    """30 s with a 2 % camera-height error, stated as the simulator states it (2 mm), fused by both backends."""
    s = synthetic_streams(SyntheticOptions(duration=30.0, visual_scale=1.02), seed=3)
    result = fuse(streams_of(s, stated_scale=1.02).select(["camera", "wheel", "imu"]), "all", FusionConfig())
    return s, result


@pytest.fixture(scope="session")
def faults():
    """The same drive with a gyro spike, an encoder jump and a wrong visual match, and its clean twin."""
    opts = dict(duration=30.0, visual_scale=1.02)
    clean = synthetic_streams(SyntheticOptions(**opts), seed=3)
    bad = synthetic_streams(SyntheticOptions(**opts, gyro_spike_at=12.0, tick_jump_at=17.0, wrong_matches=[8.0]), seed=3)
    sensors = ["camera", "wheel", "imu"]
    return clean, fuse(streams_of(clean).select(sensors), "all"), bad, fuse(streams_of(bad).select(sensors), "all")
