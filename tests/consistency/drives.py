"""The generated recordings the consistency checks break: their parameters and how each is made."""

from __future__ import annotations

from pathlib import Path

from fusion_vo.simulation import simulate

#: a 30 s random drive whose camera is a token (64 x 36 at 5 Hz: the checks here use wheels, IMU, twist)
TOKEN_CAMERA = {"width": 64, "height": 36, "fu": 42.0, "fv": 42.0, "cu": 31.5, "cv": 17.5, "camera_rate": 5.0,
                "supersample": 1}
#: a 0.3 m square at 20 Hz through a 320 x 180 camera of focal length 210 px: four straight legs for the scale
SMALL_SQUARE = {"side": 0.3, "width": 320, "height": 180, "fu": 210.0, "fv": 210.0, "cu": 159.5, "cv": 89.5}


def make_drive(path: Path) -> Path:
    """The 30 s random drive (seed 3) through the token camera, written to ``path``."""
    return simulate(path, profile="random", seed=3, duration=30.0, **TOKEN_CAMERA)


def make_square(path: Path) -> Path:
    """The small square (seed 1), written to ``path``."""
    return simulate(path, profile="square", seed=1, **SMALL_SQUARE)
