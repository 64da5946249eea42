"""The DDS tests' peer, run while the session's second process runs at the lowest priority (tests/background.py):
the node's timing is then the machine's, the jobs take only the time it leaves."""

from __future__ import annotations

from contextlib import nullcontext

import pytest

from dds_namespace import run_peer


@pytest.fixture(scope="session")
def peer(background):
    """``peer(tmp_path, spec)``: :func:`dds_namespace.run_peer` with the background jobs at the lowest priority
    meanwhile."""

    def run(tmp_path, spec):
        with background.lowest() if background is not None else nullcontext():
            return run_peer(tmp_path, spec)

    return run
