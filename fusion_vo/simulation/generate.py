"""Generate a complete recording: a robot drives a profile over a photographed floor.

Steps (each a small module of this package):

1. motion      a differential-drive command profile, integrated at 1 kHz (:mod:`.robot`)
2. frames      every camera frame ray-cast onto the floor (:mod:`.render`), with motion blur over the
               exposure, height vibration and tilt; then exposure, vignetting, a specular highlight
               and sensor noise (:mod:`.photometry`)
3. sensors     wheel encoders with calibration errors and slip, IMU with biases and noise, an optional
               range finder and robot odometry (:mod:`.sensors`)
4. files       the folder layout of ``datasets/README.md``, written under a temporary name and renamed
               when complete, plus ``simulation.yaml`` with the options and the true calibration

The same options and seed always give the same files.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

import cv2
import numpy as np
import yaml

from fusion_vo.schema import FRACTION, Range
from fusion_vo.geometry.camera import (DISTORTION_MODELS, MAX_IMAGE_SIDE, MAX_LEVER_ARM_M, CameraModel,
                                       focal_length_problem)
from fusion_vo.measurements import (MAX_ACCELERATION, MAX_ANGULAR_RATE, MAX_CAMERA_HEIGHT_M, MAX_POSITION_M,
                                    MAX_SPEED)
from fusion_vo.recording.gps import HEADER, enu_to_geodetic, format_rows
from fusion_vo.recording.writer import RecordingWriter, check_target
from fusion_vo.simulation.floor import TEXTURES, Floor, Rectangle
from fusion_vo.simulation.mount import body_pose, camera_mount
from fusion_vo.simulation.photometry import Photometric, Photometry
from fusion_vo.simulation.realistic import RealisticCamera, RealisticRenderer
from fusion_vo.simulation.render import Renderer
from fusion_vo.simulation.robot import MAX_DURATION_S, PROFILES, Limits, Motion, make_motion
from fusion_vo.simulation.sensors import (GpsSimulation, ImuNoise, WheelTruth, gps_fixes, imu_samples,
                                         odometry_twist, sample_times, wheel_ticks)

log = logging.getLogger(__name__)

#: default speed limits per profile (max_speed [m/s], max_turn_rate [rad/s])
PROFILE_SPEEDS = {"random": (0.3, 0.9), "square": (0.2, 1.0), "circle": (0.15, 0.6)}

#: ranges that several options share (:attr:`SimulationOptions.RANGES`)
_SHAPE = Range(0, 1e3, open_low=True)  # side, radius, length [m]
_POSITIVE = Range(0, open_low=True)
_RATE = Range(0, 1e4, open_low=True)  # [Hz]
_LEVER_ARM = Range(-MAX_LEVER_ARM_M, MAX_LEVER_ARM_M)  # [m]
_ERROR = Range(-1, 1, open_low=True, open_high=True)  # a relative calibration error
_NOISE = Range(0, 1e3)  # a noise density or random walk


@dataclass
class SimulationOptions:
    """Everything a generated recording depends on (with the seed).

    Attributes
    ----------
    duration : float or None
        Length of the drive [s] (random, standstill; None: the profile's default).
    max_speed : float or None
        Top speed [m/s] (None: the profile's default).
    max_turn_rate : float or None
        Top turn rate [rad/s] (None: the profile's default).
    side : float or None
        Side of the square (square, umbmark) [m].
    radius : float or None
        Radius of the circle [m].
    length : float or None
        Length of the straight drive [m].
    angle : float or None
        Angle of a turn in place [rad].
    texture : str
        Floor photograph: gravel, grass or brick (scikit-image's CC0 images).
    texel_size : float
        Size on the floor of one pixel of the texture [m].
    featureless : list
        Rectangles of flat grey floor [m], each as x_min, y_min, x_max, y_max.
    featureless_time : list or None
        A time span [s] (t0, t1) in which the floor the camera sees is flat grey.
    width, height : int
        Image size [px].
    fu, fv : float
        Focal lengths [px].
    cu, cv : float
        Principal point [px].
    distortion_model : str
        radial-tangential, equidistant or none.
    distortion : list
        Distortion coefficients of that model.
    camera_rate : float
        Frame rate [Hz].
    camera_height : float
        Height of the camera above the floor [m].
    lever_arm : float
        Camera ahead of the wheel axle [m].
    lateral_offset : float
        Camera to the left of the centre line [m].
    tilt_x_deg, tilt_y_deg : float
        Camera tilt about the body's x and y axes [deg].
    height_error : float
        Fraction: the sensor.yaml height is the true one times 1 + height_error (``height_sigma`` states
        that error, at least 0.1 mm).
    height_vibration : float
        Amplitude of the camera's vertical vibration [m].
    vibration_frequency : float
        Frequency of that vibration [Hz].
    exposure_time : float
        Exposure [s] (motion blur; 0: none).
    blur_samples : int
        Sub-frames rendered for motion blur.
    supersample : int
        Rendering supersampling factor per axis.
    dropped_frames : float
        Fraction of frames missing from the recording, in [0, 1).
    png_compression : int
        PNG compression level, 0-9.
    gain : float
        Image gain.
    exposure_drift : float
        Amplitude of the slow exposure change (fraction).
    exposure_period : float
        Period of that change [s].
    vignetting : float
        Brightness lost at the image corners (fraction).
    highlight_radius : float
        Radius of a specular highlight [px] (0: none).
    highlight_center : list
        Centre of the highlight (fractions of width and height).
    noise : float
        Image noise [grey levels].
    shot_noise : float
        Signal-dependent noise factor.
    wheel_rate : float
        Encoder sample rate [Hz].
    ticks_per_revolution : int
        Encoder ticks per wheel revolution.
    wheel_radius : float
        Nominal wheel radius [m].
    wheel_base : float
        Nominal wheel base [m].
    radius_error_left, radius_error_right : float
        Fractions: true radius = nominal · (1 + error); ``radius_sigma`` of wheel0/sensor.yaml states the
        larger one.
    base_error : float
        Fraction: true wheel base = nominal · (1 + error).
    slip : float
        Wheel slip noise [sqrt(m)].
    wheel_start_count : int
        First encoder count (near 2**31 to make the counters wrap).
    imu_rate : float
        IMU sample rate [Hz].
    gyro_bias : list
        Gyro bias [rad/s] about x, y, z.
    accel_bias : list
        Accelerometer bias [m/s²] along x, y, z.
    gyro_noise_density : float
        Gyro white noise [rad/s/√Hz].
    gyro_random_walk : float
        Gyro bias random walk [rad/s²/√Hz].
    accel_noise_density : float
        Accelerometer white noise [m/s²/√Hz].
    accel_random_walk : float
        Accelerometer bias random walk [m/s³/√Hz].
    realistic : dict or None
        Options of :class:`fusion_vo.simulation.realistic.RealisticCamera`; when given, frames are rendered
        through that module's own lens, optics and sensor instead of the estimator's camera model (the
        photometry options and fu .. distortion are then unused).
    gps : bool
        Write gps0.
    gps_rate : float
        GPS fix rate [Hz].
    gps_noise : float
        GPS noise [m] per horizontal axis.
    gps_lever_arm : list
        Antenna position [m] in the body frame (x, y, z).
    gps_outages : list
        Time spans [s] without fixes, each as t0, t1.
    gps_jumps : list
        Time spans [s] whose fixes are offset east and north by de, dn metres (multipath), each as
        t0, t1, de, dn.
    gps_heading_deg : float
        Heading of the world x axis in ENU [deg], counter-clockwise from east.
    gps_origin : list
        ENU position of the world origin [m].
    gps_datum : list
        Latitude [deg], longitude [deg] and altitude [m] of the ENU datum.
    range_finder : bool
        Write range0 (a downward range finder).
    range_noise : float
        Range finder noise [m].
    odometry : bool
        Write odom0 (an odometry twist).
    gt_rate : float
        Ground-truth rate [Hz].
    jitter : float
        Timestamp jitter of wheel and IMU samples [s].
    start_time_ns : int
        First timestamp [ns].
    """

    # motion
    duration: float | None = None
    max_speed: float | None = None
    max_turn_rate: float | None = None
    side: float | None = None
    radius: float | None = None
    length: float | None = None
    angle: float | None = None
    # floor
    texture: str = "gravel"
    texel_size: float = 0.00025
    featureless: list = field(default_factory=list)
    featureless_time: list | None = None
    # camera
    width: int = 640
    height: int = 360
    fu: float = 420.0
    fv: float = 420.0
    cu: float = 319.5
    cv: float = 179.5
    distortion_model: str = "radial-tangential"
    distortion: list = field(default_factory=lambda: [-0.03, 0.01, 0.0005, -0.0003])
    camera_rate: float = 20.0
    camera_height: float = 0.10
    lever_arm: float = 0.25
    lateral_offset: float = 0.0
    tilt_x_deg: float = 0.0
    tilt_y_deg: float = 0.0
    height_error: float = 0.0
    height_vibration: float = 0.0
    vibration_frequency: float = 3.0
    exposure_time: float = 0.0
    blur_samples: int = 5
    supersample: int = 2
    dropped_frames: float = 0.0
    png_compression: int = 0
    # photometry
    gain: float = 1.0
    exposure_drift: float = 0.0
    exposure_period: float = 10.0
    vignetting: float = 0.0
    highlight_radius: float = 0.0
    highlight_center: list = field(default_factory=lambda: [0.55, 0.45])
    noise: float = 1.0
    shot_noise: float = 0.0
    # wheels
    wheel_rate: float = 50.0
    ticks_per_revolution: int = 4096
    wheel_radius: float = 0.05
    wheel_base: float = 0.30
    radius_error_left: float = 0.006
    radius_error_right: float = -0.004
    base_error: float = 0.015
    slip: float = 0.0005
    wheel_start_count: int = 0
    # imu
    imu_rate: float = 200.0
    gyro_bias: list = field(default_factory=lambda: [0.002, -0.001, 0.005])
    accel_bias: list = field(default_factory=lambda: [0.02, -0.01, 0.03])
    gyro_noise_density: float = 1.7e-4
    gyro_random_walk: float = 2.0e-5
    accel_noise_density: float = 2.0e-3
    accel_random_walk: float = 3.0e-3
    # independent camera
    realistic: dict | None = None
    # gps
    gps: bool = False
    gps_rate: float = 5.0
    gps_noise: float = 0.05
    gps_lever_arm: list = field(default_factory=lambda: [-0.10, 0.0, 0.40])
    gps_outages: list = field(default_factory=list)
    gps_jumps: list = field(default_factory=list)
    gps_heading_deg: float = 30.0
    gps_origin: list = field(default_factory=lambda: [0.0, 0.0])
    gps_datum: list = field(default_factory=lambda: [47.3977, 8.5456, 488.0])
    # other
    range_finder: bool = False
    range_noise: float = 0.0005
    odometry: bool = False
    gt_rate: float = 200.0
    jitter: float = 0.0
    start_time_ns: int = 1_600_000_000_000_000_000

    #: the range of every number option (of each number of a list option); beyond it an option is a typo, or
    #: sets work without end (``duration``, the rates, the image size, ``supersample``, ``blur_samples``)
    RANGES: ClassVar[dict[str, Range]] = {
        "duration": Range(0, MAX_DURATION_S, open_low=True), "max_speed": Range(0, MAX_SPEED, open_low=True),
        "max_turn_rate": Range(0, MAX_ANGULAR_RATE, open_low=True), "side": _SHAPE, "radius": _SHAPE,
        "length": _SHAPE, "angle": Range(-100, 100),
        "texel_size": Range(0, 1, open_low=True), "featureless": Range(-1e4, 1e4),
        "featureless_time": Range(0, MAX_DURATION_S),
        "width": Range(8, 4096), "height": Range(8, 4096), "fu": _POSITIVE, "fv": _POSITIVE,
        "cu": Range(-MAX_IMAGE_SIDE, MAX_IMAGE_SIDE), "cv": Range(-MAX_IMAGE_SIDE, MAX_IMAGE_SIDE),
        "distortion": Range(-1e3, 1e3), "camera_rate": _RATE, "camera_height": Range(0, MAX_CAMERA_HEIGHT_M, open_low=True),
        "lever_arm": _LEVER_ARM, "lateral_offset": _LEVER_ARM,
        "tilt_x_deg": Range(-90, 90, open_low=True, open_high=True),
        "tilt_y_deg": Range(-90, 90, open_low=True, open_high=True),
        "height_error": Range(-1, 1, open_low=True, open_high=True), "height_vibration": Range(0, 10),
        "vibration_frequency": Range(0, 1000), "exposure_time": Range(0, 1), "blur_samples": Range(1, 100),
        "supersample": Range(1, 16), "dropped_frames": Range(0, 1, open_high=True), "png_compression": Range(0, 9),
        "gain": Range(0, 100, open_low=True), "exposure_drift": FRACTION, "exposure_period": Range(0, 1e6, open_low=True),
        "vignetting": FRACTION, "highlight_radius": Range(0, MAX_IMAGE_SIDE), "highlight_center": Range(-10, 10),
        "noise": Range(0, 65535), "shot_noise": Range(0, 100),
        "wheel_rate": _RATE, "ticks_per_revolution": Range(1, 2**32), "wheel_radius": Range(1e-6, 1e3),
        "wheel_base": Range(1e-6, 1e3), "radius_error_left": _ERROR, "radius_error_right": _ERROR, "base_error": _ERROR,
        "slip": Range(0, 1), "wheel_start_count": Range(-(2**31), 2**32 - 1),
        "imu_rate": _RATE, "gyro_bias": Range(-MAX_ANGULAR_RATE, MAX_ANGULAR_RATE),
        "accel_bias": Range(-MAX_ACCELERATION, MAX_ACCELERATION), "gyro_noise_density": _NOISE,
        "gyro_random_walk": _NOISE, "accel_noise_density": _NOISE, "accel_random_walk": _NOISE,
        "gps_rate": Range(0, 100, open_low=True), "gps_noise": Range(0, 1e6, open_low=True),
        "gps_lever_arm": _LEVER_ARM, "gps_outages": Range(0, MAX_DURATION_S), "gps_jumps": Range(-1e6, 1e6),
        "gps_heading_deg": Range(-360, 360), "gps_origin": Range(-MAX_POSITION_M, MAX_POSITION_M),
        "range_noise": Range(0, 1), "gt_rate": _RATE, "jitter": Range(0, 1),
    }

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            _check_type(f.name, str(f.type), value)
            if str(f.type) == "int":  # 640.0 from a YAML file is fine, but stored as an int
                setattr(self, f.name, int(value))
        for name, bound in self.RANGES.items():
            value = getattr(self, name)
            for item in _numbers_of(value):
                problem = bound.error(f"option '{name}'", item)
                if problem:
                    raise ValueError(problem)
        problem = focal_length_problem(self.fu, self.fv, (self.width, self.height))
        if problem:
            raise ValueError(f"options 'fu', 'fv': {problem}")
        if self.texture not in TEXTURES:
            raise ValueError(f"option 'texture' must be one of {', '.join(TEXTURES)}, not {self.texture!r}")
        if self.distortion_model not in DISTORTION_MODELS:
            raise ValueError(f"option 'distortion_model' must be one of {', '.join(DISTORTION_MODELS)}")
        n_coeffs = {"radial-tangential": (4, 5), "equidistant": (4,), "none": (0, 4)}[self.distortion_model]
        if len(self.distortion) not in n_coeffs:
            raise ValueError(f"option 'distortion': {self.distortion_model} takes "
                             f"{' or '.join(map(str, n_coeffs))} coefficients")
        for name, n in (("gyro_bias", 3), ("accel_bias", 3), ("highlight_center", 2), ("featureless_time", 2),
                        ("gps_lever_arm", 3), ("gps_origin", 2), ("gps_datum", 3)):
            value = getattr(self, name)
            if value is not None and len(value) != n:
                raise ValueError(f"option '{name}' needs {n} numbers")
        if self.realistic is not None:
            if not isinstance(self.realistic, dict):
                raise ValueError("option 'realistic' must be a mapping of option: value")
            RealisticCamera.from_dict(self.realistic)
        for name, n, what in (("gps_outages", 2, "[t0, t1]"), ("gps_jumps", 4, "[t0, t1, de, dn]")):
            for item in getattr(self, name):
                if not isinstance(item, (list, tuple)) or len(item) != n or item[1] < item[0]:
                    raise ValueError(f"option '{name}' is a list of {what} with t0 <= t1")
        if abs(self.gps_datum[0]) > 90 or abs(self.gps_datum[1]) > 180:
            raise ValueError("option 'gps_datum' is [latitude, longitude, altitude] in degrees and metres")
        for rect in self.featureless:
            if not isinstance(rect, (list, tuple)) or len(rect) != 4:
                raise ValueError("option 'featureless' is a list of [x_min, y_min, x_max, y_max] rectangles")
        if self.featureless_time is not None and self.featureless_time[1] < self.featureless_time[0]:
            raise ValueError("option 'featureless_time' is [t0, t1] with t0 <= t1")
        if not 0 <= self.start_time_ns < 2**63:  # the recording's timestamps are nanoseconds in 0 .. 2^63
            raise ValueError(f"option 'start_time_ns' must lie in 0 .. 2^63 - 1, not {self.start_time_ns}")

    @classmethod
    def from_dict(cls, d: dict) -> "SimulationOptions":
        """Options from a mapping (a YAML file) through the configuration schema
        (:func:`fusion_vo.schema.build`); unknown keys and bad values raise ``ValueError``."""
        from fusion_vo import schema
        from fusion_vo.errors import InputError

        try:
            return schema.build(cls, d)
        except InputError as exc:
            raise ValueError(exc.message) from None


def _numbers_of(value) -> list:
    """The numbers of an option: itself, the items of a list, the items of a list of lists (none for None)."""
    if value is None:
        return []
    if isinstance(value, (list, tuple)):
        return [v for item in value for v in (item if isinstance(item, (list, tuple)) else [item])]
    return [value]


def _check_number(name: str, value, integer: bool) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"option '{name}' must be a number, not {value!r}")
    if not math.isfinite(value):
        raise ValueError(f"option '{name}' must be finite, not {value}")
    if integer and value != int(value):
        raise ValueError(f"option '{name}' must be a whole number, not {value}")


def _check_type(name: str, annotation: str, value) -> None:
    """Check one option against its annotation (``float``, ``int``, ``bool``, ``str``, ``list``, ``| None``)."""
    if value is None:
        if "None" not in annotation:
            raise ValueError(f"option '{name}' needs a value")
        return
    kind = annotation.split("|")[0].strip()
    if kind == "dict":
        return
    if kind in ("float", "int"):
        _check_number(name, value, kind == "int")
    elif kind == "bool":
        if not isinstance(value, bool):
            raise ValueError(f"option '{name}' must be true or false, not {value!r}")
    elif kind == "str":
        if not isinstance(value, str):
            raise ValueError(f"option '{name}' must be a name, not {value!r}")
    elif kind == "list":
        if not isinstance(value, (list, tuple)):
            raise ValueError(f"option '{name}' must be a list, not {value!r}")
        for item in value:
            for v in item if isinstance(item, (list, tuple)) else [item]:
                _check_number(name, v, False)


def _motion_for(profile: str, o: SimulationOptions, rng: np.random.Generator) -> Motion:
    speed, turn = PROFILE_SPEEDS.get(profile, (0.15, 0.6))
    limits = Limits(max_speed=o.max_speed or speed, max_turn_rate=o.max_turn_rate or turn)
    kwargs = {k: getattr(o, k) for k in ("duration", "side", "radius", "length", "angle") if getattr(o, k) is not None}
    return make_motion(profile, limits, rng, **kwargs)


def _featureless_rectangles(o: SimulationOptions, motion: Motion, T_BS: np.ndarray) -> list[Rectangle]:
    rects = [Rectangle(*map(float, r)) for r in o.featureless]
    if o.featureless_time:
        t0, t1 = o.featureless_time
        m = (motion.t >= t0) & (motion.t <= t1)
        if np.any(m):
            p = motion.xyyaw[m]
            cam = p[:, :2] + np.column_stack([np.cos(p[:, 2]) * T_BS[0, 3] - np.sin(p[:, 2]) * T_BS[1, 3],
                                              np.sin(p[:, 2]) * T_BS[0, 3] + np.cos(p[:, 2]) * T_BS[1, 3]])
            margin = 0.12
            lo, hi = cam.min(axis=0) - margin, cam.max(axis=0) + margin
            rects.append(Rectangle(float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])))
    return rects


def simulate(out_dir: str | Path, profile: str = "square", seed: int = 0,
             options: SimulationOptions | None = None, force: bool = False, **overrides) -> Path:
    """Generate a recording in ``out_dir``; returns its path.

    The folder is written by :class:`~fusion_vo.recording.writer.RecordingWriter`: it appears only when
    complete, and an existing ``out_dir`` is replaced only if it is empty or a recording fusion-vo wrote
    (``force`` replaces any other folder, but never the current folder or one above it).

    Parameters
    ----------
    out_dir : folder to write.
    profile : one of :data:`fusion_vo.simulation.robot.PROFILES`.
    seed : seed of every random choice (motion, noise, dropped frames).
    options : SimulationOptions, optional
    force : replace a non-empty folder that is not a recording fusion-vo wrote.
    **overrides : option fields, applied on top of ``options``.

    Raises
    ------
    InputError
        If ``out_dir`` may not be replaced (see above) or another command is writing it.
    """
    if profile not in PROFILES:
        raise ValueError(f"unknown profile '{profile}' (choose one of {', '.join(PROFILES)})")
    o = dataclasses.replace(options or SimulationOptions(), **overrides) if overrides else (options or SimulationOptions())
    rng = np.random.default_rng(seed)
    out_dir = Path(out_dir)
    check_target(out_dir, force)
    with RecordingWriter(out_dir, force=force, source=f"simulate --profile {profile} --seed {seed}") as writer:
        info = _generate(writer, profile, seed, o, rng)
        writer.commit()
    log.info("generated %s: %d frames, %.1f s, %.2f m", out_dir, info["frames"], info["duration_s"], info["path_length_m"])
    return out_dir


def _generate(writer: RecordingWriter, profile: str, seed: int, o: SimulationOptions, rng: np.random.Generator) -> dict:
    motion = _motion_for(profile, o, rng)
    t_end = motion.t[-1]
    if len(motion.t) < 2 or t_end - o.exposure_time < 1.0 / o.camera_rate:  # a recording is at least a frame pair
        exposure = f" exposed {o.exposure_time:g} s each" if o.exposure_time > 0.5 / o.camera_rate else ""
        raise ValueError(f"the '{profile}' drive lasts {t_end:.3g} s: too short for two camera frames at "
                         f"{o.camera_rate:g} Hz{exposure} (make it longer: duration, length, side, radius or angle)")
    if t_end > MAX_DURATION_S:
        raise ValueError(f"the '{profile}' drive lasts {t_end:.3g} s, longer than the {MAX_DURATION_S:g} s a generated "
                         "recording may last (make it shorter: duration, length, side, radius or angle)")
    if o.start_time_ns + math.ceil(t_end * 1e9) + 10**9 >= 2**63:  # (a second's margin for the sensors' stamps)
        raise ValueError(f"option 'start_time_ns': the drive's {t_end:.3g} s would run past 2^63 ns, the last "
                         "timestamp a recording can hold")
    T_BS = camera_mount(o.lever_arm, o.camera_height, o.tilt_x_deg, o.tilt_y_deg, o.lateral_offset)
    ns = lambda t: np.int64(o.start_time_ns) + np.rint(np.asarray(t) * 1e9).astype(np.int64)  # noqa: E731

    # ---- camera frames
    cam = CameraModel(o.width, o.height, o.fu, o.fv, o.cu, o.cv, o.distortion_model, np.array(o.distortion, float),
                      T_BS, o.camera_rate)
    real_cam = RealisticCamera.from_dict(o.realistic) if o.realistic is not None else None
    if real_cam is not None:
        real = RealisticRenderer(real_cam, o.width, o.height, o.exposure_time, o.blur_samples)
    else:
        floor = Floor.photographed(o.texture, o.texel_size, featureless=_featureless_rectangles(o, motion, T_BS))
        renderer = Renderer(cam, floor, o.supersample)
    photo = Photometric(Photometry(o.gain, o.exposure_drift, o.exposure_period, o.vignetting, o.highlight_radius,
                                   tuple(o.highlight_center), o.noise, o.shot_noise), o.width, o.height)
    half = o.exposure_time / 2
    n_frames = int(math.floor((t_end - half) * o.camera_rate)) + 1
    frame_t = np.arange(n_frames) / o.camera_rate + half
    frame_t = frame_t[frame_t + half <= t_end]
    keep = rng.random(len(frame_t)) >= o.dropped_frames
    keep[0] = True
    stamps, names = [], []
    png = [cv2.IMWRITE_PNG_COMPRESSION, int(o.png_compression)]
    if o.png_compression == 0:  # stored, not compressed: row filters would only cost time
        png += [cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_NONE]

    def camera_pose(ts: float) -> np.ndarray:
        """True ``T_WS`` of the independent camera at ``ts`` (height changes and rocking included)."""
        x, y, yaw = motion.pose_at(np.array([ts]))[0]
        T = T_BS.copy()
        T[2, 3] = o.camera_height + o.height_vibration * math.sin(2 * math.pi * o.vibration_frequency * ts)
        rock = np.eye(4)
        rock[:3, :3] = real_cam.rocking(ts)[0]
        return body_pose(x, y, yaw) @ T @ rock

    for i, t in enumerate(frame_t):
        if not keep[i]:
            continue
        if real_cam is not None:
            img = real.frame(camera_pose, float(t), rng)
        else:
            times = [t] if o.exposure_time <= 0 else list(np.linspace(t - half, t + half, max(o.blur_samples, 2)))
            poses = []
            for ts in times:
                x, y, yaw = motion.pose_at(np.array([ts]))[0]
                T = T_BS.copy()
                T[2, 3] = o.camera_height + o.height_vibration * math.sin(2 * math.pi * o.vibration_frequency * ts)
                poses.append(body_pose(x, y, yaw) @ T)
            radiance = renderer.radiance_blurred(poses)
            img = photo.apply(radiance, float(t), rng)
        stamps.append(ns(t))
        names.append(writer.image(f"{ns(t)}.png", img, png))
        if (i + 1) % 200 == 0:
            log.info("rendered %d / %d frames", i + 1, len(frame_t))
    writer.frame_list(np.array(stamps, dtype=np.int64), names)
    T_written = T_BS.copy()
    T_written[2, 3] = o.camera_height * (1.0 + o.height_error)
    # the calibration's stated uncertainty: the size of the error written into it (at least 0.1 mm)
    cam_yaml = dataclasses.replace(cam, T_BS=T_written).to_dict()
    cam_yaml["height_sigma"] = float(max(abs(o.height_error) * o.camera_height, 1e-4))
    if real_cam is not None:
        for key in ("intrinsics", "distortion_model", "distortion_coefficients"):
            cam_yaml.pop(key)
        cam_yaml.update(real.sensor_calibration())
    writer.yaml("cam0/sensor.yaml", cam_yaml)

    # ---- wheels
    truth = WheelTruth(o.wheel_radius * (1 + o.radius_error_left), o.wheel_radius * (1 + o.radius_error_right),
                       o.wheel_base * (1 + o.base_error), o.wheel_radius, o.wheel_base, o.ticks_per_revolution)
    wt = sample_times(0.0, t_end, o.wheel_rate, o.jitter, rng)
    left, right = wheel_ticks(motion, truth, wt, o.slip, o.wheel_start_count, rng)
    writer.csv("wheel0/data.csv", "#timestamp [ns],left_ticks,right_ticks", ns(wt),
               np.column_stack([left, right]), "%d")
    writer.yaml("wheel0/sensor.yaml", {"ticks_per_revolution": int(o.ticks_per_revolution),
                                             "wheel_radius_left": o.wheel_radius, "wheel_radius_right": o.wheel_radius,
                                             "wheel_base": o.wheel_base,
                                             "radius_sigma": float(max(abs(o.radius_error_left), abs(o.radius_error_right))
                                                                   * o.wheel_radius) or 1e-4})
    if o.odometry:
        tw = odometry_twist(wt, left, right, truth)
        writer.csv("odom0/data.csv", "#timestamp [ns],v_x [m s^-1],v_y [m s^-1],w_z [rad s^-1]",
                   ns(wt[1:]), tw[1:], "%.9g")

    # ---- IMU
    it = sample_times(0.0, t_end, o.imu_rate, o.jitter, rng)
    noise = ImuNoise(o.gyro_noise_density, o.gyro_random_walk, o.accel_noise_density, o.accel_random_walk,
                     tuple(o.gyro_bias), tuple(o.accel_bias))
    gyro, accel, bias_g = imu_samples(motion, it, noise, rng)
    if real_cam is not None and real_cam.rocking_deg > 0:  # the camera's roll and pitch, seen by the gyro
        gyro = gyro + np.array([T_BS[:3, :3] @ real_cam.rocking(float(ti))[1] for ti in it])
    writer.csv("imu0/data.csv",
               "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
               "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]", ns(it), np.column_stack([gyro, accel]), "%.9g")
    writer.yaml("imu0/sensor.yaml", {
        "sensor_type": "imu", "rate_hz": float(o.imu_rate),
        "T_BS": {"cols": 4, "rows": 4, "data": [float(v) for v in np.eye(4).ravel()]},
        "gyroscope_noise_density": o.gyro_noise_density, "gyroscope_random_walk": o.gyro_random_walk,
        "accelerometer_noise_density": o.accel_noise_density, "accelerometer_random_walk": o.accel_random_walk})

    # ---- range finder
    if o.range_finder:
        rt = sample_times(0.0, t_end, o.camera_rate * 2, 0.0, rng)
        h = o.camera_height + o.height_vibration * np.sin(2 * math.pi * o.vibration_frequency * rt)
        h = h + o.range_noise * rng.standard_normal(len(rt))
        writer.csv("range0/data.csv", "#timestamp [ns],distance [m]", ns(rt), h[:, None], "%.6f")

    # ---- ground truth
    gt_t = sample_times(0.0, t_end, o.gt_rate, 0.0, rng)
    p = motion.pose_at(gt_t)
    half_yaw = p[:, 2] / 2
    gt = np.column_stack([p[:, 0], p[:, 1], np.zeros(len(p)), np.cos(half_yaw), np.zeros(len(p)), np.zeros(len(p)),
                          np.sin(half_yaw)])
    writer.csv("state_groundtruth_estimate0/data.csv",
               "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []",
               ns(gt_t), gt, "%.9f")

    # ---- GPS (last, so that recordings without it keep their random streams)
    gps_truth = {}
    if o.gps:
        gps_truth = _write_gps(writer, motion, o, t_end, ns, rng)

    info = {"frames": int(keep.sum()), "duration_s": float(t_end), "path_length_m": motion.path_length}
    writer.yaml("simulation.yaml", {
        "profile": profile, "seed": int(seed), "options": dataclasses.asdict(o), "summary": info,
        "truth": {"camera_height": o.camera_height, "lever_arm": o.lever_arm, "lateral_offset": o.lateral_offset,
                  "tilt_x_deg": o.tilt_x_deg, "tilt_y_deg": o.tilt_y_deg,
                  "T_BS": [float(v) for v in T_BS.ravel()],
                  "wheel_radius_left": truth.radius_left, "wheel_radius_right": truth.radius_right,
                  "wheel_base": truth.wheel_base, "gyro_bias_start": [float(v) for v in bias_g[0]],
                  "dropped_frames": int((~keep).sum()), **gps_truth}})
    return info


def _write_gps(writer: RecordingWriter, motion: Motion, o: SimulationOptions, t_end: float, ns, rng) -> dict:
    """``gps0/data.csv`` and ``sensor.yaml`` of simulated fixes; returns the truth for simulation.yaml."""
    sim = GpsSimulation(o.gps_rate, o.gps_noise, tuple(o.gps_lever_arm), o.gps_outages, o.gps_jumps,
                        math.radians(o.gps_heading_deg), tuple(o.gps_origin))
    t, enu, jumped = gps_fixes(motion, sim, t_end, rng)
    n = len(t)
    geo = enu_to_geodetic(enu, o.gps_datum)
    var = o.gps_noise ** 2
    rows = format_rows(ns(t), geo, enu, np.zeros(n), np.full(n, 2), np.tile([var, 0.0, var], (n, 1)))
    writer.lines("gps0/data.csv", HEADER, rows)
    T = np.eye(4)
    T[:3, 3] = o.gps_lever_arm
    writer.yaml("gps0/sensor.yaml", {
        "sensor_type": "gnss", "rate_hz": float(o.gps_rate),
        "T_BS": {"cols": 4, "rows": 4, "data": [float(v) for v in T.ravel()]},
        "horizontal_sigma_m": float(o.gps_noise),
        "datum": {"latitude": float(o.gps_datum[0]), "longitude": float(o.gps_datum[1]),
                  "altitude": float(o.gps_datum[2])}})
    return {"gps_world_heading_deg": float(o.gps_heading_deg), "gps_world_origin_enu": [float(v) for v in o.gps_origin],
            "gps_fixes": int(n), "gps_jumped_fixes": int(jumped.sum())}
