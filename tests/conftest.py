"""Every test carries the marker of its layer, from the folder it lives in (``pytest -m unit`` runs the first).

unit         one module or class on small inputs made in the test: frontends, geometry, sensors (the
             measurement models), configuration, recording reader, evaluation metrics
integration  several stages together on a generated drive or a real bag: backends, consistency checks,
             calibration, simulation, export
end_to_end   the commands and scripts as a user runs them: end_to_end, faults, batch, ros2, examples,
             benchmarks, ecosystem (install, licences, documentation)
"""

from __future__ import annotations

from pathlib import Path

import pytest

LAYERS = {
    "unit": ("frontends", "geometry", "sensors", "config", "recording", "evaluation"),
    "integration": ("backends", "consistency", "calibration", "simulation", "export"),
    "end_to_end": ("end_to_end", "faults", "batch", "ros2", "examples", "benchmarks", "ecosystem"),
}
FOLDER_LAYER = {folder: layer for layer, folders in LAYERS.items() for folder in folders}
TESTS = Path(__file__).resolve().parent


def pytest_collection_modifyitems(config, items) -> None:
    """Mark each test with its folder's layer; a test folder that no layer names is an error."""
    for item in items:
        folder = Path(item.fspath).resolve().relative_to(TESTS).parts[0]
        if folder not in FOLDER_LAYER:
            raise pytest.UsageError(f"tests/{folder}: no layer in tests/conftest.py's LAYERS names this folder")
        item.add_marker(getattr(pytest.mark, FOLDER_LAYER[folder]))
