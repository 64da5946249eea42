"""Generated recordings for the consistency checks, made once per session and broken in copies."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

from drives import make_drive, make_square  # noqa: E402


@pytest.fixture(scope="session")
def drive(tmp_path_factory) -> Path:
    """The unbroken 30 s drive (never modify it: use ``broken``)."""
    return make_drive(tmp_path_factory.mktemp("drive") / "rec")


@pytest.fixture
def broken(drive, tmp_path) -> Path:
    """A fresh copy of the drive to break."""
    return Path(shutil.copytree(drive, tmp_path / "rec"))


@pytest.fixture(scope="session")
def square(tmp_path_factory) -> Path:
    """The small square (never modify it)."""
    return make_square(tmp_path_factory.mktemp("square") / "rec")


@pytest.fixture(scope="session")
def square_vo(square):
    """Visual odometry of the small square with its true focal length."""
    from fusion_vo.odometry import OdometryConfig, run_visual_odometry
    from fusion_vo.recording import Recording

    rec = Recording(square)
    return rec, run_visual_odometry(rec, OdometryConfig())
