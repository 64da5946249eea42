"""A small generated recording, broken in many ways by the fault-injection tests.

Every fault is checked against the same promise: exit status 0 or 2, no traceback, a one-line error that
names the file (and line, or key), nothing half-written, and nothing outside the output folder touched.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import pytest

from fault_tools import make_pristine


@pytest.fixture(scope="session")
def pristine(tmp_path_factory) -> Path:
    """The unbroken recording (never modify it: use ``recording``)."""
    return make_pristine(tmp_path_factory.mktemp("faults") / "rec")


@pytest.fixture
def recording(pristine, tmp_path) -> Path:
    """A fresh copy of the recording in ``tmp_path/rec`` to break."""
    return Path(shutil.copytree(pristine, tmp_path / "rec", symlinks=True))


@pytest.fixture(scope="session")
def pristine_run(pristine, tmp_path_factory) -> Path:
    """A run folder of the recording (EKF only; never modify it: use ``run_folder``)."""
    from fusion_vo.cli.main import main

    out = tmp_path_factory.mktemp("faults_run") / "run"
    assert main(["-q", "run", str(pristine), "--out", str(out), "--backend", "ekf", "--no-evaluate"]) == 0
    return out


@pytest.fixture
def run_folder(pristine_run, tmp_path) -> Path:
    """A fresh copy of the run folder in ``tmp_path/run`` to break."""
    return Path(shutil.copytree(pristine_run, tmp_path / "run", symlinks=True))


def fault_kinds() -> dict[str, int] | None:
    """The ways this suite breaks a recording or its configuration, by kind (the count README.md quotes), or
    ``None`` when the modules that hold them were not collected."""
    recording, config = sys.modules.get("test_recording_faults"), sys.modules.get("test_config_faults")
    if recording is None or config is None:
        return None
    return {"recording faults": len(recording.FAULTS) + len(recording.PHYSICAL_RANGE_FAULTS),
            "out-of-range": len(config.OUT_OF_RANGE), "further fusion values": len(config.FUSION_BAD)}


def pytest_terminal_summary(terminalreporter) -> None:
    """Print the count of fault kinds (README.md: "it breaks a small recording or its configuration in N ways")."""
    kinds = fault_kinds()
    if kinds:
        parts = ", ".join(f"{n} {kind}" for kind, n in kinds.items())
        terminalreporter.write_line(f"fault suite: a recording or its configuration broken in {sum(kinds.values())} "
                                    f"ways ({parts}), and every configured number just outside each end of its range")
