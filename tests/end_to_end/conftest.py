"""Generated recordings shared by the end-to-end tests (made once per test session)."""

import pytest

from fusion_vo.simulation.standard import make_standard


@pytest.fixture(scope="session")
def standard_recording(tmp_path_factory):
    """``standard_recording(name)`` -> path of that standard generated recording."""
    made = {}

    def get(name):
        if name not in made:
            made[name] = make_standard(name, tmp_path_factory.mktemp("rec") / name)
        return made[name]

    return get
