"""Generated recordings for the consistency checks, made once per session and broken in copies."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from fusion_vo.simulation import simulate

sys.path.insert(0, str(Path(__file__).parent))

#: a 30 s random drive whose camera is a token (64 x 36 at 5 Hz: the checks here use wheels, IMU, twist)
TOKEN_CAMERA = {"width": 64, "height": 36, "fu": 42.0, "fv": 42.0, "cu": 31.5, "cv": 17.5, "camera_rate": 5.0,
                "supersample": 1}
#: a 0.3 m square at 20 Hz through a 320 x 180 camera of focal length 210 px: four straight legs for the scale
SMALL_SQUARE = {"side": 0.3, "width": 320, "height": 180, "fu": 210.0, "fv": 210.0, "cu": 159.5, "cv": 89.5}


@pytest.fixture(scope="session")
def drive(tmp_path_factory) -> Path:
    """The unbroken 30 s drive (never modify it: use ``broken``)."""
    return simulate(tmp_path_factory.mktemp("drive") / "rec", profile="random", seed=3, duration=30.0, **TOKEN_CAMERA)


@pytest.fixture
def broken(drive, tmp_path) -> Path:
    """A fresh copy of the drive to break."""
    return Path(shutil.copytree(drive, tmp_path / "rec"))


@pytest.fixture(scope="session")
def square(tmp_path_factory) -> Path:
    """The small square (never modify it)."""
    return simulate(tmp_path_factory.mktemp("square") / "rec", profile="square", seed=1, **SMALL_SQUARE)


@pytest.fixture(scope="session")
def square_vo(square):
    """Visual odometry of the small square with its true focal length."""
    from fusion_vo.odometry import OdometryConfig, run_visual_odometry
    from fusion_vo.recording import Recording

    rec = Recording(square)
    return rec, run_visual_odometry(rec, OdometryConfig())
