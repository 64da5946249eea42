"""Import a ROS bag (ROS 1 ``.bag``, ROS 2 folder, ``.mcap`` or ``.db3``) into the recording layout.

The bag is read with :class:`rosbags.highlevel.AnyReader`; messages are decoded with the bag's own
message definitions, or with a ROS 2 typestore when the bag carries none. Each supported topic becomes
one stream of the recording folder::

    sensor_msgs/Image, CompressedImage  ->  cam0/data.csv + cam0/data/<t>.png (grey, 8 or 16 bit)
    sensor_msgs/CameraInfo              ->  cam0/sensor.yaml (unless --camera-yaml is given)
    sensor_msgs/Imu                     ->  imu0/data.csv (+ q_RS_w,x,y,z when the IMU gives an orientation)
    nav_msgs/Odometry                   ->  odom0/data.csv (body twist) and odom0/pose.csv (its pose)
    sensor_msgs/NavSatFix               ->  gps0/data.csv (latitude, longitude, altitude, local ENU)
    tf2_msgs/TFMessage on /tf_static    ->  T_BS of imu0, cam0 and gps0

Time
----
A sample's time is its header stamp ``sec * 10^9 + nanosec`` [ns]; a zero stamp falls back to the time
the bag recorded the message. Each stream is sorted by time; a sample whose stamp equals an earlier one
of the same stream is dropped (the first one in bag order is kept) and counted.

Local ENU of GPS fixes
----------------------
Geodetic latitude ``φ``, longitude ``λ`` and ellipsoidal height ``h`` go to Earth-centred coordinates on
the WGS-84 ellipsoid (``a = 6378137 m``, ``f = 1/298.257223563``, ``e² = f (2 - f)``)::

    N(φ) = a / sqrt(1 - e² sin² φ)
    X = (N + h) cos φ cos λ,   Y = (N + h) cos φ sin λ,   Z = (N (1 - e²) + h) sin φ

and are rotated into East-North-Up at the first fix ``(φ0, λ0, h0)``::

    [e]   [ -sin λ0          cos λ0          0      ]
    [n] = [ -sin φ0 cos λ0  -sin φ0 sin λ0   cos φ0 ] (X - X0)
    [u]   [  cos φ0 cos λ0   cos φ0 sin λ0   sin φ0 ]

Extrinsics
----------
``/tf_static`` transforms (and any given with ``static_tfs``, in ``static_transform_publisher`` order
``x y z yaw pitch roll parent child``) form a tree; ``T_BS`` of a sensor is the chain of transforms from
the body frame (the odometry's ``child_frame_id``, else ``base_link``) to the sensor message's
``frame_id``. Rotations from yaw, pitch, roll are ``R = Rz(yaw) Ry(pitch) Rx(roll)``.

The output is written to a temporary folder next to the target and renamed into place only when
complete, so an interrupted import never leaves a folder that looks like a finished recording.
"""

from __future__ import annotations

import logging
import math
import os
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Sequence

import cv2
import numpy as np
import yaml

from fusion_vo.errors import InputError
from fusion_vo.geometry.camera import CameraModel, load_yaml

log = logging.getLogger(__name__)

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
IMU = "sensor_msgs/msg/Imu"
ODOMETRY = "nav_msgs/msg/Odometry"
NAV_SAT_FIX = "sensor_msgs/msg/NavSatFix"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"

#: stream name -> (message types it accepts, command-line option that selects its topic)
STREAM_TYPES: dict[str, tuple[tuple[str, ...], str]] = {
    "cam0": ((IMAGE, COMPRESSED_IMAGE), "--image-topic"),
    "imu0": ((IMU,), "--imu-topic"),
    "odom0": ((ODOMETRY,), "--odom-topic"),
    "gps0": ((NAV_SAT_FIX,), "--gps-topic"),
}

#: sensor_msgs/Image encoding -> (numpy dtype, channels, OpenCV conversion to grey or None)
IMAGE_ENCODINGS: dict[str, tuple[str, int, int | None]] = {
    "mono8": ("u1", 1, None),
    "8uc1": ("u1", 1, None),
    "mono16": ("u2", 1, None),
    "16uc1": ("u2", 1, None),
    "bgr8": ("u1", 3, cv2.COLOR_BGR2GRAY),
    "8uc3": ("u1", 3, cv2.COLOR_BGR2GRAY),
    "rgb8": ("u1", 3, cv2.COLOR_RGB2GRAY),
    "bgra8": ("u1", 4, cv2.COLOR_BGRA2GRAY),
    "8uc4": ("u1", 4, cv2.COLOR_BGRA2GRAY),
    "rgba8": ("u1", 4, cv2.COLOR_RGBA2GRAY),
    "bgr16": ("u2", 3, cv2.COLOR_BGR2GRAY),
    "16uc3": ("u2", 3, cv2.COLOR_BGR2GRAY),
    "rgb16": ("u2", 3, cv2.COLOR_RGB2GRAY),
    "bgra16": ("u2", 4, cv2.COLOR_BGRA2GRAY),
    "rgba16": ("u2", 4, cv2.COLOR_RGBA2GRAY),
    "bayer_rggb8": ("u1", 1, cv2.COLOR_BayerRGGB2GRAY),
    "bayer_bggr8": ("u1", 1, cv2.COLOR_BayerBGGR2GRAY),
    "bayer_gbrg8": ("u1", 1, cv2.COLOR_BayerGBRG2GRAY),
    "bayer_grbg8": ("u1", 1, cv2.COLOR_BayerGRBG2GRAY),
    "uyvy": ("u1", 2, cv2.COLOR_YUV2GRAY_UYVY),
    "yuv422": ("u1", 2, cv2.COLOR_YUV2GRAY_UYVY),
    "yuyv": ("u1", 2, cv2.COLOR_YUV2GRAY_YUY2),
    "yuv422_yuy2": ("u1", 2, cv2.COLOR_YUV2GRAY_YUY2),
}

WGS84_A = 6378137.0
WGS84_F = 1.0 / 298.257223563
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)


# ---------------------------------------------------------------------------------------- results
@dataclass(frozen=True)
class BagTopic:
    """One topic of a bag: its name, message type (``pkg/msg/Type``) and message count."""

    topic: str
    msgtype: str
    count: int


@dataclass
class StreamSummary:
    """What became of one imported topic.

    Attributes
    ----------
    stream : str
        Folder of the recording (``cam0``, ``imu0``, ``odom0``, ``gps0``).
    topic, msgtype : str
        Source topic and its message type.
    messages : int
        Messages read from the bag.
    written : int
        Rows written.
    duplicates : int
        Samples dropped because an earlier sample of the stream had the same timestamp.
    dropped : int
        Samples dropped as unusable (non-finite values, undecodable image, GPS without a fix).
    bag_time_stamps : int
        Samples whose header stamp was zero and that took the bag's record time instead.
    rate_hz : float or None
        Rate measured from the written timestamps (inverse of the median interval).
    t_first_ns, t_last_ns : int
        First and last written timestamp.
    """

    stream: str
    topic: str
    msgtype: str
    messages: int = 0
    written: int = 0
    duplicates: int = 0
    dropped: int = 0
    bag_time_stamps: int = 0
    rate_hz: float | None = None
    t_first_ns: int = 0
    t_last_ns: int = 0

    @property
    def duration_s(self) -> float:
        return (self.t_last_ns - self.t_first_ns) * 1e-9


@dataclass
class ImportSummary:
    """Result of :func:`import_bag`: the output folder, one :class:`StreamSummary` per stream, notes."""

    bag: Path
    out: Path
    topics: list[BagTopic]
    streams: list[StreamSummary] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def stream(self, name: str) -> StreamSummary | None:
        """The summary of stream ``name`` (``"imu0"`` ...), or ``None`` when it was not imported."""
        return next((s for s in self.streams if s.stream == name), None)


@dataclass(frozen=True)
class StaticTransform:
    """A fixed transform: pose of frame ``child`` in frame ``parent`` as a 4x4 matrix ``T``."""

    parent: str
    child: str
    T: np.ndarray


# ---------------------------------------------------------------------------------------- geometry
def geodetic_to_enu(lat_deg, lon_deg, alt_m, lat0_deg: float, lon0_deg: float, alt0_m: float) -> np.ndarray:
    """East, north, up [m] of WGS-84 positions relative to a reference position (module docstring).

    Parameters
    ----------
    lat_deg, lon_deg, alt_m : array_like, shape (N,)
        Latitude and longitude [deg], ellipsoidal altitude [m].
    lat0_deg, lon0_deg, alt0_m : float
        The reference (origin of the local frame).

    Returns
    -------
    ndarray, shape (N, 3)
        ``(e, n, u)`` per position.
    """
    xyz = _geodetic_to_ecef(np.asarray(lat_deg, float), np.asarray(lon_deg, float), np.asarray(alt_m, float))
    xyz0 = _geodetic_to_ecef(np.array([lat0_deg]), np.array([lon0_deg]), np.array([alt0_m]))
    phi, lam = math.radians(lat0_deg), math.radians(lon0_deg)
    sp, cp, sl, cl = math.sin(phi), math.cos(phi), math.sin(lam), math.cos(lam)
    R = np.array([[-sl, cl, 0.0], [-sp * cl, -sp * sl, cp], [cp * cl, cp * sl, sp]])
    return (xyz - xyz0) @ R.T


def _geodetic_to_ecef(lat_deg: np.ndarray, lon_deg: np.ndarray, alt_m: np.ndarray) -> np.ndarray:
    phi, lam = np.radians(lat_deg), np.radians(lon_deg)
    n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * np.sin(phi) ** 2)
    return np.column_stack([
        (n + alt_m) * np.cos(phi) * np.cos(lam),
        (n + alt_m) * np.cos(phi) * np.sin(lam),
        (n * (1.0 - WGS84_E2) + alt_m) * np.sin(phi),
    ])


def quat_to_matrix(w: float, x: float, y: float, z: float) -> np.ndarray:
    """Rotation matrix of a (normalised) quaternion ``w + xi + yj + zk``."""
    q = np.array([w, x, y, z], dtype=float)
    n = np.linalg.norm(q)
    if not np.isfinite(n) or n < 1e-9:
        raise ValueError("zero or non-finite quaternion")
    w, x, y, z = q / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def ypr_to_matrix(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """``Rz(yaw) Ry(pitch) Rx(roll)``, the rotation of ``static_transform_publisher x y z yaw pitch roll``."""
    cy, sy, cp, sp, cr, sr = (math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch),
                              math.cos(roll), math.sin(roll))
    Rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    Ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    return Rz @ Ry @ Rx


def parse_static_tf(text: str) -> StaticTransform:
    """Parse ``"x y z yaw pitch roll parent child"`` (or ``"x y z qx qy qz qw parent child"``).

    The order is that of ROS's ``static_transform_publisher``, so a line of a launch file can be pasted.
    """
    parts = text.replace(",", " ").split()
    if len(parts) not in (8, 9):
        raise InputError(f"--static-tf '{text}': expected 'x y z yaw pitch roll parent child' "
                         "or 'x y z qx qy qz qw parent child'")
    try:
        nums = [float(p) for p in parts[:-2]]
    except ValueError:
        raise InputError(f"--static-tf '{text}': the first {len(parts) - 2} fields must be numbers") from None
    if not all(math.isfinite(v) for v in nums):
        raise InputError(f"--static-tf '{text}': values must be finite")
    T = np.eye(4)
    T[:3, 3] = nums[:3]
    if len(nums) == 6:
        T[:3, :3] = ypr_to_matrix(*nums[3:6])
    else:
        try:
            T[:3, :3] = quat_to_matrix(nums[6], nums[3], nums[4], nums[5])
        except ValueError:
            raise InputError(f"--static-tf '{text}': zero quaternion") from None
    return StaticTransform(_frame(parts[-2]), _frame(parts[-1]), T)


def chain_transform(transforms: Iterable[StaticTransform], target: str, source: str) -> np.ndarray | None:
    """Pose of frame ``source`` in frame ``target`` from a set of fixed transforms, or ``None``.

    The transforms are edges of an undirected graph (walked backwards through their inverse); the
    first path found breadth-first is used.
    """
    target, source = _frame(target), _frame(source)
    if target == source:
        return np.eye(4)
    edges: dict[str, list[tuple[str, np.ndarray]]] = {}
    for tf in transforms:
        edges.setdefault(tf.parent, []).append((tf.child, tf.T))
        edges.setdefault(tf.child, []).append((tf.parent, _inverse(tf.T)))
    best = {target: np.eye(4)}
    queue = [target]
    while queue:
        frame = queue.pop(0)
        for nxt, T in edges.get(frame, []):
            if nxt not in best:
                best[nxt] = best[frame] @ T
                if nxt == source:
                    return best[nxt]
                queue.append(nxt)
    return None


def _inverse(T: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = T[:3, :3].T
    out[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return out


def _frame(name: str) -> str:
    return name.strip().lstrip("/")


# ---------------------------------------------------------------------------------------- images
class UnsupportedImage(ValueError):
    """An image format the import cannot convert (as opposed to one damaged message)."""


def image_to_grey(msg) -> np.ndarray:
    """Grey ``uint8``/``uint16`` image of a ``sensor_msgs/Image`` message.

    Raises
    ------
    UnsupportedImage
        For an encoding that is not in :data:`IMAGE_ENCODINGS`.
    ValueError
        For a data buffer that does not match width, height and step.
    """
    enc = str(msg.encoding).strip().lower()
    if enc not in IMAGE_ENCODINGS:
        raise UnsupportedImage(f"image encoding '{msg.encoding}' is not supported "
                         f"(supported: {', '.join(sorted(IMAGE_ENCODINGS))})")
    kind, channels, code = IMAGE_ENCODINGS[enc]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    itemsize = 2 if kind == "u2" else 1
    row_bytes = w * channels * itemsize
    buf = np.asarray(msg.data, dtype=np.uint8).reshape(-1)
    if h <= 0 or w <= 0 or step < row_bytes or buf.size < h * step:
        raise ValueError(f"image data of {buf.size} bytes does not fit {w}x{h} {enc} with step {step}")
    raw = np.ascontiguousarray(buf[: h * step].reshape(h, step)[:, :row_bytes])
    if itemsize == 2:
        raw = raw.view(np.dtype((">" if msg.is_bigendian else "<") + "u2")).astype(np.uint16)
    img = raw.reshape(h, w, channels) if channels > 1 else raw.reshape(h, w)
    if code is not None:
        img = cv2.cvtColor(img, code)
    return np.ascontiguousarray(img)


def compressed_to_grey(msg) -> np.ndarray:
    """Grey image of a ``sensor_msgs/CompressedImage`` message (JPEG, PNG, ... via ``cv2.imdecode``).

    Raises
    ------
    UnsupportedImage
        For ``compressedDepth`` images.
    ValueError
        When the data cannot be decoded.
    """
    fmt = str(msg.format).lower()
    if "compresseddepth" in fmt:
        raise UnsupportedImage(f"compressed depth images ('{msg.format}') are not supported")
    data = np.asarray(msg.data, dtype=np.uint8).reshape(-1)
    img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    if img is None:
        raise ValueError(f"cannot decode compressed image (format '{msg.format}')")
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY)
    if img.dtype not in (np.uint8, np.uint16):
        raise UnsupportedImage(f"pixel type {img.dtype} is not supported")
    return img


# ---------------------------------------------------------------------------------------- reading
def open_reader(bag: str | Path):
    """An unopened :class:`~rosbags.highlevel.AnyReader` for ``bag`` (ROS 1 file, ROS 2 folder or file)."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    bag = Path(bag)
    if not bag.exists():
        raise InputError("bag not found", bag)
    try:
        return AnyReader([bag], default_typestore=get_typestore(Stores.LATEST))
    except Exception as exc:  # rosbags raises several error types for unreadable input
        raise InputError(f"not a readable ROS bag ({_one_line(exc)})", bag) from None


def list_topics(bag: str | Path) -> list[BagTopic]:
    """Topics of a bag with their message types and counts, sorted by name."""
    with _opened(bag) as reader:
        return _topics(reader)


class _opened:
    """Context manager opening a bag with :class:`InputError` for anything unreadable."""

    def __init__(self, bag: str | Path):
        self.bag = Path(bag)
        self.reader = open_reader(self.bag)

    def __enter__(self):
        try:
            self.reader.open()
        except Exception as exc:
            raise InputError(f"not a readable ROS bag ({_one_line(exc)})", self.bag) from None
        return self.reader

    def __exit__(self, *exc) -> bool:
        try:
            self.reader.close()
        except Exception:  # closing a half-read corrupt bag may fail again; the first error matters
            pass
        return False


def _topics(reader) -> list[BagTopic]:
    counts: dict[tuple[str, str], int] = {}
    for c in reader.connections:
        counts[(c.topic, c.msgtype)] = counts.get((c.topic, c.msgtype), 0) + c.msgcount
    return [BagTopic(t, m, n) for (t, m), n in sorted(counts.items())]


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) < 200 else text[:197] + "..."


def select_topics(topics: Sequence[BagTopic], requested: dict[str, str | None], bag: Path) -> dict[str, BagTopic]:
    """Choose the topic of each stream.

    A requested topic must exist and carry a supported type for its stream. A stream without a request
    takes the single topic of its types; none means the stream is absent; several are ambiguous.

    Parameters
    ----------
    topics : the bag's topics.
    requested : stream name (``cam0``, ``imu0``, ``odom0``, ``gps0``) -> topic or ``None``.
    bag : the bag, for error messages.
    """
    by_name = {t.topic: t for t in topics}
    chosen: dict[str, BagTopic] = {}
    for stream, (types, option) in STREAM_TYPES.items():
        want = requested.get(stream)
        if want:
            name = want if want in by_name else "/" + want.lstrip("/")
            if name not in by_name:
                raise InputError(f"{option} {want}: no such topic in the bag (topics: "
                                 f"{', '.join(t.topic for t in topics) or 'none'})", bag)
            if by_name[name].msgtype not in types:
                raise InputError(f"{option} {want}: topic carries {by_name[name].msgtype}, "
                                 f"expected {' or '.join(types)}", bag)
            chosen[stream] = by_name[name]
            continue
        found = [t for t in topics if t.msgtype in types]
        if len(found) > 1:
            raise InputError(f"several topics could be {stream} ({', '.join(t.topic for t in found)}); "
                             f"choose one with {option}", bag)
        if found:
            chosen[stream] = found[0]
    return chosen


def _stamp(header, bag_t: int) -> tuple[int, bool]:
    t = int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
    return (t, False) if t > 0 else (int(bag_t), True)


# ---------------------------------------------------------------------------------------- streams
class _Rows:
    """Samples of one stream in bag order; sorted and de-duplicated on :meth:`finish`."""

    def __init__(self, summary: StreamSummary):
        self.summary = summary
        self.t: list[int] = []
        self.values: list[tuple] = []

    def add(self, t: int, values: tuple) -> None:
        self.t.append(t)
        self.values.append(values)

    def finish(self) -> tuple[np.ndarray, list[tuple]]:
        t = np.asarray(self.t, dtype=np.int64)
        order = np.argsort(t, kind="stable")
        t = t[order]
        keep = np.ones(len(t), dtype=bool)
        keep[1:] = t[1:] != t[:-1]
        self.summary.duplicates += int((~keep).sum())
        idx = order[keep]
        t = t[keep]
        _measure(self.summary, t)
        return t, [self.values[i] for i in idx]


def _measure(summary: StreamSummary, t: np.ndarray) -> None:
    summary.written = len(t)
    if len(t):
        summary.t_first_ns, summary.t_last_ns = int(t[0]), int(t[-1])
    if len(t) > 1:
        dt = np.median(np.diff(t)) * 1e-9
        summary.rate_hz = round(float(1.0 / dt), 3) if dt > 0 else None


def _write_csv(path: Path, header: str, t: np.ndarray, rows: Sequence[Sequence], fmt: str | Sequence[str]) -> None:
    """Write ``timestamp,v1,v2,...`` rows; ``fmt`` is one %-format for all values or one per column."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", encoding="utf-8") as f:
        f.write(header + "\n")
        for ti, row in zip(t, rows):
            fmts = [fmt] * len(row) if isinstance(fmt, str) else fmt
            f.write(f"{int(ti)}," + ",".join(fm % v for fm, v in zip(fmts, row)) + "\n")


def _finite(values: Sequence[float]) -> bool:
    return all(math.isfinite(v) for v in values)


def _yaml_text(comments: Sequence[str], data: dict) -> str:
    head = "".join(f"# {c}\n" for c in comments)
    return head + yaml.safe_dump(data, sort_keys=False, default_flow_style=None)


def _matrix_entry(T: np.ndarray) -> dict:
    return {"cols": 4, "rows": 4, "data": [round(float(v), 9) + 0.0 for v in T.ravel()]}


# ---------------------------------------------------------------------------------------- import
def import_bag(
    bag: str | Path,
    out: str | Path,
    *,
    image_topic: str | None = None,
    imu_topic: str | None = None,
    odom_topic: str | None = None,
    gps_topic: str | None = None,
    camera_yaml: str | Path | None = None,
    static_tfs: Sequence[StaticTransform] = (),
    overwrite: bool = False,
) -> ImportSummary:
    """Write the recording folder ``out`` from the supported topics of ``bag``.

    Parameters
    ----------
    bag : path of a ROS 1 ``.bag`` file, a ROS 2 bag folder, or a ROS 2 ``.mcap``/``.db3`` file.
    out : the recording folder to create.
    image_topic, imu_topic, odom_topic, gps_topic : topic of each stream; when ``None`` the single topic
        of the stream's message type is taken (none: the stream is left out; several: an error).
    camera_yaml : a ``cam0/sensor.yaml`` to use instead of the bag's ``CameraInfo``.
    static_tfs : fixed transforms to add to the bag's ``/tf_static`` (see :func:`parse_static_tf`).
    overwrite : replace ``out`` if it exists.

    Returns
    -------
    ImportSummary

    Raises
    ------
    InputError
        For a missing or unreadable bag, an unknown topic or one of the wrong type, an existing ``out``
        without ``overwrite``, or a bag without any supported topic.
    """
    bag, out = Path(bag), Path(out)
    _check_target(out, overwrite)
    cam_yaml = load_yaml(camera_yaml) if camera_yaml is not None else None
    with _opened(bag) as reader:
        topics = _topics(reader)
        requested = {"cam0": image_topic, "imu0": imu_topic, "odom0": odom_topic, "gps0": gps_topic}
        chosen = select_topics(topics, requested, bag)
        if not chosen:
            raise InputError("no supported topic (sensor_msgs/Image, CompressedImage, Imu, NavSatFix, "
                             f"nav_msgs/Odometry); topics: {', '.join(t.topic for t in topics) or 'none'}", bag)
        if cam_yaml is not None and "cam0" not in chosen:
            raise InputError("--camera-yaml given but the bag has no image topic", bag)
        summary = ImportSummary(bag, out, topics)
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".part", dir=out.parent))
        try:
            _Importer(reader, bag, tmp, chosen, topics, cam_yaml, camera_yaml, list(static_tfs), summary).run()
            _move_into_place(tmp, out, overwrite)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
    for s in summary.streams:
        log.debug("%s <- %s: %d rows, %.1f Hz, %d duplicates, %d dropped", s.stream, s.topic, s.written,
                 s.rate_hz or 0.0, s.duplicates, s.dropped)
    for note in summary.notes:
        log.debug("note: %s", note)
    return summary


def _check_target(out: Path, overwrite: bool) -> None:
    if out.exists() and not out.is_dir():
        raise InputError("output exists and is not a folder", out)
    if out.is_dir() and any(out.iterdir()) and not overwrite:
        raise InputError("output folder exists and is not empty (use --force to replace it)", out)


def _move_into_place(tmp: Path, out: Path, overwrite: bool) -> None:
    if out.exists():
        _check_target(out, overwrite)
        old = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".old", dir=out.parent))
        os.replace(out, old / out.name)
        os.replace(tmp, out)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(tmp, out)


class _Importer:
    """One pass over the bag's selected topics, writing into the temporary folder ``root``."""

    def __init__(self, reader, bag: Path, root: Path, chosen: dict[str, BagTopic], topics: list[BagTopic],
                 cam_yaml: dict | None, cam_yaml_path, static_tfs: list[StaticTransform], summary: ImportSummary):
        self.reader, self.bag, self.root = reader, bag, root
        self.chosen, self.summary = chosen, summary
        self.cam_yaml, self.cam_yaml_path = cam_yaml, cam_yaml_path
        self.transforms = list(static_tfs)
        self.frames: dict[str, str] = {}  # stream -> frame_id of its messages
        self.body_frame: str | None = None
        self.rows = {name: _Rows(StreamSummary(name, t.topic, t.msgtype)) for name, t in chosen.items()}
        self.image_size: tuple[int, int] | None = None
        self.written_images: set[int] = set()
        self.imu_missing_orientation = 0
        self.imu_covariance: dict[str, list[float]] = {"gyro": [], "accel": []}
        self.gps_sigma: list[float] = []
        self.camera_info = None
        self.caminfo_topic = _pick_camera_info(topics, chosen.get("cam0")) if cam_yaml is None else None
        self.tf_topics = [t.topic for t in topics if t.msgtype == TF_MESSAGE and _frame(t.topic) == "tf_static"]

    # -------------------------------------------------------------- main loop
    def run(self) -> None:
        wanted = {t.topic: name for name, t in self.chosen.items()}
        extra = set(self.tf_topics) | ({self.caminfo_topic} if self.caminfo_topic else set())
        conns = [c for c in self.reader.connections if c.topic in wanted or c.topic in extra]
        handlers = {"cam0": self._image, "imu0": self._imu, "odom0": self._odom, "gps0": self._gps}
        for conn, bag_t, msg in self._messages(conns):
            if conn.topic in wanted:
                name = wanted[conn.topic]
                self.rows[name].summary.messages += 1
                handlers[name](msg, bag_t)
            elif conn.msgtype == TF_MESSAGE:
                self._tf(msg)
            elif self.camera_info is None and conn.msgtype == CAMERA_INFO and float(msg.k[0]) > 0:
                self.camera_info = msg
        self.body_frame = self.body_frame or "base_link"
        for name in self.chosen:
            getattr(self, f"_finish_{name}")()
            self.summary.streams.append(self.rows[name].summary)

    def _messages(self, conns):
        """Decoded ``(connection, bag time, message)`` in bag order; a damaged bag is an InputError."""
        stream = iter(self.reader.messages(connections=conns))
        while True:
            try:
                conn, bag_t, raw = next(stream)
                msg = self.reader.deserialize(raw, conn.msgtype)
            except StopIteration:
                return
            except Exception as exc:  # damaged chunks fail in rosbags or its decompressors, in many ways
                raise InputError(f"cannot read the bag ({_one_line(exc)})", self.bag) from None
            yield conn, bag_t, msg

    def _header_time(self, name: str, msg, bag_t: int) -> int:
        t, fallback = _stamp(msg.header, bag_t)
        if fallback:
            self.rows[name].summary.bag_time_stamps += 1
        if name not in self.frames and msg.header.frame_id:
            self.frames[name] = _frame(msg.header.frame_id)
        return t

    # -------------------------------------------------------------- per message
    def _image(self, msg, bag_t: int) -> None:
        rows = self.rows["cam0"]
        t = self._header_time("cam0", msg, bag_t)
        if t in self.written_images:
            rows.summary.duplicates += 1  # the first image with this stamp is kept
            return
        try:
            img = image_to_grey(msg) if rows.summary.msgtype == IMAGE else compressed_to_grey(msg)
        except UnsupportedImage as exc:
            raise InputError(f"{rows.summary.topic}: {exc}", self.bag) from None
        except ValueError as exc:
            rows.summary.dropped += 1
            log.warning("%s: image at %d ns skipped: %s", rows.summary.topic, t, exc)
            return
        size = (img.shape[1], img.shape[0])
        if self.image_size is None:
            self.image_size = size
        elif size != self.image_size:
            rows.summary.dropped += 1
            log.warning("%s: image at %d ns is %dx%d, not %dx%d like the first; skipped", rows.summary.topic, t,
                        *size, *self.image_size)
            return
        path = self.root / "cam0" / "data" / f"{t}.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        if not cv2.imwrite(str(path), img):
            raise InputError("cannot write image", path)
        self.written_images.add(t)
        rows.add(t, (path.name,))

    def _imu(self, msg, bag_t: int) -> None:
        rows = self.rows["imu0"]
        t = self._header_time("imu0", msg, bag_t)
        w, a, q = msg.angular_velocity, msg.linear_acceleration, msg.orientation
        values = (float(w.x), float(w.y), float(w.z), float(a.x), float(a.y), float(a.z))
        if not _finite(values):
            rows.summary.dropped += 1
            return
        quat = (float(q.w), float(q.x), float(q.y), float(q.z))
        has_q = float(msg.orientation_covariance[0]) != -1.0 and _finite(quat) and \
            abs(math.sqrt(sum(v * v for v in quat)) - 1.0) < 0.05
        if not has_q:
            self.imu_missing_orientation += 1
        rows.add(t, values + (quat if has_q else None,))
        if len(self.imu_covariance["gyro"]) < 1000:
            self.imu_covariance["gyro"].append(float(msg.angular_velocity_covariance[0]))
            self.imu_covariance["accel"].append(float(msg.linear_acceleration_covariance[0]))

    def _odom(self, msg, bag_t: int) -> None:
        rows = self.rows["odom0"]
        t = self._header_time("odom0", msg, bag_t)
        if self.body_frame is None and msg.child_frame_id:
            self.body_frame = _frame(msg.child_frame_id)
        tw, p = msg.twist.twist, msg.pose.pose
        twist = (float(tw.linear.x), float(tw.linear.y), float(tw.angular.z))
        pose = (float(p.position.x), float(p.position.y), float(p.position.z), float(p.orientation.w),
                float(p.orientation.x), float(p.orientation.y), float(p.orientation.z))
        if not _finite(twist):
            rows.summary.dropped += 1
            return
        rows.add(t, (twist, pose if _finite(pose) and any(pose[3:]) else None))

    def _gps(self, msg, bag_t: int) -> None:
        rows = self.rows["gps0"]
        t = self._header_time("gps0", msg, bag_t)
        fix = (float(msg.latitude), float(msg.longitude), float(msg.altitude))
        if int(msg.status.status) < 0 or not _finite(fix) or abs(fix[0]) > 90 or abs(fix[1]) > 180:
            rows.summary.dropped += 1
            return
        rows.add(t, fix)
        if int(msg.position_covariance_type) > 0:
            cov = msg.position_covariance
            self.gps_sigma.append(math.sqrt(max(0.0, 0.5 * (float(cov[0]) + float(cov[4])))))

    def _tf(self, msg) -> None:
        for ts in msg.transforms:
            tr, rq = ts.transform.translation, ts.transform.rotation
            T = np.eye(4)
            try:
                T[:3, :3] = quat_to_matrix(float(rq.w), float(rq.x), float(rq.y), float(rq.z))
            except ValueError:
                continue
            T[:3, 3] = [float(tr.x), float(tr.y), float(tr.z)]
            self.transforms.append(StaticTransform(_frame(ts.header.frame_id), _frame(ts.child_frame_id), T))

    # -------------------------------------------------------------- finishing
    def _extrinsics(self, stream: str) -> tuple[np.ndarray | None, str]:
        frame = self.frames.get(stream)
        if frame is None:
            return None, "its messages name no frame_id"
        if frame == self.body_frame:
            return np.eye(4), f"identity: the messages are in the body frame '{frame}'"
        T = chain_transform(self.transforms, self.body_frame, frame)
        if T is None:
            return None, f"no fixed transform from '{self.body_frame}' to '{frame}'"
        return T, f"from the fixed transforms '{self.body_frame}' -> '{frame}'"

    def _finish_cam0(self) -> None:
        rows = self.rows["cam0"]
        t, values = rows.finish()
        _write_csv(self.root / "cam0" / "data.csv", "#timestamp [ns],filename", t, values, "%s")
        if not len(t):
            self.summary.notes.append(f"{rows.summary.topic}: no usable image")
            return
        T, how = self._extrinsics("cam0")
        data: dict
        if self.cam_yaml is not None:
            data = dict(self.cam_yaml)
            data.setdefault("rate_hz", rows.summary.rate_hz)
            data.setdefault("resolution", list(self.image_size))
            source = f"from {self.cam_yaml_path}"
            if "T_BS" not in data and T is not None:
                data["T_BS"] = _matrix_entry(T)
        elif self.camera_info is not None:
            data = _camera_info_yaml(self.camera_info, rows.summary.rate_hz, self.summary.notes)
            source = f"from {self.caminfo_topic}"
            if T is not None:
                data["T_BS"] = _matrix_entry(T)
        else:
            self.summary.notes.append("cam0/sensor.yaml not written: the bag has no CameraInfo topic; "
                                      "give --camera-yaml")
            return
        if "T_BS" not in data:
            self.summary.notes.append(f"cam0 T_BS unknown ({how}): the default mounting (looking straight "
                                      "down, 0.25 m ahead of the axle, 0.1 m up) was written; edit it")
        model = CameraModel.from_dict(data, self.cam_yaml_path or self.bag)
        if (model.width, model.height) != tuple(self.image_size):
            raise InputError(f"camera calibration is for {model.width}x{model.height} but the images are "
                             f"{self.image_size[0]}x{self.image_size[1]}", self.cam_yaml_path or self.bag)
        text = _yaml_text([f"camera of {rows.summary.topic} ({rows.summary.msgtype}), calibration {source}",
                           f"T_BS {how}" if "T_BS" in data else "T_BS: default mounting, not from the bag"],
                          model.to_dict())
        (self.root / "cam0" / "sensor.yaml").write_text(text, encoding="utf-8")

    def _finish_imu0(self) -> None:
        rows = self.rows["imu0"]
        t, values = rows.finish()
        with_q = bool(values) and all(v[6] is not None for v in values)
        header = ("#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
                  "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]")
        if with_q:
            header += ",q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []"
            table = [v[:6] + v[6] for v in values]
        else:
            table = [v[:6] for v in values]
            if any(v[6] is not None for v in values):
                self.summary.notes.append(f"{rows.summary.topic}: {self.imu_missing_orientation} messages "
                                          "without an orientation; the quaternion columns were left out")
        _write_csv(self.root / "imu0" / "data.csv", header, t, table, "%.9g")
        T, how = self._extrinsics("imu0")
        comments = [f"IMU of {rows.summary.topic}, frame '{self.frames.get('imu0', '')}'"]
        if T is None:
            T = np.eye(4)
            comments.append(f"T_BS is the identity: {how}; edit it if the IMU is not aligned with the body")
            self.summary.notes.append(f"imu0 T_BS set to the identity ({how})")
        else:
            comments.append(f"T_BS {how}")
        data = {"sensor_type": "imu", "rate_hz": rows.summary.rate_hz, "T_BS": _matrix_entry(T)}
        rate = rows.summary.rate_hz or 0.0
        for key, name in (("gyroscope_noise_density", "gyro"), ("accelerometer_noise_density", "accel")):
            var = [v for v in self.imu_covariance[name] if v > 0]
            if var and rate > 0:
                data[key] = float(f"{math.sqrt(float(np.median(var)) / rate):.6g}")
        if len(data) > 3:
            comments.append("noise densities = sqrt(message covariance / rate_hz)")
        (self.root / "imu0" / "sensor.yaml").write_text(_yaml_text(comments, data), encoding="utf-8")

    def _finish_odom0(self) -> None:
        rows = self.rows["odom0"]
        t, values = rows.finish()
        _write_csv(self.root / "odom0" / "data.csv",
                   "#timestamp [ns],v_x [m s^-1],v_y [m s^-1],w_z [rad s^-1]", t, [v[0] for v in values], "%.9g")
        poses = [(ti, v[1]) for ti, v in zip(t, values) if v[1] is not None]
        _write_csv(self.root / "odom0" / "pose.csv",
                   "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []",
                   np.array([p[0] for p in poses], dtype=np.int64), [p[1] for p in poses], "%.9g")

    def _finish_gps0(self) -> None:
        rows = self.rows["gps0"]
        t, values = rows.finish()
        fixes = np.array(values, dtype=float).reshape(-1, 3)
        enu = geodetic_to_enu(fixes[:, 0], fixes[:, 1], fixes[:, 2], *fixes[0]) if len(fixes) else fixes
        table = [(*f, *e) for f, e in zip(fixes, enu)]
        path = self.root / "gps0" / "data.csv"
        _write_csv(path, "#timestamp [ns],latitude [deg],longitude [deg],altitude [m],e [m],n [m],u [m]",
                   t, table, ("%.10f", "%.10f", "%.4f", "%.4f", "%.4f", "%.4f"))
        T, how = self._extrinsics("gps0")
        data = {"sensor_type": "gnss", "rate_hz": rows.summary.rate_hz}
        if len(fixes):
            data["enu_origin"] = {"latitude": float(fixes[0, 0]), "longitude": float(fixes[0, 1]),
                                  "altitude": float(fixes[0, 2])}
        if self.gps_sigma:
            data["horizontal_sigma_m"] = float(f"{np.median(self.gps_sigma):.4g}")
        comments = [f"GNSS receiver of {rows.summary.topic}, frame '{self.frames.get('gps0', '')}'",
                    "e, n, u of data.csv: local East-North-Up [m] relative to enu_origin (WGS-84)"]
        if T is not None:
            data["T_BS"] = _matrix_entry(T)
            comments.append(f"T_BS (antenna in the body frame) {how}")
        (self.root / "gps0" / "sensor.yaml").write_text(_yaml_text(comments, data), encoding="utf-8")


def _pick_camera_info(topics: Sequence[BagTopic], image: BagTopic | None) -> str | None:
    """The ``CameraInfo`` topic that goes with ``image``: the only one, or the one in its namespace."""
    if image is None:
        return None
    infos = [t.topic for t in topics if t.msgtype == CAMERA_INFO]
    if len(infos) == 1:
        return infos[0]
    parts = image.topic.rstrip("/").split("/")
    for depth in range(len(parts) - 1, 0, -1):
        ns = "/".join(parts[:depth])
        near = [i for i in infos if i.rsplit("/", 1)[0] == ns]
        if len(near) == 1:
            return near[0]
    return None


def _camera_info_yaml(info, rate_hz: float | None, notes: list[str]) -> dict:
    """``cam0/sensor.yaml`` entries from a ``sensor_msgs/CameraInfo`` message."""
    K = [float(v) for v in info.k]
    D = [float(v) for v in info.d]
    model = str(info.distortion_model).lower()
    data = {"sensor_type": "camera", "rate_hz": rate_hz, "resolution": [int(info.width), int(info.height)],
            "camera_model": "pinhole", "intrinsics": [K[0], K[4], K[2], K[5]]}
    if not any(D):
        data["distortion_model"] = "none"
        data["distortion_coefficients"] = []
    elif model in ("plumb_bob", "rational_polynomial") and len(D) >= 4:
        keep = D[:5] if len(D) >= 5 else D[:4]
        if model == "rational_polynomial" and any(D[5:]):
            notes.append("CameraInfo rational_polynomial: only k1, k2, p1, p2, k3 were kept")
        data["distortion_model"] = "radial-tangential"
        data["distortion_coefficients"] = keep
    elif model in ("equidistant", "fisheye") and len(D) >= 4:
        data["distortion_model"] = "equidistant"
        data["distortion_coefficients"] = D[:4]
    else:
        raise InputError(f"CameraInfo distortion model '{info.distortion_model}' with {len(D)} coefficients "
                         "is not supported; give --camera-yaml")
    return data
