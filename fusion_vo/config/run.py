"""The configuration of ``fusion-vo run``: one section per stage; any key left out keeps its default::

    frontend: klt            # or: features, direct
    sensors: [camera, wheel, imu]   # default: those the recording has; any registered sensor's name
    backend: all             # none | ekf | gtsam | all
    odometry: {height: null, use_range: true, min_sigma_xy: 2.0e-5, min_sigma_yaw: 2.0e-5}
    klt: {...}               # frontends.klt.KltConfig
    features: {...}          # frontends.features.FeatureConfig
    direct: {...}            # frontends.direct.DirectConfig
    fusion: {...}            # fusion_vo.backends.FusionConfig (ekf, graph, sensor noise models, and the
                             # section of each sensor registered outside the library, e.g. compass: {sigma: 0.02})
    evaluate: true           # compute metrics and plots when the recording has ground truth
    influence: true          # fuse once more without each input and report how far each moved the track

:class:`RunConfig` is composed of the stages' own models, so an option is defined once, where it is used.
``fusion-vo run --print-config`` prints every option with its default and description, ``--print-schema`` the JSON
schema (for editors), ``--print-reference`` the Markdown reference (``docs/configuration-reference.md``); all three
come from the models (:mod:`fusion_vo.config.render`) with the sections and states of the registered sensors
(:func:`run_model`). A run's own ``run.yaml`` is :meth:`RunConfig.to_dict` and reads back as the same
configuration (:func:`load_config`).
"""

from __future__ import annotations

import functools
import json
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, ConfigDict, Field, field_validator
from pydantic_core import PydanticCustomError

from frontends.direct_config import DirectConfig
from frontends.features_config import FeatureConfig
from frontends.klt_config import KltConfig
from fusion_vo.backends.config import FusionConfig
from fusion_vo.config import BACKENDS, FRONTENDS, SENSORS
from fusion_vo.config.base import Section
from fusion_vo.config.files import load_yaml, validate
from fusion_vo.config.render import commented_yaml, json_schema, markdown_reference, view
from fusion_vo.config.odometry import OdometryConfig, OdometrySettings
from fusion_vo.sensors import registry


def sensor_names() -> tuple[str, ...]:
    """The registered sensors' names: the built-in ones in their documented order, then the others."""
    registered = registry.names()
    return tuple(n for n in SENSORS if n in registered) + tuple(n for n in registered if n not in SENSORS)


def _registered_sensor(name: str) -> str:
    registry.ensure([name])  # an instance of a kind (odom1, imu2) is made when named
    names = sensor_names()
    if name not in names:
        expected = ", ".join(repr(n) for n in names[:-1]) + f" or {names[-1]!r}"
        raise PydanticCustomError("literal_error", "Input should be {expected}", {"expected": expected})
    return name


#: a sensor's name: a registered one (:mod:`fusion_vo.sensors.registry`)
SensorName = Annotated[str, AfterValidator(_registered_sensor)]


class RunConfig(Section):
    """Configuration of ``fusion-vo run`` (a YAML file given with ``--config``; module docstring)."""

    model_config = ConfigDict(title="fusion-vo run configuration")

    frontend: Literal[FRONTENDS] = Field("klt", description="Visual frontend: ``klt``, ``features`` or ``direct``.")
    sensors: list[SensorName] | None = Field(None, description=(
        "Sensors the backends may use (of camera, wheel, imu, odom, range, gps, or any sensor registered with "
        "``fusion_vo.sensors.registry``); the recording must have them. Null (the default) uses the camera, wheels "
        "and IMU the recording has; GPS (``gps0/``) is fused only when listed, and the world frame is then "
        "East-North-Up at its datum."))
    backend: Literal[BACKENDS] = Field("all", description=(
        "``none`` (visual and wheel dead reckoning only), ``ekf``, ``gtsam`` or ``all``."))
    odometry: OdometrySettings = Field(default_factory=OdometrySettings, description=(
        "Visual odometry options: the fields of ``fusion_vo.config.odometry.OdometryConfig`` except the frontend "
        "and its options."))
    klt: KltConfig = Field(default_factory=KltConfig, description="Options of the KLT frontend "
                                                                   "(``frontends.klt.KltConfig``).")
    features: FeatureConfig = Field(default_factory=FeatureConfig, description=(
        "Options of the corner-feature frontend (``frontends.features.FeatureConfig``)."))
    direct: DirectConfig = Field(default_factory=DirectConfig, description=(
        "Options of the direct (photometric) frontend (``frontends.direct.DirectConfig``)."))
    fusion: FusionConfig = Field(default_factory=FusionConfig, description=(
        "Backend options (``fusion_vo.backends.FusionConfig``)."))
    evaluate: bool = Field(True, description="Evaluate against ground truth at the end of the run when the recording "
                                             "has it.")
    influence: bool = Field(True, description=(
        "Run the EKF and its smoother once more with each input left out and report how far each input moved the "
        "fused track (``influence.json``, the report's verdict; :mod:`fusion_vo.evaluation.influence`). It costs "
        "one fusion per input: on robot_localization's 395 s Husky log it doubles the CPU time of an EKF-only run "
        "(11.9 s against 5.9 s, ``docs/report.md``); false skips it."))

    @field_validator("sensors", mode="before")
    @classmethod
    def _split_sensors(cls, value: Any) -> Any:
        """``camera, wheel`` (one string) is ``[camera, wheel]``."""
        if isinstance(value, str):
            return [s.strip() for s in value.split(",") if s.strip()]
        return value

    def odometry_config(self) -> OdometryConfig:
        """The visual odometry configuration, with the chosen frontend and its section's options."""
        return OdometryConfig(**dict(self.odometry), frontend=self.frontend,
                              frontend_options=getattr(self, self.frontend).to_dict())

    def to_dict(self) -> dict[str, Any]:
        """Every option as plain YAML-safe values (what ``run.yaml`` holds; reads back as this configuration)."""
        return self.model_dump(mode="json")


def validate_config(data: Any, path: str | Path | None = None) -> RunConfig:
    """A run configuration from a mapping (read from ``path``), every option filled in.

    A top-level key or a section left empty (null) keeps its defaults.

    Raises
    ------
    InputError
        For an unknown key, a value of the wrong type or out of its range, or a combination of options a
        stage rejects; the message names ``path`` and the key path.
    """
    if isinstance(data, dict):
        data = {k: v for k, v in data.items() if v is not None}
    return validate(RunConfig, data, path)


def load_config(path: str | Path | None) -> RunConfig:
    """Read a YAML configuration (missing keys keep their defaults); ``None`` gives the defaults.

    A run's own ``run.yaml`` reads back as its configuration: the recording it names (``sequence``) is left
    to the command's argument.
    """
    if path is None:
        return RunConfig()
    path = Path(path)
    data = load_yaml(path)
    if isinstance(data.get("sequence"), str):  # a run's own run.yaml: the recording it names is the run's argument
        data = {k: v for k, v in data.items() if k != "sequence"}
    return validate_config(data, path)


def run_model() -> type[Section]:
    """The run configuration as the schema and the printed configuration show it: :class:`RunConfig` with the
    registered sensors' names as the choices of ``sensors``, and in ``fusion`` the registered sensors' sections
    and the priors of their states, every field's default the one in effect (a section whose defaults differ
    from its class's, like ``fusion.odom``, shows its own)."""
    sections = tuple(s.config for s in registry.sensors()
                     if s.config is not None and s.config[0] not in FusionConfig.model_fields)
    return _run_model(sensor_names(), sections, registry.configurable_states())


@functools.cache
def _run_model(names: tuple[str, ...], sections: tuple, states: tuple) -> type[Section]:
    defaults = RunConfig().to_dict()
    models = {f"fusion.{name}": model for name, model in sections}
    for state in states:
        models[f"fusion.states.{state.name}"] = registry.StatePrior
    return view(RunConfig, defaults, models, {"sensors": (list[Literal[names]] | None)})


def default_config_text(config: RunConfig | None = None) -> str:
    """The configuration as commented YAML (for ``--print-config``): every option, with its value in
    ``config`` (default: the defaults) and the first sentence of its description."""
    values = (config or RunConfig()).to_dict()
    lines = [f"# fusion-vo run configuration: every option with its {'default' if config is None else 'value'}",
             "# (units in square brackets; fusion-vo run --print-schema gives the full descriptions)"]
    return "\n".join(lines + commented_yaml(run_model(), values)) + "\n"


def schema_text() -> str:
    """The JSON schema of the run configuration (for ``--print-schema``)."""
    return json.dumps(json_schema(run_model()), indent=2) + "\n"


#: the paragraph under the generated reference's heading (``docs/configuration-reference.md``)
REFERENCE_INTRO = """Every option of the YAML file that `fusion-vo run --config FILE` reads, section by section, with its
default, the values it accepts (its range) and its description, from the configuration's models, the same that
check the file. Any key left out keeps its default. Sensors registered by an installed package add their own
sections to `fusion`."""


def reference_text() -> str:
    """The configuration reference as Markdown (for ``--print-reference``, ``docs/configuration-reference.md``)."""
    return markdown_reference(run_model(), RunConfig().to_dict(), "Configuration reference", REFERENCE_INTRO,
                              "fusion-vo run --print-reference > docs/configuration-reference.md")
