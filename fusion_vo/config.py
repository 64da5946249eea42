"""Run configuration: every parameter has a documented default and can be set from a YAML file.

A configuration file has one section per stage; any key left out keeps its default::

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

The schema is made of the frontends' own pydantic models and of models derived from the other stages'
dataclasses (:mod:`fusion_vo.schema`), so an option is defined once, where it is used. ``fusion-vo run --print-config`` prints every option with its default
and description; ``fusion-vo run --print-schema`` prints the JSON schema (for editors). A mistake names
the file, the key path and what was expected::

    run.yaml: fusion.ekf.accel_sigma: expected a number, got 'abc'
"""

from __future__ import annotations

import dataclasses
import functools
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from fusion_vo.choices import BACKENDS, FRONTENDS, SENSORS  # noqa: F401 (re-exported: the names of the choices)

if TYPE_CHECKING:  # the stages, pydantic and OpenCV are loaded when a configuration is built, not for --help
    from pydantic import BaseModel

    from fusion_vo.odometry import OdometryConfig

#: fields of OdometryConfig that the run sets itself (from ``frontend`` and the frontend's section)
_ODOMETRY_EXCLUDE = ("frontend", "frontend_options")


def _sections() -> dict[str, tuple[type, tuple[str, ...]]]:
    """The sections that are a stage's configuration (a pydantic model or a dataclass): name -> (class, fields
    not in the file)."""
    from frontends.direct import DirectConfig
    from frontends.features import FeatureConfig
    from frontends.klt import KltConfig
    from fusion_vo.backends.config import FusionConfig
    from fusion_vo.odometry import OdometryConfig

    return {"odometry": (OdometryConfig, _ODOMETRY_EXCLUDE), "klt": (KltConfig, ()),
            "features": (FeatureConfig, ()), "direct": (DirectConfig, ()), "fusion": (FusionConfig, ("sensors", "states"))}


@dataclass
class RunConfig:
    """Configuration of ``fusion-vo run``.

    Attributes
    ----------
    frontend : str
        Visual frontend: ``klt``, ``features`` or ``direct``.
    sensors : list of str or None
        Sensors the backends may use (of camera, wheel, imu, odom, range, gps, or any sensor registered with
        ``fusion_vo.sensors.registry``); the recording must have them. ``None``
        (the default) uses the camera, wheels and IMU the recording has; GPS (``gps0/``) is fused only
        when listed, and the world frame is then East-North-Up at its datum.
    backend : str
        ``none`` (visual and wheel dead reckoning only), ``ekf``, ``gtsam`` or ``all``.
    odometry : dict
        Visual odometry options: the fields of ``fusion_vo.odometry.OdometryConfig`` except ``frontend``.
    klt : dict
        Options of the KLT frontend (``frontends.klt.KltConfig``).
    features : dict
        Options of the corner-feature frontend (``frontends.features.FeatureConfig``).
    direct : dict
        Options of the direct (photometric) frontend (``frontends.direct.DirectConfig``).
    fusion : dict
        Backend options (``fusion_vo.backends.FusionConfig``).
    evaluate : bool
        Evaluate against ground truth at the end of the run when the recording has it.
    influence : bool
        Run the EKF and its smoother once more with each input left out and report how far each input moved the
        fused track (``influence.json``, the report's verdict; :mod:`fusion_vo.evaluation.influence`). It costs
        one fusion per input: on robot_localization's 395 s Husky log it doubles the CPU time of an EKF-only run
        (11.9 s against 5.9 s, ``docs/report.md``); false skips it.
    """

    frontend: str = "klt"
    sensors: list[str] | None = None
    backend: str = "all"
    odometry: dict = field(default_factory=dict)
    klt: dict = field(default_factory=dict)
    features: dict = field(default_factory=dict)
    direct: dict = field(default_factory=dict)
    fusion: dict = field(default_factory=dict)
    evaluate: bool = True
    influence: bool = True

    def odometry_config(self) -> OdometryConfig:
        """The visual odometry configuration, with the chosen frontend's options."""
        from fusion_vo.odometry import OdometryConfig

        opts = dict(self.odometry)
        opts["frontend"] = self.frontend
        opts["frontend_options"] = dict(getattr(self, self.frontend, None) or {})  # the section named by frontend
        return OdometryConfig.from_dict(opts)

    def fusion_config(self, path: Path | None = None):
        """The backends' :class:`~fusion_vo.backends.FusionConfig` (validated by the schema)."""
        from fusion_vo import schema
        from fusion_vo.backends.config import FusionConfig

        return FusionConfig.from_dict(self.fusion, path, ("fusion",))

    def validate(self, path: Path | None = None) -> None:
        """Check every section against the schema; raise :class:`InputError` naming the key path."""
        validate_config(self.to_dict(), path)

    def resolved(self, path: Path | None = None) -> "RunConfig":
        """This configuration with every option of every section filled in (for ``run.yaml``)."""
        return validate_config(self.to_dict(), path)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def _split_sensors(value):
    if isinstance(value, str):
        return [s.strip() for s in value.split(",") if s.strip()]
    return value


def run_model() -> type[BaseModel]:
    """The pydantic model of the whole run configuration (sections from the stages' models): the sensor
    names are the registered ones, and the ``fusion`` section holds the registered sensors' sections
    (:mod:`fusion_vo.sensors.registry`), so the model follows the registry."""
    from fusion_vo.backends.config import FusionConfig
    from fusion_vo.sensors import registry

    own = {f.name for f in dataclasses.fields(FusionConfig)}
    sections = tuple(s.config for s in registry.sensors() if s.config is not None and s.config[0] not in own)
    registered = registry.names()  # the built-in names in their documented order, then the others
    names = tuple(n for n in SENSORS if n in registered) + tuple(n for n in registered if n not in SENSORS)
    return _run_model(names, sections, registry.all_states())


@functools.cache
def _run_model(sensor_names: tuple[str, ...], sensor_sections: tuple, states: tuple = ()) -> type[BaseModel]:
    from pydantic import ConfigDict, Field, create_model, field_validator

    from fusion_vo import schema

    docs = schema.field_docs(RunConfig)
    fields: dict[str, Any] = {
        "frontend": (Literal[FRONTENDS], Field("klt", description=docs["frontend"])),
        "sensors": (list[Literal[sensor_names]] | None, Field(None, description=docs["sensors"])),
        "backend": (Literal[BACKENDS], Field("all", description=docs["backend"])),
    }
    for name, (cls, exclude) in _sections().items():
        section = schema.model_of(cls, exclude)
        if name == "fusion" and (sensor_sections or states):  # the registered sensors' sections and states
            extra = {}
            for key, section_cls in sensor_sections:
                sub = schema.model_of(section_cls)
                extra[key] = (sub, Field(default_factory=sub, description=sub.__doc__))
            if states:
                from fusion_vo.sensors.registry import StatePrior

                priors = {}
                for state in states:
                    sub = schema.model_of(StatePrior, defaults=state.prior())
                    priors[state.name] = (sub, Field(default_factory=sub, description=f"{state.name}: its prior "
                                                                                  "(initial, sigma) and random walk"))
                model = create_model("States", __config__=ConfigDict(extra="forbid"), **priors)
                extra["states"] = (model, Field(default_factory=model, description=schema.field_docs(cls)["states"]))
            section = create_model("FusionConfig", __base__=section, **extra)
        fields[name] = (section, Field(default_factory=section, description=docs[name]))
    fields["evaluate"] = (bool, Field(True, description=docs["evaluate"]))
    fields["influence"] = (bool, Field(True, description=docs["influence"]))
    validators = {"split_sensors": field_validator("sensors", mode="before")(_split_sensors)}
    return create_model("RunConfig", __config__=ConfigDict(extra="forbid", title="fusion-vo run configuration"),
                        __doc__="Configuration of fusion-vo run (a YAML file given with --config).",
                        __validators__=validators, **fields)


def validate_config(data: dict, path: Path | None = None) -> RunConfig:
    """Validate a run configuration mapping and return the :class:`RunConfig` with every option filled in.

    Raises
    ------
    InputError
        For an unknown key, a value of the wrong type or a combination of options a stage rejects; the
        message names ``path`` and the key path.
    """
    from fusion_vo import schema

    if isinstance(data, dict):  # a top-level key left empty keeps its default
        data = {k: v for k, v in data.items() if v is not None}
    values = schema.validate(run_model(), data, path)
    sections = {}
    for name, (cls, exclude) in _sections().items():
        if name == "fusion":  # with the registered sensors' sections (FusionConfig.sensors)
            built = cls.from_dict(schema.plain(getattr(values, name)), path, (name,))
            sections[name] = {k: v for k, v in schema.plain(built).items() if k not in exclude}
            sections[name].update(schema.plain(built.sensors))
            if built.states:
                sections[name]["states"] = schema.plain(built.states)
            continue
        built = schema.to_dataclass(cls, getattr(values, name), path, (name,))  # the stage's own checks
        sections[name] = {k: v for k, v in schema.plain(built).items() if k not in exclude}
    return RunConfig(frontend=values.frontend, sensors=None if values.sensors is None else list(values.sensors),
                     backend=values.backend, evaluate=values.evaluate, influence=values.influence, **sections)


def load_config(path: str | Path | None) -> RunConfig:
    """Read a YAML configuration (missing keys keep their defaults); ``None`` gives the defaults.

    A run's own ``run.yaml`` reads back as its configuration: the recording it names (``sequence``) is left
    to the command's argument.

    The returned sections hold every option of their stage (the file's values and the defaults).
    """
    if path is None:
        return RunConfig()
    from fusion_vo.geometry.camera import load_yaml

    path = Path(path)
    data = load_yaml(path)
    if isinstance(data.get("sequence"), str):  # a run's own run.yaml: the recording it names is the run's argument
        data = {k: v for k, v in data.items() if k != "sequence"}
    return validate_config(data, path)


def default_config_text(config: RunConfig | None = None) -> str:
    """The configuration as commented YAML (for ``--print-config``): every option, with its value in
    ``config`` (default: the defaults) and the first sentence of its description."""
    from fusion_vo import schema

    model = run_model()
    values = None if config is None else schema.validate(model, config.to_dict())
    lines = [f"# fusion-vo run configuration: every option with its {'default' if config is None else 'value'}",
             "# (units in square brackets; fusion-vo run --print-schema gives the full descriptions)"]
    return "\n".join(lines + schema.commented_yaml(model, values)) + "\n"


def schema_text() -> str:
    """The JSON schema of the run configuration (for ``--print-schema``)."""
    from fusion_vo import schema

    return json.dumps(schema.json_schema(run_model()), indent=2) + "\n"


#: the paragraph under the generated reference's heading (``docs/configuration-reference.md``)
REFERENCE_INTRO = """Every option of the YAML file that `fusion-vo run --config FILE` reads, section by section, with its
default, the values it accepts and its description (the dataclasses' docstrings, through the same schema that
checks the file). Any key left out keeps its default. The numbers of `fusion` have no per-option range here:
their rules (every `*sigma*` positive, every other number non-negative, a few counts, fractions and upper
bounds) are listed in [configuration.md](configuration.md#ranges). Sensors registered by an installed package
add their own sections to `fusion`."""


def reference_text() -> str:
    """The configuration reference as Markdown (for ``--print-reference``, ``docs/configuration-reference.md``)."""
    from fusion_vo import schema

    return schema.markdown_reference(run_model(), "Configuration reference", REFERENCE_INTRO,
                                     "fusion-vo run --print-reference > docs/configuration-reference.md")
