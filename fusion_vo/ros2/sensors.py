"""The node's sensors: their calibrations, the streaming fusion they feed and the live camera odometry.

The calibrations come from the folder ``calibration`` of the node's settings, in the recording layout and
read by the recording's own readers (:class:`~fusion_vo.recording.Recording`): a camera from
``cam0/sensor.yaml``, the IMU's mounting and noise from ``imu0/sensor.yaml`` (identity and the
configuration's noise without it, with a warning), the wheels from ``wheel0/sensor.yaml``, the GPS antenna,
default sigma and datum from ``gps0/sensor.yaml`` (:func:`~fusion_vo.recording.gps.gps_settings`). The
sensors used are those of ``sensors``, else those whose folders the calibration folder holds
(:func:`~fusion_vo.pipeline.resolve_sensors`, the rule of ``fusion-vo run``).

Live visual odometry is :class:`~fusion_vo.odometry.VisualOdometry` with the frontend, ground geometry and
camera noise model a run would use; what needs the whole recording is left out: the gyro derotation of
roll and pitch (it takes the IMU's whole record), the lens check and the range finder's smoothed heights
(the range finder's readings go to the fusion as height measurements instead).
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from frontends import make_frontend
from fusion_vo.backends.streaming import StreamingFusion
from fusion_vo.calibration.camera_noise import CameraNoise
from fusion_vo.config.sensor_files import read_camera
from fusion_vo.errors import InputError
from fusion_vo.geometry.camera import CameraModel
from fusion_vo.geometry.ground import GroundGeometry
from fusion_vo.odometry import VisualOdometry
from fusion_vo.pipeline import resolve_sensors
from fusion_vo.recording import Recording
from fusion_vo.recording.gps import gps_settings
from fusion_vo.ros2.settings import NodeSettings
from fusion_vo.sensors.imu import imu_calibration
from fusion_vo.sensors.visual import stated_height_sigma
from fusion_vo.sensors.wheel import wheel_config

log = logging.getLogger(__name__)

#: the fusion's own horizon: none in effect (the node gates stamps on its clock, :mod:`.node`)
NO_HORIZON = 1e9
#: sensors the node has an input for
NODE_SENSORS = ("camera", "wheel", "imu", "odom", "range", "gps")


@dataclass
class SensorSetup:
    """What the node's inputs need: the sensors, their calibrations, and the notes of defaults taken."""

    sensors: list[str]
    camera: CameraModel | None = None
    camera_height: float | None = None
    camera_height_sigma: float | None = None
    camera_noise: object | None = None  # fusion_vo.calibration.camera_noise.CameraNoise
    imu_T_BS: np.ndarray | None = None
    imu_noise: dict = field(default_factory=dict)
    wheel_config: object | None = None  # fusion_vo.measurements.WheelConfig
    gps: dict | None = None  # lever_arm, sigma, datum (gps_settings)
    notes: list[str] = field(default_factory=list)


def sensor_setup(settings: NodeSettings) -> SensorSetup:
    """Resolve the sensors of ``settings`` and read their calibrations (InputError naming the file)."""
    run, folder = settings.run, settings.calibration
    rec = Recording(folder) if folder is not None else None
    if run.sensors is None:
        if rec is None:
            raise InputError("give the sensors to use (parameter 'sensors', e.g. [imu, odom]) or a calibration "
                             "folder whose cam0/, imu0/, wheel0/, odom0/ name them")
        sensors = resolve_sensors(rec, run)
    else:
        sensors = list(run.sensors)
    unknown = [s for s in sensors if s not in NODE_SENSORS]
    if unknown:
        raise InputError(f"sensors: the node has no input for '{unknown[0]}' (it takes {', '.join(NODE_SENSORS)})")
    setup = SensorSetup(sensors)
    fusion = run.fusion
    if "camera" in sensors:
        yaml_path = _need(folder, "cam0", "the camera")
        setup.camera = read_camera(yaml_path)
        setup.camera_height_sigma = stated_height_sigma(rec)
        setup.camera_noise = CameraNoise.stated(rec) if run.odometry_config().camera_noise else None
    if fusion.camera_height is not None:
        setup.camera_height = fusion.camera_height
    elif setup.camera is not None:
        setup.camera_height = float(run.odometry.height or setup.camera.T_BS[2, 3])
    if "imu" in sensors:
        if rec is not None and os.path.lexists(folder / "imu0" / "sensor.yaml"):
            setup.imu_T_BS, setup.imu_noise, _ = imu_calibration(rec)
        else:
            setup.imu_T_BS = np.eye(4)
            setup.notes.append("no imu0/sensor.yaml in the calibration: the IMU is taken as aligned with the body, "
                               "with the configuration's noise")
    if "wheel" in sensors:
        _need(folder, "wheel0", "the wheels")
        setup.wheel_config = wheel_config(rec)
    if "gps" in sensors:
        path = (folder / "gps0" / "sensor.yaml") if folder is not None else Path("gps0") / "sensor.yaml"
        setup.gps, notes = gps_settings(path)
        setup.notes.extend(notes)
    if "range" in sensors and setup.camera_height is None:
        raise InputError("the range sensor needs the camera height: give the camera's calibration or "
                         "fusion.camera_height")
    for note in setup.notes:
        log.warning("%s", note)
    return setup


def _need(folder: Path | None, stream: str, what: str) -> Path:
    path = None if folder is None else folder / stream / "sensor.yaml"
    if path is None or not os.path.lexists(path):
        raise InputError(f"{what} needs its calibration {stream}/sensor.yaml: give the folder holding it as "
                         "'calibration'", path)
    return path


def streaming_fusion(settings: NodeSettings, setup: SensorSetup) -> StreamingFusion:
    """The :class:`StreamingFusion` the node feeds (InputError for a combination it cannot run).

    Every call processes all that is due (``steps_per_call=None``): the node calls it from its intake and
    camera threads, never from a callback, so a call's length holds up no other input, and the state does
    not stay behind when the inputs pause (work spread over later calls would wait for them).
    """
    lever = None if setup.gps is None else setup.gps["lever_arm"]
    return StreamingFusion(settings.backend, settings.run.fusion, setup.sensors,
                           wheel_config=setup.wheel_config, imu_T_BS=setup.imu_T_BS, imu_noise=setup.imu_noise or None,
                           camera_height=setup.camera_height, camera_height_sigma=setup.camera_height_sigma,
                           camera_frame_errors=setup.camera_noise is not None, gps_lever_arm=lever,
                           history=settings.node.history, horizon=NO_HORIZON,
                           steps_per_call=None)


def visual_odometry(settings: NodeSettings, setup: SensorSetup) -> VisualOdometry:
    """Live visual odometry of the camera: frontend, ground geometry and the track (no derotation)."""
    config = settings.run.odometry_config()
    cam = setup.camera
    try:
        geometry = GroundGeometry(cam, height=config.height, min_sigma_xy=config.min_sigma_xy,
                                  min_sigma_yaw=config.min_sigma_yaw)
        frontend = make_frontend(config.frontend, dict(config.frontend_options), point_map=geometry.rectifier)
    except (TypeError, ValueError) as exc:
        raise InputError(f"camera: {exc}", settings.source) from None
    return VisualOdometry(frontend, geometry, None, max_bridge=config.max_bridge)
