"""The ``sensor.yaml`` files of a recording (``datasets/README.md``): one model per file, each key a field with its
physical range.

A file is read with :meth:`SensorFile.read`: a value that cannot be (a YAML boolean or a text where a number belongs,
NaN, a number beyond its range, a ``T_BS`` that is no rigid motion) is an :class:`~fusion_vo.errors.InputError` in
one line naming the file and the key, exit status 2 on the command line::

    cam0/sensor.yaml: height_sigma must be at most 1000, not 1e+300
    imu0/sensor.yaml: T_BS must have a rotation matrix as its rotation part (orthonormal, determinant +1)

Keys a file type does not read are left alone (EuRoC's ``comment``, a tool's own keys); one close to a key it reads
(``hieght_sigma``) is warned about, naming the key meant (:func:`warn_unknown_keys`).

=============  ==============================================================================================
``cam0``       :class:`CameraFile`: resolution, intrinsics, distortion, ``T_BS``, ``height_sigma``,
               ``bit_depth``, ``camera_noise``; :func:`camera_model` and :func:`uncalibrated_camera` make the
               :class:`~fusion_vo.geometry.camera.CameraModel`
``imu0``       :class:`ImuFile`: ``T_BS``, rate and the EuRoC noise keys
``wheel0``     :class:`WheelFile`: ticks per revolution, radii, wheel base, ``radius_sigma``
``gps0``       :class:`GpsFile`: antenna ``T_BS``, ``horizontal_sigma_m``, ``datum``
=============  ==============================================================================================

``odom0/`` and ``range0/`` have no ``sensor.yaml``: their rows carry everything.
"""

from __future__ import annotations

import difflib
import logging
import os
from pathlib import Path
from typing import Annotated, Any, ClassVar, Literal, Self

import numpy as np
from pydantic import BeforeValidator, ConfigDict, Field, field_validator, model_validator

from fusion_vo.config.base import INTEGER, NUMBER, Float, Section
from fusion_vo.config.files import load_yaml, validate
from fusion_vo.errors import InputError
from fusion_vo.geometry.camera import DISTORTION_MODELS, CameraModel, default_T_BS

log = logging.getLogger(__name__)

#: largest translation [m] a sensor's ``T_BS`` may state: beyond it the number is a typo, not a lever arm
MAX_LEVER_ARM_M = 1e3
#: largest image side [px] a ``resolution`` may state (a frame of it is 10^10 pixels)
MAX_IMAGE_SIDE = 100_000
#: a focal length [px] lies within this factor of the image's larger side either way: from a field of view of
#: 0.6 degrees to far beyond a fisheye's (fx = fy = 1e-9 ended a run 1.9e11 m away)
FOCAL_FACTOR = 100.0
#: the largest standard deviation or noise density a file may state [m, rad/s/√Hz ...]: its square must not overflow
MAX_SIGMA = 1e3
#: the largest rate a file may state [Hz]
MAX_RATE_HZ = 1e6
#: distortion model names of other tools, and the model each is
DISTORTION_ALIASES = {"radtan": "radial-tangential", "plumb_bob": "radial-tangential", "fisheye": "equidistant"}
#: the number of distortion coefficients each model takes
COEFFICIENTS = {"radial-tangential": (4, 5), "equidistant": (4,), "division": (1,), "none": (0, 4, 5)}


def _matrix(value: Any) -> list[list[float]]:
    """A sensor's pose ``T_BS``: ``{cols: 4, rows: 4, data: [16 numbers]}`` (EuRoC) or a nested list, a rigid
    motion (finite numbers, a rotation part that is a rotation, a translation within :data:`MAX_LEVER_ARM_M`, the
    bottom row ``[0, 0, 0, 1]``)."""
    try:
        if isinstance(value, dict):
            m = np.asarray(value["data"], dtype=np.float64).reshape(int(value.get("rows", 4)), int(value.get("cols", 4)))
        elif isinstance(value, (str, bytes)):
            raise ValueError
        else:
            m = np.asarray(value, dtype=np.float64)
        if m.shape != (4, 4):
            raise ValueError
    except (KeyError, TypeError, ValueError, OverflowError):
        raise ValueError("must be a 4x4 matrix (cols: 4, rows: 4, data: [16 numbers])") from None
    if not np.all(np.isfinite(m)):
        raise ValueError("must hold finite numbers (NaN or inf found)")
    if not np.allclose(m[3], [0.0, 0.0, 0.0, 1.0], rtol=0, atol=1e-6):  # a homogeneous transform (the row was ignored)
        raise ValueError(f"must have the bottom row [0, 0, 0, 1], not {[float(v) for v in m[3]]}")
    R = m[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-5) or abs(np.linalg.det(R) - 1) > 1e-5:
        raise ValueError("must have a rotation matrix as its rotation part (orthonormal, determinant +1)")
    if np.max(np.abs(m[:3, 3])) > MAX_LEVER_ARM_M:
        raise ValueError(f"must have a translation within {MAX_LEVER_ARM_M:g} m (a lever arm), not "
                         f"{np.max(np.abs(m[:3, 3])):g} m")
    return m.tolist()


#: a sensor's pose in the body frame, checked by :func:`_matrix`
Pose = Annotated[tuple[tuple[float, float, float, float], ...], BeforeValidator(_matrix)]
#: an optional standard deviation or noise density of a file (positive)
_Sigma = Annotated[float, Field(gt=0, le=MAX_SIGMA), NUMBER] | None
#: an optional random walk of a file (0: none)
_Walk = Annotated[float, Field(ge=0, le=MAX_SIGMA), NUMBER] | None
#: an optional rate [Hz]
_Rate = Annotated[float, Field(gt=0, le=MAX_RATE_HZ), NUMBER] | None
#: a wheel's radius or the wheel base [m]: from a micrometre to a kilometre
_Length = Annotated[float, Field(ge=1e-6, le=1e3), NUMBER]


class SensorFile(Section):
    """Base of a ``sensor.yaml`` model: keys it does not read are left alone (module docstring)."""

    model_config = ConfigDict(extra="ignore")

    #: keys of every file that are not read (EuRoC's)
    OTHER_KEYS: ClassVar[tuple[str, ...]] = ("sensor_type", "comment")

    T_BS: Pose | None = Field(None, description="The sensor's pose in the body frame (a 4x4 rigid motion; "
                                                "translation [m]).")
    rate_hz: _Rate = Field(None, description="Nominal sample rate [Hz] (informative: the timestamps are used).")

    @classmethod
    def read(cls, path: str | Path, required: bool = True, warn: bool = True) -> Self:
        """The file at ``path``; an absent one that is not ``required`` holds only defaults. With ``warn``, a key
        close to one the file type reads is warned about (:func:`warn_unknown_keys`).

        Raises
        ------
        InputError
            Naming the file and the key: a missing required file, YAML that does not parse, a value that cannot be.
        """
        path = Path(path)
        data = {} if not required and not os.path.lexists(path) else load_yaml(path)
        if warn:
            warn_unknown_keys(data, cls.known_keys(), path)
        return validate(cls, data, path)

    @classmethod
    def known_keys(cls) -> tuple[str, ...]:
        """The keys the file type reads, and EuRoC's keys that it does not."""
        return (*cls.OTHER_KEYS, *cls.model_fields)

    def pose(self, default: np.ndarray) -> np.ndarray:
        """``T_BS`` as a 4x4 array (``default`` when the file does not state it)."""
        return np.array(self.T_BS, dtype=np.float64) if self.T_BS is not None else np.array(default, dtype=np.float64)


class CameraNoiseFile(Section):
    """``camera_noise`` of ``cam0/sensor.yaml``: the camera's heading noise by turn, measured against ground truth
    (``fusion-vo calibrate camera-noise``, :mod:`fusion_vo.calibration.camera_noise`)."""

    frontend: str = Field(min_length=1, description="The frontend it was measured with.")
    edges: list[Annotated[float, Field(ge=0, le=10), NUMBER]] = Field(min_length=1, description=(
        "Lower edges of the turn bands [rad between two frames], rising from 0."))
    heading_sigma: list[Annotated[float, Field(gt=0, le=10), NUMBER]] = Field(min_length=1, description=(
        "RMS heading error of an increment in each band [rad]."))
    frame_sigma: Float = Field(ge=0, le=10, description="Standard deviation of each frame's own heading error [rad].")
    increments: Annotated[int, Field(ge=0, le=10**9), INTEGER] = Field(0, description="How many increments it was "
                                                                                      "measured on.")

    @model_validator(mode="after")
    def _bands(self) -> CameraNoiseFile:
        if self.edges[0] != 0 or np.any(np.diff(self.edges) <= 0):
            raise ValueError(f"edges must rise from 0, not {self.edges}")
        if len(self.heading_sigma) != len(self.edges):
            raise ValueError(f"heading_sigma needs one number per edge ({len(self.edges)}), not "
                             f"{len(self.heading_sigma)}")
        return self


class CameraFile(SensorFile):
    """``cam0/sensor.yaml``: the camera's calibration.

    Besides the ranges of the fields: the distortion coefficients are as many as the model takes (all zero for
    ``none``), and the focal lengths lie within :data:`FOCAL_FACTOR` of the image's larger side either way.
    """

    rate_hz: _Rate = Field(20.0, description="Nominal frame rate [Hz] (informative: the timestamps are used).")
    resolution: tuple[Annotated[int, Field(ge=1, le=MAX_IMAGE_SIDE), INTEGER],
                      Annotated[int, Field(ge=1, le=MAX_IMAGE_SIDE), INTEGER]] = Field(description=(
                          "Image width and height [px]."))
    camera_model: Literal["pinhole"] = Field("pinhole", description="Projection model (only ``pinhole``).")
    intrinsics: tuple[Float, Float, Float, Float] | None = Field(None, description=(
        "``[fu, fv, cu, cv]``: focal lengths and principal point [px]; a camera without them runs only "
        "``--uncalibrated``."))
    distortion_model: Literal[DISTORTION_MODELS] = Field("none", description=(
        "Lens model of the coefficients: ``radial-tangential`` (``radtan``, ``plumb_bob``), ``equidistant`` "
        "(``fisheye``), ``division`` or ``none``."))
    distortion_coefficients: list[Annotated[float, Field(ge=-1e6, le=1e6), NUMBER]] = Field(
        default_factory=lambda: [0.0] * 4, description="The coefficients of that model.")
    height_sigma: _Sigma = Field(None, description=(
        "Standard deviation of the camera height that ``T_BS`` states [m] (the visual scale's prior)."))
    bit_depth: Literal[8, 10, 12, 14, 16] | None = Field(None, description=(
        "Bits of data in each pixel of 16-bit frames (null: read off the first frame)."))
    camera_noise: CameraNoiseFile | None = Field(None, description=(
        "The camera's heading noise measured against ground truth (``fusion-vo calibrate camera-noise``)."))

    @field_validator("distortion_model", mode="before")
    @classmethod
    def _alias(cls, value: Any) -> Any:
        return DISTORTION_ALIASES.get(value, value) if isinstance(value, str) else value

    @model_validator(mode="after")
    def _consistent(self) -> CameraFile:
        counts = COEFFICIENTS[self.distortion_model]
        if len(self.distortion_coefficients) not in counts:
            raise ValueError(f"distortion_coefficients: {self.distortion_model} needs "
                             f"{' or '.join(map(str, counts))} numbers, not {len(self.distortion_coefficients)}")
        if self.distortion_model == "none" and any(self.distortion_coefficients):
            raise ValueError("distortion_coefficients are not all zero but distortion_model is 'none': name the model "
                             "they belong to (radial-tangential, equidistant, division) or set them to 0")
        if self.intrinsics is not None:
            problem = focal_length_problem(self.intrinsics[0], self.intrinsics[1], self.resolution)
            if problem:
                raise ValueError(f"intrinsics: {problem}")
        return self

    def camera(self, path: str | Path | None = None) -> CameraModel:
        """The camera model this file states.

        Raises
        ------
        InputError
            Naming ``path`` when the file has no intrinsics, and the way to run without them.
        """
        if self.intrinsics is None:
            raise InputError("missing key 'intrinsics' (a camera without calibration: run with --uncalibrated "
                             "[--focal-length PX], or 'uncalibrated: true' under 'odometry' in the configuration)",
                             path)
        fu, fv, cu, cv = self.intrinsics
        coefficients = np.array(self.distortion_coefficients, dtype=np.float64)
        return CameraModel(width=self.resolution[0], height=self.resolution[1], fu=fu, fv=fv, cu=cu, cv=cv,
                           distortion_model=self.distortion_model,
                           distortion=coefficients if len(coefficients) else np.zeros(4),
                           T_BS=self.pose(default_T_BS()), rate_hz=self.rate_hz)


class ImuFile(SensorFile):
    """``imu0/sensor.yaml``: the IMU's mounting and EuRoC's noise keys (each optional)."""

    gyroscope_noise_density: _Sigma = Field(None, description="Gyro white noise [rad/s/√Hz].")
    gyroscope_random_walk: _Walk = Field(None, description="Gyro bias random walk [rad/s²/√Hz].")
    accelerometer_noise_density: _Sigma = Field(None, description="Accelerometer white noise [m/s²/√Hz].")
    accelerometer_random_walk: _Walk = Field(None, description="Accelerometer bias random walk [m/s³/√Hz].")

    def noise(self) -> dict[str, float]:
        """The noise keys the file states."""
        return {key: value for key in ("gyroscope_noise_density", "gyroscope_random_walk",
                                       "accelerometer_noise_density", "accelerometer_random_walk")
                if (value := getattr(self, key)) is not None}


class WheelFile(SensorFile):
    """``wheel0/sensor.yaml``: the wheels' calibration (the first four keys are required)."""

    ticks_per_revolution: Float = Field(ge=1, le=2.0**32, description="Encoder ticks per wheel revolution.")
    wheel_radius_left: _Length = Field(description="Radius of the left wheel [m].")
    wheel_radius_right: _Length = Field(description="Radius of the right wheel [m].")
    wheel_base: _Length = Field(description="Distance between the wheels' contact points [m].")
    radius_sigma: _Sigma = Field(None, description=(
        "Standard deviation of the wheels' common radius error [m] (the wheels' distance scale's prior)."))


class GpsDatum(Section):
    """The origin of the local East-North-Up frame."""

    latitude: Float = Field(ge=-90, le=90, description="Latitude [deg].")
    longitude: Float = Field(ge=-180, le=180, description="Longitude [deg].")
    altitude: Float = Field(0.0, ge=-1e5, le=1e5, description="Altitude above the WGS-84 ellipsoid [m].")


class GpsFile(SensorFile):
    """``gps0/sensor.yaml``: the antenna's position (the translation of ``T_BS``), the sigma of fixes without a
    covariance and the datum (every key optional)."""

    horizontal_sigma_m: Annotated[float, Field(gt=0, le=1e6), NUMBER] | None = Field(None, description=(
        "Standard deviation per horizontal axis of a fix without a covariance [m]."))
    datum: GpsDatum | None = Field(None, description="ENU origin [deg, deg, m] (null: the first usable fix).")


def focal_length_problem(fu: float, fv: float, size) -> str | None:
    """What is wrong with focal lengths [px] that do not both lie within :data:`FOCAL_FACTOR` of the larger side of
    ``size`` (width, height) either way, or ``None``."""
    side = max(size)
    low, high = side / FOCAL_FACTOR, side * FOCAL_FACTOR
    if low <= fu <= high and low <= fv <= high:
        return None
    return (f"focal lengths {fu:g}, {fv:g} px are not a camera's for a {size[0]}x{size[1]} image (each must be "
            f"between {low:g} and {high:g} px)")


def camera_model(data: dict, path: str | Path | None = None) -> CameraModel:
    """The camera model of a ``cam0/sensor.yaml`` mapping read from ``path`` (:meth:`CameraFile.camera`)."""
    return validate(CameraFile, data, path).camera(path)


def read_camera(path: str | Path) -> CameraModel:
    """The camera model of the ``cam0/sensor.yaml`` at ``path`` (:meth:`CameraFile.camera`)."""
    return CameraFile.read(path).camera(path)


def uncalibrated_camera(path: str | Path, focal_length: float | None = None, quiet: bool = False) -> CameraModel:
    """A pinhole model for a camera without a calibration (``cam0/sensor.yaml`` without intrinsics).

    The resolution, rate and ``T_BS`` are read from the file; the lens is taken as distortion-free with its
    principal point at the image centre. The focal length is ``focal_length`` when given, else the file's ``fu,
    fv`` when it has intrinsics, else that of a 60 degree horizontal field of view (``0.866 * width``): the metric
    scale is then only as good as that guess (a fused run can re-estimate it as the camera height, whose ratio to
    the focal length is all that matters), with a warning unless ``quiet`` (a check of the inputs before the run).

    Raises
    ------
    InputError
        Naming ``path`` and the key (a configured ``focal_length`` out of range for the image names
        ``focal_length``).
    """
    path = Path(path)
    data = load_yaml(path)
    if "resolution" not in data:
        raise InputError("uncalibrated mode still needs 'resolution: [width, height]'", path)
    # the file's lens is not used, nor its intrinsics when a focal length is given
    unused = {"distortion_model": "none", "distortion_coefficients": []}
    if focal_length is not None:
        unused["intrinsics"] = None
    cam = validate(CameraFile, {**data, **unused}, path)
    width, height = cam.resolution
    if focal_length is not None:
        fu = fv = float(focal_length)
        problem = focal_length_problem(fu, fv, cam.resolution)
        if problem:
            raise InputError(f"focal_length: {problem}", path)
    elif cam.intrinsics is not None:
        fu, fv = cam.intrinsics[:2]
    else:
        fu = fv = width / (2.0 * np.tan(np.radians(30.0)))
        if not quiet:
            log.warning("%s: no focal length given; assuming a 60 degree horizontal field of view (%.0f px)", path, fu)
    if not (np.isfinite(fu) and np.isfinite(fv) and fu > 0 and fv > 0):
        raise InputError("focal_length must be a positive number of pixels", path)
    return CameraModel(width=width, height=height, fu=fu, fv=fv, cu=(width - 1) / 2.0, cv=(height - 1) / 2.0,
                       distortion_model="none", T_BS=cam.pose(default_T_BS()), rate_hz=cam.rate_hz)


def warn_unknown_keys(data: dict, known, path: str | Path) -> list[str]:
    """Log a warning for each key of ``data`` that is not in ``known`` but close to one of them (a misspelt optional
    key would otherwise be ignored without a word); other keys (EuRoC's ``comment``, a tool's own keys) are left
    alone. Returns the warnings."""
    known = list(known)
    out = []
    for key in data:
        if not isinstance(key, str) or key in known:
            continue
        close = difflib.get_close_matches(key, known, n=1, cutoff=0.8)
        if close:
            out.append(f"{path}: unknown key '{key}' (did you mean '{close[0]}'?)")
            log.warning("%s", out[-1])
    return out
