"""Small generated recordings shared by the simulator tests (tiny images, a few seconds)."""

from __future__ import annotations

import pytest

from fusion_vo.simulation import simulate

#: an 80 x 48 camera with the default field of view per pixel scaled down, one ray per pixel
TINY = {"width": 80, "height": 48, "fu": 60.0, "fv": 60.0, "cu": 39.5, "cv": 23.5, "supersample": 1}


@pytest.fixture(scope="session")
def generate(tmp_path_factory):
    """``generate(name, profile, seed, **options)``: a tiny recording, made once per session and name."""
    made = {}

    def make(name: str, profile: str = "random", seed: int = 0, **options):
        if name not in made:
            out = tmp_path_factory.mktemp("sim") / name
            made[name] = simulate(out, profile=profile, seed=seed, **{**TINY, **options})
        return made[name]

    return make
