"""Open a recording folder and read its streams.

Layout (``datasets/README.md``)::

    SEQ/cam0/data.csv + cam0/data/*.png  (or cam0/video.<ext>), cam0/sensor.yaml
    SEQ/imu0/data.csv, imu0/sensor.yaml
    SEQ/wheel0/data.csv, wheel0/sensor.yaml
    SEQ/odom0/data.csv
    SEQ/range0/data.csv
    SEQ/gps0/data.csv, gps0/sensor.yaml
    SEQ/state_groundtruth_estimate0/data.csv

Every stream is optional. A stream is *present* when its folder (``imu0/``) or its ``data.csv`` exists
(:meth:`Recording.has`); a present stream whose ``data.csv`` is missing or unreadable (a broken link, a link loop,
a folder) is an :class:`~fusion_vo.errors.InputError` naming the file, never silently dropped. Asking for a stream
that is absent raises :class:`~fusion_vo.errors.InputError` too.

:class:`Recording` reads the camera's frames and the ground truth. Each other stream is read by its sensor, in
the sensor's module (:func:`fusion_vo.sensors.imu.read_imu`, :func:`fusion_vo.sensors.wheel.read_ticks`, ...), as a
registered plugin reads its own: through :meth:`Recording.table` (the checked rows of ``FOLDER/data.csv``) and
:meth:`Recording.sensor_file` (its ``sensor.yaml``).
Camera frames are decoded lazily by :meth:`Recording.frames`. A frame that cannot be read (missing,
corrupt, wrong size) is yielded with ``image=None`` and an ``error`` text, so that a long run can skip it
with a warning and count it instead of stopping. Frame files are read as bytes and decoded in memory, so
any path the operating system accepts works (OpenCV's own file functions fail on paths that are not valid
UTF-8). Frame names in ``cam0/data.csv`` must stay inside ``cam0/data/`` (no absolute path, no ``..``).

16-bit frames that hold 10-, 12- or 14-bit data (the top bits always zero) are scaled to the full 16-bit
range: the bit depth is ``bit_depth`` in ``cam0/sensor.yaml`` if given, otherwise read off the first frame
that decodes (its largest value).
"""

from __future__ import annotations

import io
import logging
import os
import stat
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, TypeVar

import cv2
import numpy as np

from fusion_vo.config.sensor_files import CameraFile, SensorFile
from fusion_vo.errors import InputError, check_file
from fusion_vo.geometry import se2
from fusion_vo.geometry.camera import CameraModel
from fusion_vo.measurements import MAX_POSITION_M, PoseData
from fusion_vo.outputs import make_folder, write_atomic
from fusion_vo.recording.csvio import check_magnitude, read_frame_list, read_table, unit_quaternions

log = logging.getLogger(__name__)

F = TypeVar("F", bound=SensorFile)

VIDEO_EXTENSIONS = (".avi", ".mp4", ".mkv", ".mov", ".webm")

#: the camera's folder (its frames, read here) and the ground truth's (the reference a run is scored against); every
#: other stream is read by its sensor (:mod:`fusion_vo.sensors`) through :meth:`Recording.table`
CAMERA = "cam0"
GROUNDTRUTH = "state_groundtruth_estimate0"

#: bit depths a 16-bit frame may hold
BIT_DEPTHS = (10, 12, 14, 16)


@dataclass
class Frame:
    """One camera frame: its index (row in ``cam0/data.csv``), time [s], grey image or ``None``."""

    index: int
    t: float
    image: np.ndarray | None
    source: str
    error: str | None = None


class Recording:
    """A recording folder.

    Parameters
    ----------
    path : str or Path
        The sequence folder.
    """

    def __init__(self, path: str | Path):
        if isinstance(path, (str, bytes)) and not path.strip():  # Path("") is the current folder
            raise InputError(f"no recording folder given ({path!r}: an empty name would read the current folder)")
        self.path = Path(path)
        if not self.path.exists():
            raise InputError("recording folder not found", self.path)
        if not self.path.is_dir():
            raise InputError("not a folder (a recording is a folder with cam0/, imu0/, wheel0/ ...)", self.path)
        self._camera: CameraModel | None = None
        self._frame_list: tuple[np.ndarray, list[str], np.ndarray] | None = None
        self._shift: int | None = None
        self._keys_told: set[str] = set()  # sensor.yaml files already checked for misspelt keys
        self._defaults_told: set[str] = set()  # streams already warned about defaults used

    def __repr__(self) -> str:
        return f"Recording({str(self.path)!r}, streams={self.streams()})"

    # ------------------------------------------------------------------ any stream
    def has(self, folder: str) -> bool:
        """Whether the stream ``folder`` (``imu0``, ``odom1``, ``compass0`` ...) is present: its folder or its
        ``data.csv`` exists (a broken link too, which reading it reports)."""
        return os.path.lexists(self.path / folder)

    def streams(self) -> list[str]:
        """The stream folders present, sorted: the folders (or links) whose name ends in a digit, as the layout
        names them (``cam0``, ``imu0``, ``state_groundtruth_estimate0``, a plugin's ``compass0`` ...)."""
        try:
            entries = list(self.path.iterdir())
        except OSError as exc:
            raise InputError(f"cannot list the recording folder ({exc.strerror})", self.path) from None
        return sorted(p.name for p in entries if p.name[-1:].isdigit() and (p.is_dir() or p.is_symlink()))

    def data_file(self, folder: str, what: str) -> Path:
        """``FOLDER/data.csv``, checked to be a readable file; an :class:`InputError` naming it (or the recording,
        when ``folder`` is absent: "this recording has no ``what`` stream")."""
        if not self.has(folder):
            raise InputError(f"this recording has no {what} stream (no {folder}/)", self.path)
        p = self.path / folder / "data.csv"
        check_file(p)
        return p

    def table(self, folder: str, columns: int | tuple[int, int], stream: str, values: str = "values",
              min_rows: int = 1, **options):
        """The rows ``timestamp [ns], v1, v2 ...`` of ``FOLDER/data.csv`` with every check of
        :func:`~fusion_vo.recording.csvio.read_table` (``options`` are its keywords; ``values`` names the columns in
        its messages), and at least ``min_rows`` of them: ``(table, path)``. ``stream`` names the stream
        (``"IMU"``)."""
        path = self.data_file(folder, stream)
        return _enough_rows(read_table(path, columns, values, **options), path, min_rows, stream), path

    def sensor_file(self, folder: str, model: type[F], required: bool) -> F:
        """``FOLDER/sensor.yaml`` read and checked by ``model`` (a
        :class:`~fusion_vo.config.sensor_files.SensorFile`); a key close to one it reads is warned about once
        per folder."""
        warn = folder not in self._keys_told
        self._keys_told.add(folder)
        return model.read(self.path / folder / "sensor.yaml", required=required, warn=warn)

    def warn_defaults(self, folder: str, defaults: list[str]) -> None:
        """Warn once per folder, naming its ``sensor.yaml``, about the ``defaults`` taken for keys it does not
        state."""
        if defaults and folder not in self._defaults_told:
            self._defaults_told.add(folder)
            log.warning("%s: %s", self.path / folder / "sensor.yaml", "; ".join(defaults))

    # ------------------------------------------------------------------ camera
    @property
    def camera(self) -> CameraModel:
        """The camera model of ``cam0/sensor.yaml`` (every key of the file is checked with it,
        :class:`~fusion_vo.config.sensor_files.CameraFile`)."""
        if self._camera is None:
            self.data_file(CAMERA, "camera")
            self._camera = self.sensor_file(CAMERA, CameraFile, required=True).camera(self.path / "cam0" / "sensor.yaml")
        return self._camera

    @camera.setter
    def camera(self, model: CameraModel) -> None:
        """Use ``model`` instead of ``cam0/sensor.yaml`` (e.g. a camera run without its calibration)."""
        self._camera = model

    def _frames_index(self) -> tuple[np.ndarray, list[str], np.ndarray]:
        if self._frame_list is None:
            path = self.data_file(CAMERA, "camera")
            self._frame_list = read_frame_list(path)
            if len(self._frame_list[0]) == 0:
                raise InputError("no frames listed", path)
            first: dict[str, int] = {}
            from_files = (self.path / "cam0" / "data").is_dir()  # (a video's rows are its frames in order)
            for name, line in zip(self._frame_list[1], self._frame_list[2]):
                if Path(name).is_absolute() or ".." in Path(name).parts:
                    raise InputError(f"frame '{name}' is outside cam0/data/ (give a name relative to cam0/data/, "
                                     "without '..')", path, int(line))
                if from_files and first.setdefault(os.path.normpath(name), int(line)) != line:
                    raise InputError(f"frame '{name}' listed again (first on line {first[os.path.normpath(name)]}): "
                                     "one image cannot be taken at two times", path, int(line))
        return self._frame_list

    @property
    def frame_times(self) -> np.ndarray:
        """Frame timestamps [s]."""
        return self._frames_index()[0].astype(np.float64) * 1e-9

    def __len__(self) -> int:
        return len(self._frames_index()[0]) if self.has(CAMERA) else 0

    def video_path(self) -> Path | None:
        cam = self.path / "cam0"
        for ext in VIDEO_EXTENSIONS:
            p = cam / f"video{ext}"
            if p.is_file():
                return p
        return None

    def frames(self, start: int = 0, stop: int | None = None) -> Iterator[Frame]:
        """Decode frames ``start .. stop-1`` one at a time (grey ``uint8`` or ``uint16``)."""
        t_ns, names, lines = self._frames_index()
        cam = self.camera
        stop = len(t_ns) if stop is None else min(stop, len(t_ns))
        video = self.video_path() if not (self.path / "cam0" / "data").is_dir() else None
        size = (cam.height, cam.width)
        if video is not None:
            yield from self._video_frames(video, t_ns, start, stop, size)
            return
        folder = self.path / "cam0" / "data"
        if not folder.is_dir():
            raise InputError("no frames: neither cam0/data/ nor cam0/video.<ext> exists", self.path / "cam0")
        shift = self.pixel_shift()
        for i in range(start, stop):
            p = folder / names[i]
            img, err = read_image(p, size, shift or 0)
            if shift is None and img is not None:
                shift = self.pixel_shift(img)
                if shift:
                    img = scale_bits(img, shift)
            if err is not None:
                err = f"{p}: {err} (cam0/data.csv line {lines[i]})"
            yield Frame(i, t_ns[i] * 1e-9, img, str(p), err)

    def pixel_shift(self, image: np.ndarray | None = None) -> int | None:
        """Left shift that brings the camera's 16-bit frames to the full range (0 for 16-bit data or 8-bit frames).

        ``bit_depth`` in ``cam0/sensor.yaml`` if given; otherwise found from the first frame decoded
        (``image``), and ``None`` until then.
        """
        if self._shift is None:
            depth = self.sensor_file(CAMERA, CameraFile, required=False).bit_depth
            if depth is not None:
                self._shift = 16 - depth if depth > 8 else 0
            elif image is not None:
                self._shift = 0
                if image.dtype == np.uint16:
                    bits = max(int(image.max()).bit_length(), 1)
                    depth = next(d for d in BIT_DEPTHS if bits <= d)
                    self._shift = 16 - depth
                    if self._shift:
                        log.info("%s: 16-bit frames hold %d-bit data; scaled to 16 bits", self.path / "cam0", depth)
        return self._shift

    def _video_frames(self, video: Path, t_ns, start, stop, size) -> Iterator[Frame]:
        try:
            str(video).encode("utf-8")
        except UnicodeEncodeError:
            raise InputError("OpenCV cannot open a video whose path is not valid UTF-8; rename the folder",
                             video) from None
        cap = cv2.VideoCapture(str(video))
        if not cap.isOpened():
            raise InputError("cannot open video file", video)
        try:
            if start:
                cap.set(cv2.CAP_PROP_POS_FRAMES, start)
            for i in range(start, stop):
                ok, img = cap.read()
                if not ok:
                    raise InputError(f"video ends after {i} frames but cam0/data.csv lists {len(t_ns)}", video)
                img, err = _to_grey(img, size)
                yield Frame(i, t_ns[i] * 1e-9, img, f"{video}#{i}", None if err is None else f"{video} frame {i}: {err}")
        finally:
            cap.release()

    # ------------------------------------------------------------------ the reference
    def has_groundtruth(self) -> bool:
        return self.has(GROUNDTRUTH)

    def groundtruth(self) -> PoseData:
        """``state_groundtruth_estimate0``: pose of B in W; see :func:`read_groundtruth_csv` for the rules."""
        return read_groundtruth_csv(self.data_file(GROUNDTRUTH, "ground truth"))


def _enough_rows(tab, path: Path, need: int, stream: str):
    """``tab``, or an :class:`InputError` naming ``path`` when it has fewer than ``need`` data rows (an
    empty or header-only file is not an absent stream: it is a stream that says nothing)."""
    if len(tab) == 0:
        raise InputError("no data rows (the file is empty or holds only its header)", path)
    if len(tab) < need:
        raise InputError(f"only {len(tab)} data row{'s' if len(tab) != 1 else ''}: the {stream} stream needs at "
                         f"least {need}", path, int(tab.lines[-1]))
    return tab


# ---------------------------------------------------------------------- ground truth

def read_groundtruth_csv(path: str | Path, min_poses: int = 1) -> PoseData:
    """Read ground truth (``state_groundtruth_estimate0/data.csv``): the one reader of it.

    Rules: rows ``timestamp [ns], p_x, p_y, p_z, q_w, q_x, q_y, q_z``, further columns ignored, as every
    stream of the layout; timestamps increase strictly (a repeated or earlier timestamp is an error naming
    the line, as in every other stream); each position within
    :data:`~fusion_vo.measurements.MAX_POSITION_M`; each quaternion's norm is within 0.05 of 1 (it is
    normalised); at least ``min_poses`` poses (the evaluation needs two). Returns the planar pose (x, y, yaw), the height z and the full quaternion (w, x, y, z).
    """
    path = Path(path)
    tab = read_table(path, (7, 7), "pose values", ignore_extra=True)  # further columns are ignored
    if len(tab) < min_poses:
        raise InputError(f"ground truth needs at least {min_poses} poses, found {len(tab)}", path)
    check_magnitude(tab, path, slice(0, 3), MAX_POSITION_M, "position [m]")
    q = unit_quaternions(tab.values[:, 3:7], tab.lines, path, "quaternion")
    yaw = se2.yaw_of_quaternion(q)
    xyyaw = np.column_stack([tab.values[:, 0], tab.values[:, 1], yaw])
    return PoseData(tab.t, xyyaw, tab.values[:, 2].copy(), q)


# ---------------------------------------------------------------------- images
def read_image(path: Path, size: tuple[int, int] | None, shift: int = 0) -> tuple[np.ndarray | None, str | None]:
    """Read and decode one frame file: ``(grey image, None)`` or ``(None, reason)``.

    The file is read as bytes and decoded in memory (any valid path works). ``size`` is ``(height,
    width)`` to check, or ``None``; a PNG whose header states another size is not decoded (a corrupt header
    may claim any size, and OpenCV would allocate it or stop at its pixel limit). ``shift`` scales 16-bit
    frames holding fewer bits (see :meth:`Recording.pixel_shift`).
    """
    try:
        # opened without blocking and checked to be a regular file before reading: a FIFO (or a device)
        # named like a frame would otherwise block the run forever
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0))
        with open(fd, "rb") as fh:
            if not stat.S_ISREG(os.fstat(fh.fileno()).st_mode):
                return None, "not a regular file"
            data = fh.read()
    except FileNotFoundError:
        return None, "image file missing"
    except OSError as exc:
        return None, f"cannot read image file ({exc.strerror})"
    if not data:
        return None, "empty image file"
    header = png_size(data)
    if size is not None and header is not None and header != size:  # not decoded: it may claim any size
        return None, f"frame is {header[1]}x{header[0]} (its PNG header) but cam0/sensor.yaml says {size[1]}x{size[0]}"
    img = decode_image(data)
    if img is None:
        return None, "unreadable or corrupt image"
    img, err = _to_grey(img, size)
    if img is not None and shift:
        img = scale_bits(img, shift)
    return img, err


def decode_image(data: bytes | np.ndarray) -> np.ndarray | None:
    """An encoded image (PNG, JPEG, ...) decoded unchanged by OpenCV, or ``None`` when it cannot be decoded
    (corrupt data, or a header beyond OpenCV's pixel limit, which OpenCV raises as an error)."""
    buf = np.frombuffer(data, dtype=np.uint8) if isinstance(data, bytes) else np.asarray(data, dtype=np.uint8)
    if not buf.size:
        return None
    try:
        return cv2.imdecode(buf.reshape(-1), cv2.IMREAD_UNCHANGED)
    except cv2.error:
        return None


def png_size(data: bytes) -> tuple[int, int] | None:
    """``(height, width)`` that a PNG file's IHDR chunk states, or ``None`` for data that is not a PNG."""
    if len(data) >= 24 and data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR":
        width, height = struct.unpack(">II", data[16:24])
        return height, width
    return None


def scale_bits(image: np.ndarray, shift: int) -> np.ndarray:
    """Scale a 16-bit frame holding ``16 - shift`` bits to the full 16-bit range (8-bit frames unchanged)."""
    if image.dtype != np.uint16 or not shift:
        return image
    return np.left_shift(np.minimum(image, (1 << (16 - shift)) - 1), shift).astype(np.uint16)


_read_image = read_image  # older name


def _to_grey(img: np.ndarray, size: tuple[int, int] | None) -> tuple[np.ndarray | None, str | None]:
    if img.ndim == 3:
        if img.shape[2] == 4:
            img = cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY)
        elif img.shape[2] == 3:
            img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
        else:
            img = img[:, :, 0]
    if img.dtype not in (np.uint8, np.uint16):
        return None, f"unsupported pixel type {img.dtype}"
    if size is not None and img.shape != size:
        return None, f"frame is {img.shape[1]}x{img.shape[0]} but cam0/sensor.yaml says {size[1]}x{size[0]}"
    return img, None


# ---------------------------------------------------------------------- TUM files
def write_tum(path: str | Path, t: np.ndarray, xyyaw: np.ndarray) -> None:
    """Write a planar trajectory as a TUM file (``timestamp x y z qx qy qz qw``, z = 0), atomically."""
    path = Path(path)
    xyyaw = np.asarray(xyyaw, dtype=np.float64).reshape(-1, 3)
    half = 0.5 * xyyaw[:, 2]
    data = np.column_stack([
        np.asarray(t, dtype=np.float64), xyyaw[:, 0], xyyaw[:, 1], np.zeros(len(xyyaw)),
        np.zeros(len(xyyaw)), np.zeros(len(xyyaw)), np.sin(half), np.cos(half),
    ])
    buf = io.StringIO()
    buf.write("# timestamp x y z qx qy qz qw\n")
    np.savetxt(buf, data, fmt=["%.9f"] + ["%.9f"] * 7)
    make_folder(path.parent)
    write_atomic(path, buf.getvalue())
