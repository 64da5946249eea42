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
from pathlib import Path
from typing import Annotated, Literal

import cv2
import numpy as np
from pydantic import Field, model_validator

from fusion_vo.config.base import NUMBER, Float, Fraction, Int, Positive, Section
from fusion_vo.geometry.camera import CameraModel
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

#: a focal length [px] lies within this factor of the image's larger side either way
FOCAL_FACTOR = 100.0

#: ranges that several options share
_Rate = Annotated[float, Field(gt=0, le=1e4), NUMBER]  # [Hz]
_Shape = Annotated[float, Field(gt=0, le=1e3), NUMBER]  # a side, radius or length [m]
_LeverArm = Annotated[float, Field(ge=-1e3, le=1e3), NUMBER]  # [m]
_Error = Annotated[float, Field(gt=-1, lt=1), NUMBER]  # a relative calibration error
_Noise = Annotated[float, Field(ge=0, le=1e3), NUMBER]  # a noise density or random walk
_Time = Annotated[float, Field(ge=0, le=MAX_DURATION_S), NUMBER]  # a time in the drive [s]
_Floor = Annotated[float, Field(ge=-1e4, le=1e4), NUMBER]  # a position on the floor [m]
_Offset = Annotated[float, Field(ge=-1e6, le=1e6), NUMBER]  # a time [s] or an offset [m] of a GPS jump
_Position = Annotated[float, Field(ge=-MAX_POSITION_M, le=MAX_POSITION_M), NUMBER]  # [m]
_AngularRate = Annotated[float, Field(ge=-MAX_ANGULAR_RATE, le=MAX_ANGULAR_RATE), NUMBER]  # [rad/s]
_Acceleration = Annotated[float, Field(ge=-MAX_ACCELERATION, le=MAX_ACCELERATION), NUMBER]  # [m/s²]
#: the distortion coefficients each model takes
_COEFFICIENTS = {"radial-tangential": (4, 5), "equidistant": (4,), "none": (0, 4)}


class SimulationOptions(Section):
    """Everything a generated recording depends on (with the seed).

    Besides the ranges of the fields: ``distortion`` has the number of coefficients its model takes, the focal
    lengths are within :data:`FOCAL_FACTOR` of the image's larger side, and every time span ``[t0, t1]`` has
    ``t0 <= t1``.
    """

    # motion
    duration: Annotated[float, Field(gt=0, le=MAX_DURATION_S), NUMBER] | None = Field(None, description=(
        "Length of the drive [s] (random, standstill; null: the profile's default)."))
    max_speed: Annotated[float, Field(gt=0, le=MAX_SPEED), NUMBER] | None = Field(None, description=(
        "Top speed [m/s] (null: the profile's default)."))
    max_turn_rate: Annotated[float, Field(gt=0, le=MAX_ANGULAR_RATE), NUMBER] | None = Field(None, description=(
        "Top turn rate [rad/s] (null: the profile's default)."))
    side: _Shape | None = Field(None, description="Side of the square (square, umbmark) [m].")
    radius: _Shape | None = Field(None, description="Radius of the circle [m].")
    length: _Shape | None = Field(None, description="Length of the straight drive [m].")
    angle: Annotated[float, Field(ge=-100, le=100), NUMBER] | None = Field(None, description="Angle of a turn in place [rad].")
    # floor
    texture: Literal[TEXTURES] = Field("gravel", description=(
        "Floor photograph: gravel, grass or brick (scikit-image's CC0 images)."))
    texel_size: Float = Field(0.00025, gt=0, le=1, description="Size on the floor of one pixel of the texture [m].")
    featureless: list[tuple[_Floor, _Floor, _Floor, _Floor]] = Field(default_factory=list, description=(
        "Rectangles of flat grey floor [m], each as x_min, y_min, x_max, y_max."))
    featureless_time: tuple[_Time, _Time] | None = Field(None, description=(
        "A time span [s] (t0, t1) in which the floor the camera sees is flat grey."))
    # camera
    width: Int = Field(640, ge=8, le=4096, description="Image width [px].")
    height: Int = Field(360, ge=8, le=4096, description="Image height [px].")
    fu: Positive = Field(420.0, description="Horizontal focal length [px].")
    fv: Positive = Field(420.0, description="Vertical focal length [px].")
    cu: Float = Field(319.5, ge=-1e5, le=1e5, description="Principal point, horizontal [px].")
    cv: Float = Field(179.5, ge=-1e5, le=1e5, description="Principal point, vertical [px].")
    distortion_model: Literal["radial-tangential", "equidistant", "none"] = Field(
        "radial-tangential", description="radial-tangential, equidistant or none.")
    distortion: list[Annotated[float, Field(ge=-1e3, le=1e3), NUMBER]] = Field(
        default_factory=lambda: [-0.03, 0.01, 0.0005, -0.0003], description="Distortion coefficients of that model.")
    camera_rate: _Rate = Field(20.0, description="Frame rate [Hz].")
    camera_height: Float = Field(0.10, gt=0, le=MAX_CAMERA_HEIGHT_M, description=(
        "Height of the camera above the floor [m]."))
    lever_arm: _LeverArm = Field(0.25, description="Camera ahead of the wheel axle [m].")
    lateral_offset: _LeverArm = Field(0.0, description="Camera to the left of the centre line [m].")
    tilt_x_deg: Float = Field(0.0, gt=-90, lt=90, description="Camera tilt about the body's x axis [deg].")
    tilt_y_deg: Float = Field(0.0, gt=-90, lt=90, description="Camera tilt about the body's y axis [deg].")
    height_error: Float = Field(0.0, gt=-1, lt=1, description=(
        "Fraction: the sensor.yaml height is the true one times 1 + height_error (``height_sigma`` states that "
        "error, at least 0.1 mm)."))
    height_vibration: Float = Field(0.0, ge=0, le=10, description="Amplitude of the camera's vertical vibration [m].")
    vibration_frequency: Float = Field(3.0, ge=0, le=1000, description="Frequency of that vibration [Hz].")
    exposure_time: Float = Field(0.0, ge=0, le=1, description="Exposure [s] (motion blur; 0: none).")
    blur_samples: Int = Field(5, ge=1, le=100, description="Sub-frames rendered for motion blur.")
    supersample: Int = Field(2, ge=1, le=16, description="Rendering supersampling factor per axis.")
    dropped_frames: Float = Field(0.0, ge=0, lt=1, description="Fraction of frames missing from the recording.")
    png_compression: Int = Field(0, ge=0, le=9, description="PNG compression level.")
    # photometry
    gain: Float = Field(1.0, gt=0, le=100, description="Image gain.")
    exposure_drift: Fraction = Field(0.0, description="Amplitude of the slow exposure change (fraction).")
    exposure_period: Float = Field(10.0, gt=0, le=1e6, description="Period of that change [s].")
    vignetting: Fraction = Field(0.0, description="Brightness lost at the image corners (fraction).")
    highlight_radius: Float = Field(0.0, ge=0, le=1e5, description="Radius of a specular highlight [px] (0: none).")
    highlight_center: tuple[Annotated[float, Field(ge=-10, le=10)], Annotated[float, Field(ge=-10, le=10)]] = Field(
        (0.55, 0.45), description="Centre of the highlight (fractions of width and height).")
    noise: Float = Field(1.0, ge=0, le=65535, description="Image noise [grey levels].")
    shot_noise: Float = Field(0.0, ge=0, le=100, description="Signal-dependent noise factor.")
    # wheels
    wheel_rate: _Rate = Field(50.0, description="Encoder sample rate [Hz].")
    ticks_per_revolution: Int = Field(4096, ge=1, le=2**32, description="Encoder ticks per wheel revolution.")
    wheel_radius: Float = Field(0.05, ge=1e-6, le=1e3, description="Nominal wheel radius [m].")
    wheel_base: Float = Field(0.30, ge=1e-6, le=1e3, description="Nominal wheel base [m].")
    radius_error_left: _Error = Field(0.006, description=(
        "Fraction: true left radius = nominal · (1 + error); ``radius_sigma`` of wheel0/sensor.yaml states the "
        "larger of the two."))
    radius_error_right: _Error = Field(-0.004, description=(
        "Fraction: true right radius = nominal · (1 + error); ``radius_sigma`` of wheel0/sensor.yaml states the "
        "larger of the two."))
    base_error: _Error = Field(0.015, description="Fraction: true wheel base = nominal · (1 + error).")
    slip: Float = Field(0.0005, ge=0, le=1, description="Wheel slip noise [sqrt(m)].")
    wheel_start_count: Int = Field(0, ge=-(2**31), le=2**32 - 1, description=(
        "First encoder count (near 2**31 to make the counters wrap)."))
    # imu
    imu_rate: _Rate = Field(200.0, description="IMU sample rate [Hz].")
    gyro_bias: tuple[_AngularRate, _AngularRate, _AngularRate] = Field((0.002, -0.001, 0.005), description=(
        "Gyro bias [rad/s] about x, y, z."))
    accel_bias: tuple[_Acceleration, _Acceleration, _Acceleration] = Field((0.02, -0.01, 0.03), description=(
        "Accelerometer bias [m/s²] along x, y, z."))
    gyro_noise_density: _Noise = Field(1.7e-4, description="Gyro white noise [rad/s/√Hz].")
    gyro_random_walk: _Noise = Field(2.0e-5, description="Gyro bias random walk [rad/s²/√Hz].")
    accel_noise_density: _Noise = Field(2.0e-3, description="Accelerometer white noise [m/s²/√Hz].")
    accel_random_walk: _Noise = Field(3.0e-3, description="Accelerometer bias random walk [m/s³/√Hz].")
    # independent camera
    realistic: RealisticCamera | None = Field(None, description=(
        "Options of :class:`fusion_vo.simulation.realistic.RealisticCamera`; when given, frames are rendered "
        "through that module's own lens, optics and sensor instead of the estimator's camera model (the "
        "photometry options and fu .. distortion are then unused)."))
    # gps
    gps: bool = Field(False, description="Write gps0.")
    gps_rate: Float = Field(5.0, gt=0, le=100, description="GPS fix rate [Hz].")
    gps_noise: Positive = Field(0.05, description="GPS noise [m] per horizontal axis.")
    gps_lever_arm: tuple[_LeverArm, _LeverArm, _LeverArm] = Field((-0.10, 0.0, 0.40), description=(
        "Antenna position [m] in the body frame (x, y, z)."))
    gps_outages: list[tuple[_Time, _Time]] = Field(default_factory=list, description=(
        "Time spans [s] without fixes, each as t0, t1."))
    gps_jumps: list[tuple[_Offset, _Offset, _Offset, _Offset]] = Field(default_factory=list, description=(
        "Time spans [s] whose fixes are offset east and north by de, dn metres (multipath), each as t0, t1, de, "
        "dn."))
    gps_heading_deg: Float = Field(30.0, ge=-360, le=360, description=(
        "Heading of the world x axis in ENU [deg], counter-clockwise from east."))
    gps_origin: tuple[_Position, _Position] = Field((0.0, 0.0), description="ENU position of the world origin [m].")
    gps_datum: tuple[Annotated[float, Field(ge=-90, le=90)], Annotated[float, Field(ge=-180, le=180)],
                     Annotated[float, Field(ge=-1e6, le=1e6)]] = Field((47.3977, 8.5456, 488.0), description=(
                         "Latitude [deg], longitude [deg] and altitude [m] of the ENU datum."))
    # other
    range_finder: bool = Field(False, description="Write range0 (a downward range finder).")
    range_noise: Float = Field(0.0005, ge=0, le=1, description="Range finder noise [m].")
    odometry: bool = Field(False, description="Write odom0 (an odometry twist).")
    gt_rate: _Rate = Field(200.0, description="Ground-truth rate [Hz].")
    jitter: Float = Field(0.0, ge=0, le=1, description="Timestamp jitter of wheel and IMU samples [s].")
    start_time_ns: Int = Field(1_600_000_000_000_000_000, ge=0, lt=2**63, description="First timestamp [ns].")

    @model_validator(mode="after")
    def _consistent(self) -> SimulationOptions:
        counts = _COEFFICIENTS[self.distortion_model]
        if len(self.distortion) not in counts:
            raise ValueError(f"distortion: {self.distortion_model} takes {' or '.join(map(str, counts))} "
                             f"coefficients, not {len(self.distortion)}")
        side = max(self.width, self.height)
        low, high = side / FOCAL_FACTOR, side * FOCAL_FACTOR
        if not (low <= self.fu <= high and low <= self.fv <= high):
            raise ValueError(f"focal lengths fu, fv {self.fu:g}, {self.fv:g} px are not a camera's for a "
                             f"{self.width}x{self.height} image (each must be between {low:g} and {high:g} px)")
        spans = [("featureless_time", self.featureless_time)] if self.featureless_time is not None else []
        spans += [("gps_outages", span) for span in self.gps_outages]
        spans += [("gps_jumps", span) for span in self.gps_jumps]
        for name, span in spans:
            if span[1] < span[0]:
                raise ValueError(f"{name}: a time span [t0, t1] needs t0 <= t1, not {list(span[:2])}")
        return self


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
    o = options or SimulationOptions()
    if overrides:
        o = SimulationOptions.from_dict({**o.model_dump(), **overrides})
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
    real_cam = o.realistic
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
        "profile": profile, "seed": int(seed), "options": o.model_dump(mode="json"), "summary": info,
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
