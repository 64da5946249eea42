"""The node's settings: one configuration schema for files and ROS parameters.

A node configuration file is a ``fusion-vo run`` configuration (:mod:`fusion_vo.config`: ``frontend``,
``sensors``, ``backend``, ``odometry``, ``klt``, ``fusion`` ...) with one more section, ``ros2``, holding
:class:`NodeConfig`::

    backend: ekf
    sensors: [imu, odom]
    fusion: {reorder_window: 0.1}
    ros2: {calibration: /robot/calib, publish_rate: 30}

ROS parameters (``--ros-args -p NAME:=VALUE`` or a ``--params-file``) override it key by key: a
:class:`NodeConfig` field by its own name (``publish_rate``), a run configuration key by its dotted path
(``backend``, ``fusion.ekf.accel_sigma``, ``odometry.min_sigma_xy``). Both go through the same validation
as ``fusion-vo run`` (:func:`fusion_vo.config.validate_config`, :func:`fusion_vo.config.files.validate`), so a
misspelt name or a bad value is one :class:`~fusion_vo.errors.InputError` naming it. ROS's own parameters
(``use_sim_time``, ``start_type_description_service``) pass through.

The node runs one streaming backend: ``backend`` is ``ekf`` or ``gtsam``; left out it is ``ekf`` (the run
configuration's default ``all`` names several backends and is refused, as is ``none``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import Field, model_validator

from fusion_vo.config.base import Float, Int, NonNegative, Positive, Section
from fusion_vo.config.files import load_yaml, validate
from fusion_vo.config.run import RunConfig, validate_config
from fusion_vo.errors import InputError

#: ROS's own parameters, passed through without validation here
ROS_PARAMETERS = ("use_sim_time", "start_type_description_service")
#: the section of a configuration file that holds :class:`NodeConfig`
SECTION = "ros2"


class NodeConfig(Section):
    """Settings of the ``fusion_vo`` node (section ``ros2`` of its configuration, or ROS parameters)."""

    calibration: str | None = Field(None, description=(
        "Folder holding the sensors' calibrations in the recording layout: ``cam0/sensor.yaml`` (intrinsics, "
        "distortion, resolution, ``T_BS`` mounting, ``height_sigma``, ``camera_noise``), ``imu0/sensor.yaml`` "
        "(``T_BS``, noise densities), ``wheel0/sensor.yaml`` (ticks per revolution, radii, wheel base), "
        "``gps0/sensor.yaml`` (antenna ``T_BS``, ``horizontal_sigma_m``, ``datum``); a recording folder or one "
        "written by ``fusion-vo import-bag`` will do. Relative to the configuration file. Without ``sensors``, the "
        "sensors whose folders it holds are used, as ``fusion-vo run`` does with a recording."))
    publish_rate: Float = Field(50.0, ge=1e-3, le=1e3, description=(
        "Rate [Hz] of ``odometry/filtered``: the pose predicted to the time of publication."))
    diagnostics_period: Float = Field(1.0, ge=1e-2, le=3600.0, description="Seconds between two ``diagnostics`` "
                                                                          "messages.")
    smoothed_lag: NonNegative = Field(0.0, description=(
        "Lag [s] of ``odometry/smoothed``, the iSAM2 smoother's pose of the node that far behind the newest "
        "measurement (backend ``gtsam``); 0 publishes no smoothed pose."))
    smoothed_rate: Float = Field(5.0, ge=1e-3, le=1e3, description="Rate [Hz] of ``odometry/smoothed``.")
    odom_frame: str = Field("odom", description="``header.frame_id`` of the published poses.")
    base_frame: str = Field("base_link", description=(
        "``child_frame_id`` of the published poses, and the frame an input odometry's twist must be in."))
    imu_frame: str = Field("", description=(
        "The frame the IMU's messages must name; empty takes the frame of the first message of the topic, and a "
        "message in another frame is then unusable (counted, reported once)."))
    camera_frame: str = Field("", description="The frame the camera's messages must name (as ``imu_frame``).")
    gps_frame: str = Field("", description="The frame the GPS receiver's messages must name (as ``imu_frame``).")
    range_frame: str = Field("", description="The frame the range finder's messages must name (as ``imu_frame``).")
    queue_depth: Int = Field(1000, ge=1, le=100_000, description=(
        "History depth of each input subscription but the camera's (1000 messages: a 5 s burst of a 200 Hz IMU "
        "waits there for the executor)."))
    image_queue: Int = Field(2, ge=1, le=10_000, description=(
        "Camera frames waiting for the camera thread; when it is full the oldest waiting frame is dropped and "
        "counted. The camera's subscription keeps ``max(image_queue, 10)`` messages."))
    trajectory_file: str = Field("", description=(
        "When given, on shutdown the fusion's online track (each node's pose as filtered when it was processed: "
        "``StreamingFusion.finish()``) is written there as a TUM file (relative to the working folder), for "
        "``fusion-vo evaluate`` or a comparison with a batch run (empty: none)."))
    history: NonNegative = Field(2.0, description=(
        "Seconds of samples kept to re-apply late measurements (``StreamingFusion.history``)."))
    horizon: Positive = Field(1.0, description=(
        "How far [s] ahead of the node's clock a message may be stamped before it is dropped (``future``), and the "
        "largest prediction of a published pose beyond the newest measurement."))

    @model_validator(mode="after")
    def _frames(self) -> NodeConfig:
        if not self.odom_frame or not self.base_frame:
            raise ValueError("odom_frame and base_frame must be frame names, not empty")
        return self


@dataclass
class NodeSettings:
    """A validated node configuration: the run configuration, the node's own settings and the backend."""

    run: RunConfig
    node: NodeConfig
    backend: str
    calibration: Path | None
    source: Path | None = None  # the configuration file, if any


def node_fields() -> list[str]:
    return list(NodeConfig.model_fields)


def load_settings(path: str | Path | None, parameters: dict[str, Any] | None = None) -> NodeSettings:
    """Read the configuration file ``path`` (None: defaults) and apply the ROS ``parameters`` over it.

    Raises
    ------
    InputError
        For an unknown parameter or key, a value the schema rejects, or a backend the node cannot run;
        the message names the file or the parameter.
    """
    source = None if path is None else Path(path)
    data = {} if source is None else load_yaml(source)
    if not isinstance(data, dict):
        raise InputError("expected a mapping of key: value", source)
    data = dict(data)
    node_data = data.pop(SECTION, None) or {}
    if not isinstance(node_data, dict):
        raise InputError(f"{SECTION}: expected a mapping of key: value, got {node_data!r}", source)
    node_data = dict(node_data)
    for name, value in (parameters or {}).items():
        _apply_parameter(data, node_data, name, value)
    run = validate_config(data, source)
    node = validate(NodeConfig, node_data, source, (SECTION,))
    backend = data.get("backend") or "ekf"
    if backend not in ("ekf", "gtsam"):
        raise InputError(f"backend: the node runs one streaming backend, 'ekf' or 'gtsam', not '{backend}'", source)
    if node.smoothed_lag > 0 and backend != "gtsam":
        raise InputError("smoothed_lag: odometry/smoothed comes from the iSAM2 smoother: it needs backend 'gtsam' "
                         "(the streaming EKF does not smooth)", source)
    calibration = None
    if node.calibration:
        calibration = Path(node.calibration).expanduser()
        given_as_parameter = {"calibration", f"{SECTION}.calibration"} & set(parameters or {})
        if not calibration.is_absolute() and source is not None and not given_as_parameter:
            calibration = source.parent / calibration  # a file's paths are relative to the file
        if not calibration.is_dir():
            raise InputError("calibration: not a folder (give the folder holding cam0/, imu0/, wheel0/ ... "
                             "with their sensor.yaml)", calibration)
    return NodeSettings(run, node, backend, calibration, source)


def _apply_parameter(data: dict, node_data: dict, name: str, value) -> None:
    """Put the ROS parameter ``name`` into the run configuration ``data`` or the node's ``node_data``."""
    if name in ROS_PARAMETERS:
        return
    if name in node_fields():
        node_data[name] = value
        return
    parts = name.split(".")
    if parts[0] == SECTION and len(parts) == 2 and parts[1] in node_fields():
        node_data[parts[1]] = value
        return
    if parts[0] not in RunConfig.model_fields:
        raise InputError(f"unknown parameter '{name}' (the node's: {', '.join(node_fields())}; the run "
                         f"configuration's: {', '.join(RunConfig.model_fields)} and their dotted keys, "
                         "e.g. fusion.ekf.accel_sigma)")
    target = data
    for part in parts[:-1]:
        nested = target.get(part)
        if not isinstance(nested, dict):
            nested = {}
            target[part] = nested
        target = nested
    target[parts[-1]] = list(value) if isinstance(value, tuple) else value
