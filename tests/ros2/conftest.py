"""The DDS tests' peer, run while the session's second process is quiet (tests/background.py): a node's timing
is then the machine's, not that of a job running beside it."""

from __future__ import annotations

from contextlib import nullcontext

import pytest

from dds_namespace import run_peer


@pytest.fixture(scope="session")
def peer(background):
    """``peer(tmp_path, spec)``: :func:`dds_namespace.run_peer` with no background job running meanwhile."""

    def run(tmp_path, spec):
        with background.quiet() if background is not None else nullcontext():
            return run_peer(tmp_path, spec)

    return run
