"""Configuration: one source for every option and for every ``sensor.yaml`` key.

Every configuration class is a pydantic model built on :class:`~fusion_vo.config.base.Section` (itself
the frontends' :class:`frontends.config.Settings`): each field carries its default, its range
(``ge``/``gt``/``le``/``lt``), its unit (in square brackets in the description) and its description; checks
that involve several fields are ``model_validator`` methods. A class stays in the module that uses it
(``FusionConfig`` in :mod:`fusion_vo.backends.config`, a sensor's noise model in its sensor's module,
``SimulationOptions`` in :mod:`fusion_vo.simulation.generate`); this package holds what they share and visual
odometry's settings:

``base``          :class:`~fusion_vo.config.base.Section`, the shared ranges, the one-line errors;
``files``         YAML loading (a key given twice is an error) and validation that names the file and the key
                  path (:class:`~fusion_vo.errors.InputError`);
``odometry``      :class:`~fusion_vo.config.odometry.OdometryConfig`, visual odometry's settings;
``run``           :class:`~fusion_vo.config.run.RunConfig`, the configuration of ``fusion-vo run``, composed of
                  the stages' sections, and :func:`~fusion_vo.config.run.load_config`;
``sensor_files``  the models of the ``sensor.yaml`` files a recording holds;
``render``        ``--print-config``, ``--print-schema`` and ``--print-reference`` from the models.

A mistake names the file, the key path and what was expected::

    run.yaml: fusion.ekf.accel_sigma: expected a number, got 'abc'
    run.yaml: fusion.graph: max_iterations must be at most 1000, not 100000

The names of the submodules are available from this package (``from fusion_vo.config import RunConfig,
load_config``); they are imported when first asked for, so that ``fusion-vo --help`` loads neither pydantic nor
the stages.
"""

from __future__ import annotations

import importlib
from typing import Any

from fusion_vo.choices import BACKENDS, FRONTENDS, SENSORS  # noqa: F401 (the names a run chooses among)

#: the names this package gives, by the submodule that defines them
_NAMES = {
    "Section": "base", "ConfigError": "base",
    "load_yaml": "files", "load_yaml_text": "files", "validate": "files", "write_yaml_atomic": "files",
    "RunConfig": "run", "load_config": "run", "validate_config": "run", "run_model": "run",
    "default_config_text": "run", "schema_text": "run", "reference_text": "run",
    "OdometryConfig": "odometry", "OdometrySettings": "odometry",
}


def __getattr__(name: str) -> Any:
    if name not in _NAMES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{_NAMES[name]}"), name)


def __dir__() -> list[str]:
    return sorted([*globals(), *_NAMES])
