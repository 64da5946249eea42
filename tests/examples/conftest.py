"""The example scripts' runs, made in the background from the session's start (tests/background.py)."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture
def example(background):
    """``example(name)`` -> (standard output, output folder) of ``python examples/NAME.py --quick --seed 1
    --out DIR``, which exited with status 0 (the test names ``example:NAME`` in its ``BACKGROUND_JOBS``)."""

    def get(name: str) -> tuple[str, Path]:
        key = f"example:{name}"
        assert background is not None and key in background, f"{key} is in no collected test's BACKGROUND_JOBS"
        job = background.result(key)
        return job.stdout, job.out

    return get
