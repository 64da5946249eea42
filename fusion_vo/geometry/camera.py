"""Camera model: pinhole intrinsics, lens distortion and the camera's pose in the body frame.

A camera point ``X_S = (x, y, z)`` (OpenCV frame: x right, y down, z along the optical axis) projects to
normalised coordinates ``(x/z, y/z)``, is distorted by the lens model and mapped to pixels by ``K``::

    K = [[fu, 0, cu], [0, fv, cv], [0, 0, 1]]

Distortion models (as in ``cam0/sensor.yaml``):

``radial-tangential``  OpenCV's ``(k1, k2, p1, p2[, k3])``;
``equidistant``        OpenCV's fisheye model ``(k1, k2, k3, k4)``;
``division``           the one-parameter division model ``(lambda,)``: a distorted normalised point
                       ``x_d`` comes from ``x_d / (1 + lambda |x_d|^2)`` (barrel: ``lambda < 0``); what
                       ``--uncalibrated`` estimates from the frames themselves
                       (:mod:`fusion_vo.calibration.lens_from_motion`);
``none``               no distortion.

``T_BS`` maps camera coordinates to body coordinates: ``X_B = R_BS X_S + t_BS``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import yaml

from fusion_vo.errors import InputError, check_file
from fusion_vo.outputs import make_folder, write_atomic

DISTORTION_MODELS = ("radial-tangential", "equidistant", "division", "none")

#: camera looking straight down with image-up pointing forward (x_S = -y_B, y_S = -x_B, z_S = -z_B)
R_BS_DOWN_FORWARD = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


@dataclass
class CameraModel:
    """Intrinsics, distortion and mounting of one camera.

    Attributes
    ----------
    width, height : int
        Image size [px].
    fu, fv, cu, cv : float
        Focal lengths and principal point [px].
    distortion_model : str
        One of :data:`DISTORTION_MODELS`.
    distortion : ndarray
        Distortion coefficients of that model.
    T_BS : ndarray, shape (4, 4)
        Camera pose in the body frame.
    rate_hz : float
        Nominal frame rate (informative; real timestamps are always used).
    """

    width: int
    height: int
    fu: float
    fv: float
    cu: float
    cv: float
    distortion_model: str = "none"
    distortion: np.ndarray = field(default_factory=lambda: np.zeros(4))
    T_BS: np.ndarray = field(default_factory=lambda: _default_T_BS())
    rate_hz: float = 20.0

    def __post_init__(self) -> None:
        self.distortion = np.asarray(self.distortion, dtype=np.float64).ravel()
        self.T_BS = np.asarray(self.T_BS, dtype=np.float64).reshape(4, 4)
        if self.distortion_model not in DISTORTION_MODELS:
            raise ValueError(f"unknown distortion model {self.distortion_model!r}")
        self._distorted = self.distortion_model != "none" and bool(np.any(self.distortion != 0))

    # ------------------------------------------------------------------ matrices
    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fu, 0.0, self.cu], [0.0, self.fv, self.cv], [0.0, 0.0, 1.0]])

    @property
    def R_BS(self) -> np.ndarray:
        return self.T_BS[:3, :3]

    @property
    def t_BS(self) -> np.ndarray:
        return self.T_BS[:3, 3]

    @property
    def has_distortion(self) -> bool:
        """Whether the lens model changes any point (fixed when the model is built)."""
        return self._distorted

    # ------------------------------------------------------------------ points
    def normalize(self, pixels: np.ndarray) -> np.ndarray:
        """Undistorted normalised coordinates ``(x/z, y/z)`` of raw pixel positions (N x 2)."""
        pts = np.asarray(pixels, dtype=np.float64).reshape(-1, 1, 2)
        if not self.has_distortion:
            out = (pts.reshape(-1, 2) - [self.cu, self.cv]) / [self.fu, self.fv]
            return out
        if self.distortion_model == "equidistant":
            out = cv2.fisheye.undistortPoints(pts, self.K, self.distortion[:4])
        elif self.distortion_model == "division":
            xd = (pts.reshape(-1, 2) - [self.cu, self.cv]) / [self.fu, self.fv]
            denom = 1.0 + self.distortion[0] * np.sum(xd * xd, axis=1, keepdims=True)
            # beyond the model's horizon (1 + lambda r^2 <= 0) the ray is undefined
            return np.where(denom > 1e-6, xd / np.maximum(denom, 1e-6), np.nan)
        else:
            out = cv2.undistortPoints(
                pts, self.K, self.distortion, None, None, None,
                (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 1e-10),
            )
        return out.reshape(-1, 2)

    def denormalize(self, normalized: np.ndarray) -> np.ndarray:
        """Raw (distorted) pixel positions of normalised coordinates (N x 2)."""
        xy = np.asarray(normalized, dtype=np.float64).reshape(-1, 2)
        if not self.has_distortion:
            return xy * [self.fu, self.fv] + [self.cu, self.cv]
        if self.distortion_model == "equidistant":
            out = cv2.fisheye.distortPoints(xy.reshape(-1, 1, 2), self.K, self.distortion[:4])
            return out.reshape(-1, 2)
        if self.distortion_model == "division":
            # r_d solves lambda r_u r_d^2 - r_d + r_u = 0; the root that tends to r_u as lambda -> 0
            disc = 1.0 - 4.0 * self.distortion[0] * np.sum(xy * xy, axis=1, keepdims=True)
            xd = 2.0 * xy / (1.0 + np.sqrt(np.where(disc >= 0, disc, np.nan)))
            return xd * [self.fu, self.fv] + [self.cu, self.cv]
        return self._distort_radtan(xy)

    def _distort_radtan(self, xy: np.ndarray) -> np.ndarray:
        """Pixels of normalised points (N x 2) through the radial-tangential model.

        The polynomial of ``cv2.projectPoints`` with the same order of operations, so the results are
        the same to the last bit, without its Jacobians with respect to every parameter, which
        ``projectPoints`` always computes from Python (what the dense fallback's remap grid of a whole
        frame would pay for nothing).
        """
        k1, k2, p1, p2 = self.distortion[:4]
        k3 = self.distortion[4] if len(self.distortion) > 4 else 0.0
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        r4 = r2 * r2
        r6 = r4 * r2
        a1 = 2 * x * y
        a2 = r2 + 2 * x * x
        a3 = r2 + 2 * y * y
        cdist = 1 + k1 * r2 + k2 * r4 + k3 * r6
        xd = x * cdist + p1 * a1 + p2 * a2
        yd = y * cdist + p1 * a3 + p2 * a1
        return np.column_stack([xd * self.fu + self.cu, yd * self.fv + self.cv])

    def project(self, points_S: np.ndarray) -> np.ndarray:
        """Pixel positions of camera-frame points (N x 3, z > 0)."""
        p = np.asarray(points_S, dtype=np.float64).reshape(-1, 3)
        return self.denormalize(p[:, :2] / p[:, 2:3])

    def pixel_rays(self, supersample: int = 1) -> np.ndarray:
        """Undistorted normalised coordinates ``(x/z, y/z)`` of the ray through every (sub-)pixel.

        Parameters
        ----------
        supersample : int
            ``s`` samples per pixel along each axis, at offsets ``(k + 0.5) / s - 0.5`` (k = 0..s-1)
            from the pixel centre; ``s = 1`` is the pixel centre itself.

        Returns
        -------
        ndarray, shape (height * s, width * s, 2), float64
            Computed with :meth:`normalize`, so ``denormalize`` maps them back to the sample positions.
        """
        s = int(supersample)
        if s < 1:
            raise ValueError("supersample must be >= 1")
        offsets = (np.arange(s) + 0.5) / s - 0.5
        us = (np.arange(self.width)[:, None] + offsets[None, :]).ravel()
        vs = (np.arange(self.height)[:, None] + offsets[None, :]).ravel()
        uu, vv = np.meshgrid(us, vs)
        return self.normalize(np.column_stack([uu.ravel(), vv.ravel()])).reshape(len(vs), len(us), 2)

    # ------------------------------------------------------------------ files
    @classmethod
    def from_yaml(cls, path: str | Path) -> "CameraModel":
        """Read a ``cam0/sensor.yaml`` file (see ``datasets/README.md``)."""
        path = Path(path)
        data = load_yaml(path)
        return cls.from_dict(data, path)

    @classmethod
    def from_dict(cls, data: dict, path: str | Path | None = None) -> "CameraModel":
        def need(key):
            if key not in data:
                hint = (" (a camera without calibration: run with --uncalibrated [--focal-length PX], or 'uncalibrated: true'"
                        " under 'odometry' in the configuration)") if key == "intrinsics" else ""
                raise InputError(f"missing key '{key}'{hint}", path)
            return data[key]

        res = resolution(need("resolution"), path)
        try:
            intr = [float(v) for v in need("intrinsics")]
            if len(intr) != 4:
                raise ValueError
        except (TypeError, ValueError):
            raise InputError("'intrinsics' needs [fu, fv, cu, cv]", path) from None
        model = str(data.get("camera_model", "pinhole"))
        if model != "pinhole":
            raise InputError(f"camera_model '{model}' is not supported (only 'pinhole')", path)
        dmodel = str(data.get("distortion_model", "none"))
        aliases = {"radtan": "radial-tangential", "plumb_bob": "radial-tangential", "fisheye": "equidistant"}
        dmodel = aliases.get(dmodel, dmodel)
        if dmodel not in DISTORTION_MODELS:
            raise InputError(f"unknown distortion_model '{dmodel}' (use one of {', '.join(DISTORTION_MODELS)})", path)
        try:
            coeffs = np.asarray(data.get("distortion_coefficients", [0.0] * 4), dtype=np.float64).ravel()
        except (TypeError, ValueError):
            raise InputError("'distortion_coefficients' must be a list of numbers", path) from None
        expected = {"radial-tangential": (4, 5), "equidistant": (4,), "division": (1,), "none": (0, 4, 5)}[dmodel]
        if len(coeffs) not in expected:
            raise InputError(f"distortion_coefficients: {dmodel} needs {' or '.join(map(str, expected))} numbers", path)
        if dmodel == "none" and np.any(coeffs != 0):
            raise InputError("distortion_coefficients are not all zero but distortion_model is 'none': name the "
                             "model they belong to (radial-tangential, equidistant, division) or set them to 0", path)
        T = parse_pose(data["T_BS"], "T_BS", path) if "T_BS" in data else _default_T_BS()
        values = np.array(intr + list(coeffs))
        if not np.all(np.isfinite(values)) or intr[0] <= 0 or intr[1] <= 0:
            raise InputError("calibration values must be finite and the focal lengths positive", path)
        check_focal_lengths(intr[0], intr[1], res, path, "intrinsics")
        rate = sensor_number(data, "rate_hz", path, 20.0, high=1e6, unit=" Hz")
        return cls(
            width=res[0], height=res[1], fu=intr[0], fv=intr[1], cu=intr[2], cv=intr[3],
            distortion_model=dmodel, distortion=coeffs if len(coeffs) else np.zeros(4), T_BS=T,
            rate_hz=rate,
        )

    def to_dict(self) -> dict:
        return {
            "sensor_type": "camera",
            "rate_hz": float(self.rate_hz),
            "resolution": [int(self.width), int(self.height)],
            "camera_model": "pinhole",
            "intrinsics": [float(self.fu), float(self.fv), float(self.cu), float(self.cv)],
            "distortion_model": self.distortion_model,
            "distortion_coefficients": [float(v) for v in self.distortion],
            "T_BS": {"cols": 4, "rows": 4, "data": [float(v) for v in self.T_BS.ravel()]},
        }

    def write_yaml(self, path: str | Path) -> None:
        """Write ``path`` (atomically); the keys of a file already there that the model does not hold
        (``height_sigma``, ``camera_noise``, ``bit_depth``, ...) are kept."""
        data = self.to_dict()
        if Path(path).is_file():
            try:
                old = load_yaml(path)
            except InputError:  # a file that is no YAML mapping is replaced whole
                old = {}
            data.update({key: value for key, value in old.items() if key not in data})
        write_yaml_atomic(path, data)


def uncalibrated_camera(path: str | Path, focal_length: float | None = None, quiet: bool = False) -> CameraModel:
    """A pinhole model for a camera without a calibration (``cam0/sensor.yaml`` without intrinsics).

    The resolution, rate and ``T_BS`` are read from the file; the lens is taken as distortion-free
    with its principal point at the image centre. The focal length is ``focal_length`` when given,
    else the file's ``fu, fv`` when it has intrinsics, else that of a 60 degree horizontal field of
    view (``0.866 * width``): the metric scale is then only as good as that guess (a fused run can
    re-estimate it as the camera height, whose ratio to the focal length is all that matters), with a
    warning unless ``quiet`` (a check of the inputs before the run).
    """
    import logging

    path = Path(path)
    data = load_yaml(path)
    if "resolution" not in data:
        raise InputError("uncalibrated mode still needs 'resolution: [width, height]'", path)
    res = resolution(data["resolution"], path)
    if focal_length is not None:
        fu = fv = float(focal_length)
    elif "intrinsics" in data:
        intr = [float(v) for v in data["intrinsics"]][:2]
        fu, fv = intr[0], intr[1]
    else:
        fu = fv = res[0] / (2.0 * np.tan(np.radians(30.0)))
        if not quiet:
            logging.getLogger(__name__).warning(
                "%s: no focal length given; assuming a 60 degree horizontal field of view (%.0f px)", path, fu)
    if not (np.isfinite(fu) and np.isfinite(fv) and fu > 0 and fv > 0):
        raise InputError("focal_length must be a positive number of pixels", path)
    check_focal_lengths(fu, fv, res, path, "focal_length" if focal_length is not None else "intrinsics")
    T = parse_pose(data["T_BS"], "T_BS", path) if "T_BS" in data else _default_T_BS()
    return CameraModel(width=res[0], height=res[1], fu=fu, fv=fv, cu=(res[0] - 1) / 2.0, cv=(res[1] - 1) / 2.0,
                       distortion_model="none", T_BS=T, rate_hz=sensor_number(data, "rate_hz", path, 20.0, high=1e6,
                                                                              unit=" Hz"))


def _default_T_BS() -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R_BS_DOWN_FORWARD
    T[:3, 3] = [0.25, 0.0, 0.1]
    return T


#: largest translation [m] a sensor's ``T_BS`` may state: beyond it the number is a typo, not a lever arm
MAX_LEVER_ARM_M = 1e3

#: largest image side [px] a ``resolution`` may state (a frame of it is 10^10 pixels)
MAX_IMAGE_SIDE = 100_000

#: a focal length [px] lies within this factor of the image's larger side either way: from a field of view
#: of 0.6 degrees to far beyond a fisheye's (fx = fy = 1e-9 ended a run 1.9e11 m away)
FOCAL_FACTOR = 100.0


def resolution(value, path: str | Path | None) -> tuple[int, int]:
    """``resolution: [width, height]`` of a ``cam0/sensor.yaml``: two whole numbers of pixels from 1 to
    :data:`MAX_IMAGE_SIDE` (a fractional one was cut to a whole one without a word), else an :class:`InputError`."""
    try:
        if isinstance(value, (str, bytes)) or len(value) != 2:
            raise ValueError
        pair = [float(v) if not isinstance(v, (bool, str)) else None for v in value]
    except (TypeError, ValueError, OverflowError):
        pair = None
    if pair is None or any(v is None or not np.isfinite(v) or v != int(v) or not 1 <= v <= MAX_IMAGE_SIDE
                           for v in pair):
        raise InputError(f"'resolution' must be [width, height], two whole numbers of pixels from 1 to "
                         f"{MAX_IMAGE_SIDE}, not {value!r}", path)
    return int(pair[0]), int(pair[1])


def focal_length_problem(fu: float, fv: float, size) -> str | None:
    """What is wrong with focal lengths [px] that do not both lie within :data:`FOCAL_FACTOR` of the larger
    side of ``size`` (width, height) either way, or ``None``."""
    side = max(size)
    low, high = side / FOCAL_FACTOR, side * FOCAL_FACTOR
    if low <= fu <= high and low <= fv <= high:
        return None
    return (f"focal lengths {fu:g}, {fv:g} px are not a camera's for a {size[0]}x{size[1]} image (each must be "
            f"between {low:g} and {high:g} px)")


def check_focal_lengths(fu: float, fv: float, size, path: str | Path | None, key: str) -> None:
    """An :class:`InputError` naming ``key`` for focal lengths :func:`focal_length_problem` refuses."""
    problem = focal_length_problem(fu, fv, size)
    if problem:
        raise InputError(f"'{key}' {problem}", path)

#: the keys of each ``sensor.yaml`` the library reads (with EuRoC's ``sensor_type`` and ``comment``), for the
#: warning about a key that is close to one of them (:func:`warn_unknown_keys`)
SENSOR_KEYS = {
    "cam0": ("sensor_type", "comment", "rate_hz", "resolution", "camera_model", "intrinsics", "distortion_model",
             "distortion_coefficients", "T_BS", "height_sigma", "bit_depth", "camera_noise"),
    "imu0": ("sensor_type", "comment", "rate_hz", "T_BS", "gyroscope_noise_density", "gyroscope_random_walk",
             "accelerometer_noise_density", "accelerometer_random_walk"),
    "wheel0": ("sensor_type", "comment", "rate_hz", "ticks_per_revolution", "wheel_radius_left", "wheel_radius_right",
               "wheel_base", "radius_sigma"),
    "gps0": ("sensor_type", "comment", "rate_hz", "T_BS", "horizontal_sigma_m", "datum"),
}


def warn_unknown_keys(data: dict, known, path: str | Path) -> list[str]:
    """Log a warning for each key of ``data`` that is not in ``known`` but close to one of them (a misspelt
    optional key would otherwise be ignored without a word); other keys (EuRoC's ``comment``, a tool's own
    keys) are left alone. Returns the warnings."""
    import difflib
    import logging

    known = list(known)
    out = []
    for key in data:
        if not isinstance(key, str) or key in known:
            continue
        close = difflib.get_close_matches(key, known, n=1, cutoff=0.8)
        if close:
            out.append(f"{path}: unknown key '{key}' (did you mean '{close[0]}'?)")
            logging.getLogger(__name__).warning("%s", out[-1])
    return out


def sensor_number(data: dict, key: str, path: str | Path | None, default: float | None = None, *,
                  zero: bool = False, low: float | None = None, high: float | None = None,
                  unit: str = "") -> float | None:
    """The number ``key`` of a ``sensor.yaml`` (``default`` when absent or null): a YAML boolean, a text that
    is no number, NaN, inf, a negative value (or zero unless ``zero``) or a value outside ``[low, high]``
    is an :class:`InputError` naming the key."""
    value = data.get(key)
    if value is None:
        return default
    try:
        if isinstance(value, bool):
            raise TypeError
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(f"'{key}' must be a number, not {value!r}", path) from None
    if not np.isfinite(x) or x < 0 or (x == 0 and not zero):
        raise InputError(f"'{key}' must be {'non-negative' if zero else 'positive'}, not {x}", path)
    if (low is not None and x < low) or (high is not None and x > high):
        span = f"between {low:g} and {high:g}" if low is not None and high is not None else (
            f"at least {low:g}" if low is not None else f"at most {high:g}")
        raise InputError(f"'{key}' must be {span}{unit}, not {x:g}", path)
    return x


def parse_pose(entry, name: str, path: str | Path | None) -> np.ndarray:
    """A sensor's pose ``T_BS`` (:func:`parse_matrix`): finite numbers, a rotation (orthonormal, det +1,
    no mirror), a translation within :data:`MAX_LEVER_ARM_M` and the bottom row ``[0, 0, 0, 1]``, else an
    :class:`InputError` naming ``name``."""
    m = parse_matrix(entry, name, path)
    if not np.all(np.isfinite(m)):
        raise InputError(f"'{name}' must hold finite numbers (NaN or inf found)", path)
    if not np.allclose(m[3], [0.0, 0.0, 0.0, 1.0], rtol=0, atol=1e-6):  # a homogeneous transform (the row was ignored)
        raise InputError(f"'{name}' bottom row must be [0, 0, 0, 1], not {[float(v) for v in m[3]]}", path)
    R = m[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-5) or abs(np.linalg.det(R) - 1) > 1e-5:
        raise InputError(f"{name} rotation part is not a rotation matrix", path)
    if np.max(np.abs(m[:3, 3])) > MAX_LEVER_ARM_M:
        raise InputError(f"'{name}' translation {np.max(np.abs(m[:3, 3])):g} m is beyond {MAX_LEVER_ARM_M:g} m: "
                         "not a lever arm", path)
    return m


def parse_matrix(entry, name: str, path: str | Path | None) -> np.ndarray:
    """Read a 4x4 matrix given as ``{cols, rows, data}`` (EuRoC) or a nested list."""
    try:
        if isinstance(entry, dict):
            data = np.asarray(entry["data"], dtype=np.float64)
            rows, cols = int(entry.get("rows", 4)), int(entry.get("cols", 4))
            m = data.reshape(rows, cols)
        else:
            m = np.asarray(entry, dtype=np.float64)
        if m.shape != (4, 4):
            raise ValueError
    except (KeyError, TypeError, ValueError):
        raise InputError(f"'{name}' must be a 4x4 matrix (cols: 4, rows: 4, data: [16 numbers])", path) from None
    return m


class _UniqueKeyLoader(yaml.SafeLoader):
    """PyYAML's safe loader, but a key given twice in one mapping is an error (PyYAML keeps the last one:
    a section written twice in a configuration would silently lose the first one's values)."""


def _unique_mapping(loader: yaml.SafeLoader, node: yaml.MappingNode, deep: bool = False):
    seen: dict = {}
    for key_node, _ in node.value:
        if key_node.tag == "tag:yaml.org,2002:merge":
            continue
        key = loader.construct_object(key_node, deep=True)
        try:
            first = seen.setdefault(key, key_node.start_mark.line)
        except TypeError:  # an unhashable key: PyYAML's own error follows
            continue
        if first != key_node.start_mark.line:
            raise yaml.constructor.ConstructorError(
                None, None, f"key '{key}' given twice (first on line {first + 1})", key_node.start_mark)
    return loader.construct_mapping(node, deep=deep)


def _bounded_int(loader: yaml.SafeLoader, node: yaml.ScalarNode) -> int:
    """A YAML integer; one beyond Python's limit on converting digits (4300) is an error at its line, not an
    exception from deep inside the loader."""
    try:
        return loader.construct_yaml_int(node)
    except ValueError:
        raise yaml.constructor.ConstructorError(
            None, None, f"an integer of {len(str(node.value))} characters is no setting", node.start_mark) from None


_UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _unique_mapping)
_UniqueKeyLoader.add_constructor("tag:yaml.org,2002:int", _bounded_int)


def load_yaml_text(text: str):
    """Load YAML text with the loader of :func:`load_yaml` (a key given twice and an integer too long to
    convert are :class:`yaml.YAMLError`)."""
    return yaml.load(text, Loader=_UniqueKeyLoader)  # noqa: S506 (a SafeLoader)


def load_yaml(path: str | Path) -> dict:
    """Load a YAML mapping, with :class:`InputError` for a missing, unreadable or malformed file."""
    path = check_file(path)
    try:
        with open(path, encoding="utf-8") as f:
            text = f.read()
        # EuRoC files start with a '%YAML:1.0' directive that PyYAML does not accept
        if text.startswith("%YAML:"):
            text = text.split("\n", 1)[1] if "\n" in text else ""
        data = load_yaml_text(text)
    except yaml.YAMLError as exc:
        line = getattr(getattr(exc, "problem_mark", None), "line", None)
        raise InputError(f"not valid YAML ({getattr(exc, 'problem', exc)})", path, None if line is None else line + 1) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read file ({exc})", path) from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise InputError("expected a YAML mapping of keys to values", path)
    return data


def write_yaml_atomic(path: str | Path, data: dict) -> None:
    """Write a YAML file under a temporary name, then rename it into place (mode from the umask)."""
    path = Path(path)
    make_folder(path.parent)
    write_atomic(path, yaml.safe_dump(data, sort_keys=False, default_flow_style=None))
