"""Run configuration: every parameter has a documented default and can be set from a YAML file.

A configuration file has one section per stage; any key left out keeps its default::

    frontend: klt            # or: features, direct
    sensors: [camera, wheel, imu]   # default: those the recording has
    backend: all             # none | ekf | gtsam | all
    odometry: {height: null, use_range: true, min_sigma_xy: 2.0e-5, min_sigma_yaw: 2.0e-5}
    klt: {...}               # frontends.klt.KltConfig
    features: {...}          # frontends.features.FeatureConfig
    direct: {...}            # frontends.direct.DirectConfig
    fusion: {...}            # backend options (fusion_vo.backends)
    evaluate: true           # compute metrics and plots when the recording has ground truth

``fusion-vo run --print-config`` prints the full default configuration.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

from fusion_vo.errors import InputError
from fusion_vo.geometry.camera import load_yaml
from fusion_vo.odometry import OdometryConfig

SENSORS = ("camera", "wheel", "imu", "odom", "range")
BACKENDS = ("none", "ekf", "gtsam", "all")
FRONTENDS = ("klt", "features", "direct")


@dataclass
class RunConfig:
    """Configuration of ``fusion-vo run``.

    Attributes
    ----------
    frontend : str
        Visual frontend: ``klt``, ``features`` or ``direct``.
    sensors : list of str or None
        Sensors the backends may use (of :data:`SENSORS`); the recording must have them. ``None``
        (the default) uses the camera, wheels and IMU the recording has.
    backend : str
        ``none`` (visual and wheel dead reckoning only), ``ekf``, ``gtsam`` or ``all``.
    odometry : dict
        :class:`fusion_vo.odometry.OdometryConfig` fields except ``frontend``.
    klt, features, direct : dict
        Options of the three frontends.
    fusion : dict
        Backend options, passed to :mod:`fusion_vo.backends`.
    evaluate : bool
        Evaluate against ground truth at the end of the run when the recording has it.
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

    def odometry_config(self) -> OdometryConfig:
        opts = dict(self.odometry)
        opts["frontend"] = self.frontend
        opts["frontend_options"] = dict(getattr(self, self.frontend if self.frontend in FRONTENDS else "klt"))
        return OdometryConfig.from_dict(opts)

    def validate(self, path: Path | None = None) -> None:
        if self.frontend not in FRONTENDS:
            raise InputError(f"frontend must be one of {', '.join(FRONTENDS)}, not '{self.frontend}'", path)
        if self.backend not in BACKENDS:
            raise InputError(f"backend must be one of {', '.join(BACKENDS)}, not '{self.backend}'", path)
        bad = [s for s in (self.sensors or []) if s not in SENSORS]
        if bad:
            raise InputError(f"unknown sensor '{bad[0]}' (known: {', '.join(SENSORS)})", path)
        try:
            self.odometry_config()
        except (TypeError, ValueError) as exc:
            raise InputError(str(exc), path) from None

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def load_config(path: str | Path | None) -> RunConfig:
    """Read a YAML configuration (missing keys keep their defaults); ``None`` gives the defaults."""
    if path is None:
        return RunConfig()
    path = Path(path)
    data = load_yaml(path)
    known = {f.name for f in dataclasses.fields(RunConfig)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise InputError(f"unknown section '{unknown[0]}' (known: {', '.join(sorted(known))})", path)
    for key in ("odometry", "klt", "features", "direct", "fusion"):
        if key in data and data[key] is not None and not isinstance(data[key], dict):
            raise InputError(f"'{key}' must be a mapping of option: value", path)
    if "sensors" in data and isinstance(data["sensors"], str):
        data["sensors"] = [s.strip() for s in data["sensors"].split(",") if s.strip()]
    cfg = RunConfig(**{k: v for k, v in data.items() if v is not None})
    cfg.validate(path)
    return cfg


def default_config_text() -> str:
    """The full default configuration as commented YAML (for ``--print-config``)."""
    import yaml

    cfg = RunConfig()
    d = cfg.to_dict()
    d["odometry"] = {k: v for k, v in dataclasses.asdict(OdometryConfig()).items() if k not in ("frontend", "frontend_options")}
    try:
        from frontends.klt import KltConfig

        d["klt"] = dataclasses.asdict(KltConfig())
    except ImportError:
        pass
    try:
        from frontends.features import FeatureConfig

        d["features"] = dataclasses.asdict(FeatureConfig())
    except ImportError:
        pass
    try:
        from frontends.direct import DirectConfig

        d["direct"] = dataclasses.asdict(DirectConfig())
    except ImportError:
        pass
    return "# fusion-vo run configuration (defaults)\n" + yaml.safe_dump(d, sort_keys=False, default_flow_style=None)
