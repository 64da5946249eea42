"""Visual odometry: recording frames -> frontend -> ground geometry -> body increments and a track.

For each frame the frontend measures the similarity to the previous usable frame; the ground geometry
turns it into ``(dx, dy, dyaw)`` of the body with its covariance (:class:`VisualIncrement`). Chaining
the increments gives the visual dead-reckoning track::

    x_{k+1} = x_k ⊕ delta_k

When the frontend loses the image (a dark, blurred or featureless stretch) and restarts, the gap between
the last measured frame and the restart is bridged with the last measured body twist (constant velocity)
and counted; the fused backends do better by leaning on the wheels and the gyro instead. A gap longer
than ``max_bridge`` (a pause in the recording, a long dark stretch) is not bridged: nothing says the
robot kept moving, so the track holds its last pose there and the gap is listed (``held``).

The body twist ``(vx, vy, yaw rate)`` of a frame is the SE(2) logarithm of its increment divided by the
real time between the two frames (not a nominal frame rate).

Frames are decoded ahead of the tracker (:func:`prepared_frames`): with ``threads >= 2`` a reader thread
decodes the recording's frames in order and a pool of ``threads`` workers does the frontend's per-frame work
that does not depend on earlier frames (its ``prepare``, when it has one), while the calling thread tracks,
and one more thread turns each measured motion into a body increment (gyro derotation, ground geometry, the
track) while the frontend measures the next frame. With ``handoff``, a frontend with a ``set_executor`` method
gets one more thread for work it can hand off (KLT: the next frame's reference warped by the predicted motion;
features: the reference warped for the refinement); it shortens the tracking thread but costs thread wake-ups,
and it does not shorten the wall time where the other threads already fill the cores
(docs/decisions/0002-hand-off-thread-off-by-default.md), so it is off by default. OpenCV releases the GIL
while it decodes and filters, so they overlap on the cores; OpenCV's own kernels may use ``threads`` threads,
the BLAS libraries one (the matrices are small). At most ``2 * threads + 2`` frames wait in a bounded queue
(:func:`read_ahead`), so memory stays flat in recording length. The results are identical frame for frame to
``threads=1`` (everything in the calling thread, OpenCV single-threaded).
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
from collections import Counter, deque
from concurrent.futures import ThreadPoolExecutor
from contextlib import closing, contextmanager
from dataclasses import dataclass, field
from typing import Callable, Iterable, Iterator, TypeVar

import cv2
import numpy as np
from threadpoolctl import threadpool_limits

from frontends import make_frontend
from frontends.base import FrameMotion, MotionStatus
from fusion_vo.calibration.camera_noise import CameraNoise
from fusion_vo.calibration.lens_from_motion import check_stated_lens, lens_from_motion
from fusion_vo.config.odometry import OdometryConfig
from fusion_vo.config.sensor_files import uncalibrated_camera
from fusion_vo.errors import InputError
from fusion_vo.geometry import se2
from fusion_vo.geometry.derotation import GyroDerotation
from fusion_vo.geometry.ground import GroundGeometry
from fusion_vo.geometry.height import smooth_heights
from fusion_vo.measurements import PoseData, RangeData, VisualIncrement
from fusion_vo.recording import Frame, Recording
from fusion_vo.sensors.imu import read_imu
from fusion_vo.sensors.range import camera_height, read_range, reading_sigma

log = logging.getLogger(__name__)

#: fraction of the width and height, about the centre, that the frontends use without a lens model: the
#: distortion left out grows with the distance from the centre (``central_region`` of every frontend)
UNCALIBRATED_CENTRAL_REGION = 0.5


@dataclass
class OdometryResult:
    """Everything visual odometry produced for one recording.

    Attributes
    ----------
    increments : list of VisualIncrement
        One per processed frame after the first (failed ones included, with their status).
    frame_t : ndarray
        Time of every processed frame [s].
    status : list of str
        Frontend status per processed frame.
    inliers : ndarray
        Inlier count per processed frame.
    velocity : ndarray, shape (N, 3)
        ``(vx, vy, yaw rate)`` per processed frame (NaN where not measured).
    height_ratio : ndarray
        ``h(t1) / h(t0)`` of the camera height per processed frame, from the similarity's scale (NaN
        where not measured).
    track : PoseData
        Visual dead reckoning, one pose per measured frame.
    skipped : list of str
        Frames that could not be loaded (file and reason).
    failure_reasons : Counter
        Frames the frontend could not measure, by the frontend's reason (one line each).
    bridged_s : float
        Time spent bridging gaps at constant velocity [s].
    held : list of tuple
        ``(start, end)`` [s] of the gaps longer than ``max_bridge`` across which the track held its pose.
    elapsed_s : float
        Wall-clock time of the run [s].
    range_scaled : bool
        The increments were scaled frame by frame with the range finder's height (``use_range``), so the
        range finder is already in them and the backends must not use it again.
    frame_height, frame_height_sigma : ndarray or None
        With ``range_scaled``: the camera height [m] each processed frame was scaled with, and its standard
        deviation [m] (smoothed, :mod:`fusion_vo.geometry.height`, or interpolated from the readings).
    height_note : str or None
        What the height smoothing used and found, in words (``None`` when it did not run).
    noise_note : str or None
        The camera noise model applied to the increments (``OdometryConfig.camera_noise``), or why the one
        stated was not, in words (``None``: none stated).
    """

    increments: list[VisualIncrement]
    frame_t: np.ndarray
    status: list[str]
    inliers: np.ndarray
    velocity: np.ndarray
    height_ratio: np.ndarray
    track: PoseData
    skipped: list[str]
    bridged_s: float
    elapsed_s: float
    range_scaled: bool = False
    held: list = field(default_factory=list)
    frame_height: np.ndarray | None = None
    frame_height_sigma: np.ndarray | None = None
    height_note: str | None = None
    noise_note: str | None = None
    failure_reasons: Counter = field(default_factory=Counter)

    @property
    def n_frames(self) -> int:
        return len(self.frame_t)

    @property
    def failures(self) -> Counter:
        return Counter(s for s in self.status if s not in ("ok", "first"))

    @property
    def fps(self) -> float:
        return self.n_frames / self.elapsed_s if self.elapsed_s > 0 else float("nan")

    @property
    def distance(self) -> float:
        xy = self.track.xyyaw[:, :2]
        return float(np.sum(np.linalg.norm(np.diff(xy, axis=0), axis=1))) if len(xy) > 1 else 0.0


class VisualOdometry:
    """Streaming visual odometry: feed frames, get body increments and the current pose.

    Parameters
    ----------
    frontend : object with ``process(image, t) -> FrameMotion``
    geometry : GroundGeometry

    derotation : GyroDerotation, optional
        Removes the roll and pitch image motion before the geometry.
    height_filter : HeightFilter, optional
        Live use with a range finder: the camera height of each frame from the readings given to
        :meth:`add_range` and the frames' own scale change (:class:`fusion_vo.geometry.height.HeightFilter`),
        where :meth:`process` is given no ``height``.
    """

    def __init__(self, frontend, geometry: GroundGeometry, derotation: GyroDerotation | None = None,
                 max_bridge: float = 1.0, height_filter=None):
        self.frontend = frontend
        self.geometry = geometry
        self.derotation = derotation
        self.max_bridge = max_bridge
        self.t: list[float] = []
        self.poses: list[np.ndarray] = []
        self.bridged_s = 0.0
        self.held: list[tuple[float, float]] = []
        self._last_twist = np.zeros(3)
        #: when a list, :meth:`finish` appends to it every motion it is given, after the derotation
        self.kept_motions: list[FrameMotion] | None = None
        self.height_filter = height_filter

    @property
    def pose(self) -> np.ndarray | None:
        """Latest ``(x, y, yaw)`` of the visual track (``None`` before the first frame)."""
        return self.poses[-1] if self.poses else None

    def process(self, image, t: float, height: float | None = None,
                height_sigma: float = 0.0) -> tuple[FrameMotion, VisualIncrement | None]:
        """Process one frame; returns the frontend's motion and the body increment (``None`` for a first frame).

        ``image`` is the frame, or what the frontend's ``prepare`` made of it; ``height`` a measured camera
        height [m] (a range finder's) with its standard deviation ``height_sigma``.
        """
        motion = self.frontend.process(image, t)
        return motion, self.finish(motion, height, height_sigma)

    def finish(self, motion: FrameMotion, height: float | None = None,
               height_sigma: float = 0.0) -> VisualIncrement | None:
        """The second half of :meth:`process`: the body increment of the frontend's ``motion`` (``None``
        for a first frame), derotated and through the ground geometry, appended to the track.
        The height's uncertainty goes into the increment's covariance
        (:meth:`~fusion_vo.geometry.ground.GroundGeometry.body_increment`).

        Nothing in it feeds back into the frontend, so a run does it in another thread while the frontend
        measures the next frame (:func:`run_visual_odometry`); it must see the motions in frame order.
        """
        if motion.status is MotionStatus.FIRST:
            self._keep(motion)
            self._filtered_height(motion, height, height_sigma)
            if not self.poses:
                self.t.append(motion.timestamp)
                self.poses.append(np.zeros(3))
            return None
        if self.derotation is not None and motion.ok and motion.prev_timestamp is not None:
            motion.info["measured_matrix"] = motion.matrix
            motion.matrix, motion.covariance = self.derotation.derotate(motion.matrix, motion.covariance,
                                                                        motion.prev_timestamp, motion.timestamp)
        self._keep(motion)
        height, height_sigma = self._filtered_height(motion, height, height_sigma)
        inc = self.geometry.increment(motion, height, height_sigma)
        if inc.ok:
            self._append(inc)
        return inc

    def add_range(self, t: float, distance: float) -> None:
        """A range finder's reading [m] at ``t`` [s], for the ``height_filter`` (a reading is used by the first
        frame at or after its time, so give each one before that frame)."""
        if self.height_filter is None:
            raise ValueError("add_range needs a height_filter")
        self.height_filter.add_reading(t, distance)

    def _filtered_height(self, motion: FrameMotion, height, height_sigma):
        """``(height, height_sigma)`` for ``motion``: the given ones, else the ``height_filter``'s."""
        if height is not None or self.height_filter is None:
            return height, height_sigma
        hf = self.height_filter
        log_ratio = log_sigma = None
        if motion.ok and motion.prev_timestamp is not None and hf.last_time == motion.prev_timestamp:
            log_ratio = -float(motion.params[3])
            log_sigma = math.sqrt(max(float(motion.covariance[3, 3]), 0.0))
        out = hf.frame(motion.timestamp, log_ratio, log_sigma)
        return (None, 0.0) if out is None else out

    def _keep(self, motion: FrameMotion) -> None:
        if self.kept_motions is not None:
            self.kept_motions.append(FrameMotion(motion.timestamp, motion.prev_timestamp, motion.matrix.copy(),
                                                 motion.covariance.copy(), motion.status,
                                                 n_inliers=motion.n_inliers))

    def _append(self, inc: VisualIncrement) -> None:
        if not self.poses:
            self.t.append(inc.t0)
            self.poses.append(np.zeros(3))
        gap = inc.t0 - self.t[-1]
        if gap > self.max_bridge:  # a pause or a long loss: nothing says the robot kept moving
            self.held.append((self.t[-1], inc.t0))
            self.poses.append(self.poses[-1])
            self.t.append(inc.t0)
        elif gap > 1e-6:  # the frontend restarted: bridge at constant velocity
            self.poses.append(se2.compose(self.poses[-1], se2.exp(self._last_twist * gap)))
            self.t.append(inc.t0)
            self.bridged_s += gap
        self.poses.append(se2.compose(self.poses[-1], inc.delta))
        self.t.append(inc.t1)
        if inc.dt > 0:
            self._last_twist = se2.log(inc.delta) / inc.dt

    def track(self) -> PoseData:
        return PoseData(np.asarray(self.t, dtype=np.float64), np.asarray(self.poses, dtype=np.float64).reshape(-1, 3))


T = TypeVar("T")


def read_ahead(items: Iterable[T], depth: int) -> Iterator[T]:
    """Iterate ``items`` in a background thread, at most ``depth`` items ahead of the consumer.

    The items come out in their order; an exception raised by ``items`` is raised here at the same
    position. When the consumer stops early (an error, ``close()``), the background thread stops after
    the item it is producing and closes ``items``.

    Parameters
    ----------
    items : iterable
        Typically a generator that decodes frames; it is only ever advanced by the background thread.
    depth : int
        Largest number of produced items waiting for the consumer (memory bound).
    """
    buffer: queue.Queue = queue.Queue(maxsize=max(int(depth), 1))
    stop = threading.Event()
    end = object()

    def put(entry) -> bool:
        while not stop.is_set():
            try:
                buffer.put(entry, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def produce() -> None:
        iterator = iter(items)
        try:
            for item in iterator:
                if not put((item, None)):
                    break
            else:
                put((end, None))
        except BaseException as exc:  # handed to the consumer, raised there
            put((end, exc))
        finally:
            close = getattr(iterator, "close", None)
            if close is not None:
                close()

    worker = threading.Thread(target=produce, name="fusion-vo-read-ahead", daemon=True)
    worker.start()
    try:
        while True:
            item, exc = buffer.get()
            if exc is not None:
                raise exc
            if item is end:
                return
            yield item
    finally:
        stop.set()
        worker.join()


def prepared_frames(frames: Iterable[Frame], prepare: Callable | None, threads: int) -> Iterator[tuple[Frame, object]]:
    """``(frame, prepare(frame.image))`` in order, decoded and prepared ahead of the caller with ``threads > 1``.

    With one thread everything happens in the calling thread. Otherwise one reader thread advances
    ``frames`` (decoding them: a recording's frame reader keeps state from frame to frame) and hands
    each frame to a pool of ``threads`` workers for ``prepare``; at most ``2 * threads + 2`` frames are
    decoded ahead of the caller (:func:`read_ahead`). A frame that failed to load (``image is None``)
    is passed through unprepared, as is every frame when ``prepare`` is ``None``.
    """

    def work(frame: Frame) -> tuple[Frame, object]:
        if prepare is None or frame.image is None:
            return frame, frame.image
        return frame, prepare(frame.image)

    if threads <= 1:
        yield from map(work, frames)
        return
    pool = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="fusion-vo-prepare")
    ahead = read_ahead((pool.submit(work, frame) for frame in frames), depth=2 * threads + 2)
    try:
        for future in ahead:
            yield future.result()
    finally:
        ahead.close()
        pool.shutdown(wait=True, cancel_futures=True)


@contextmanager
def opencv_threads(n: int):
    """Let OpenCV's kernels use ``n`` threads inside the block, the BLAS libraries one; then restore both.

    The matrices of a frame (descriptor distances: 150 x 121) are far too small for a multi-threaded
    BLAS, whose waiting workers cost more than they compute (OpenCV's ``gemm`` goes to the OpenBLAS
    that opencv-python bundles); parallelism comes from the frame pipeline instead.
    """
    before = cv2.getNumThreads()
    cv2.setNumThreads(int(n))
    try:
        with threadpool_limits(limits=1, user_api="blas"):
            yield
    finally:
        cv2.setNumThreads(before)


@contextmanager
def _shut_down(pool: ThreadPoolExecutor | None):
    """Shut ``pool`` down when the block ends (cancelling what has not started), if there is one."""
    try:
        yield pool
    finally:
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)


def heights_for(recording: Recording, times: np.ndarray) -> np.ndarray | None:
    """Camera height at ``times`` from the range finder (linear interpolation), or ``None``."""
    out = range_heights(recording, times)
    return None if out is None else out[0]


@dataclass
class RangeReadings:
    """A range finder's readings that its gate passes: times ``t`` [s], ``height`` [m], and the standard
    deviation of one reading [m] measured from them (``None`` when too few)."""

    t: np.ndarray
    height: np.ndarray
    sigma: float | None


def range_readings(recording: Recording) -> RangeReadings | None:
    """The gated readings of the recording's range finder (:func:`fusion_vo.sensors.range.camera_height`,
    :func:`fusion_vo.sensors.range.reading_sigma`), or ``None`` without a usable one."""
    if not recording.has("range0"):
        return None
    r: RangeData = read_range(recording)
    if len(r) == 0:
        return None
    gated = camera_height(r)
    if not gated.valid.any():
        return None
    return RangeReadings(gated.t[gated.valid], gated.height[gated.valid], reading_sigma(r, gated=gated))


def range_heights(recording: Recording, times: np.ndarray,
                  readings: RangeReadings | None = None) -> tuple[np.ndarray, np.ndarray] | None:
    """Camera height at ``times`` from the range finder (linear interpolation) and its standard deviation,
    or ``None`` without a range finder (``readings``: the recording's :func:`range_readings`, when at hand).

    Only the readings the range gate passes are used (:func:`fusion_vo.sensors.range.camera_height`: a
    spike would otherwise scale the frames around it). The standard deviation of one reading is measured
    from the readings (:func:`fusion_vo.sensors.range.reading_sigma`); a height interpolated a fraction
    ``a`` of the way between two readings has ``σ² ((1 - a)² + a²)``.
    """
    readings = readings or range_readings(recording)
    if readings is None:
        return None
    times = np.asarray(times, dtype=np.float64)
    t = np.asarray(readings.t, dtype=np.float64)
    heights = np.interp(times, t, readings.height)
    sigma = readings.sigma or 0.0
    j = np.clip(np.searchsorted(t, times), 1, max(len(t) - 1, 1))
    span = t[j] - t[j - 1] if len(t) > 1 else np.ones_like(times)
    a = np.clip((times - t[j - 1]) / np.where(span > 0, span, 1.0), 0.0, 1.0) if len(t) > 1 else np.zeros_like(times)
    return heights, sigma * np.sqrt((1.0 - a) ** 2 + a**2)


def smoothed_heights(readings: RangeReadings, motions: list[FrameMotion]):
    """The camera height at each of ``motions``' frames from the range finder's ``readings`` and the motions'
    scale (:func:`fusion_vo.geometry.height.smooth_heights`), or ``None`` when the readings do not allow it.

    A motion's scale is used as the height ratio of its two frames when it is measured from the frame
    just before it in ``motions``.
    """
    if readings.sigma is None or len(motions) < 2:
        return None
    t = np.array([m.timestamp for m in motions], dtype=np.float64)
    log_ratio = np.full(len(motions), np.nan)
    log_sigma = np.full(len(motions), np.nan)
    for k in range(1, len(motions)):
        m = motions[k]
        if m.ok and m.prev_timestamp is not None and abs(m.prev_timestamp - t[k - 1]) < 1e-9:
            log_ratio[k] = -m.params[3]
            log_sigma[k] = math.sqrt(max(float(m.covariance[3, 3]), 0.0))
    return smooth_heights(t, log_ratio, log_sigma, readings.t, readings.height, readings.sigma)


def _height_note(smoothed, reading_sigma: float) -> str:
    """What the height smoothing used and found, for the run's notes."""
    return (f"camera height from {smoothed.n_readings} range readings and {smoothed.n_ratios} frame scales "
            f"({smoothed.n_downweighted} down-weighted, the scales' stated variance times {smoothed.ratio_factor:.3g}): "
            f"median sigma {1e3 * float(np.median(smoothed.sigma)):.3g} mm against {1e3 * reading_sigma:.3g} mm "
            "for one reading")


def run_visual_odometry(
    recording: Recording,
    config: OdometryConfig | None = None,
    progress: Callable[[int, int], None] | None = None,
    frames: Iterable | None = None,
) -> OdometryResult:
    """Run visual odometry over a whole recording, streaming its frames.

    Parameters
    ----------
    recording : Recording
    config : OdometryConfig
    progress : callable ``(done, total)``, optional
        Called after every frame (for a progress bar).
    frames : iterable of Frame, optional
        Frames to use instead of ``recording.frames()``.

    With ``config.threads`` other than 1 the frames are decoded and prepared in other threads ahead of
    the tracker (:func:`prepared_frames`); the results are the same as with one thread.
    """
    config = config or OdometryConfig()
    if config.uncalibrated:
        cam = uncalibrated_camera(recording.path / "cam0" / "sensor.yaml", config.focal_length)
        recording.camera = cam  # the frames are read with this model's image size
        if config.lens_from_motion:
            cam, _ = lens_from_motion(recording, cam)
        recording.camera = cam  # every later reader of this recording sees the same model
    else:
        cam = recording.camera
        if config.check_lens and not cam.has_distortion:
            cam, _ = check_stated_lens(recording, cam)
            recording.camera = cam
    try:
        geometry = GroundGeometry(cam, height=config.height, min_sigma_xy=config.min_sigma_xy,
                                  min_sigma_yaw=config.min_sigma_yaw)
    except ValueError as exc:
        raise InputError(str(exc), recording.path / "cam0" / "sensor.yaml") from None
    try:
        options = dict(config.frontend_options)
        if config.uncalibrated and not cam.has_distortion and options.get("central_region") is None:
            options["central_region"] = UNCALIBRATED_CENTRAL_REGION
        frontend = make_frontend(config.frontend, options, point_map=geometry.rectifier)
    except (TypeError, ValueError) as exc:
        raise InputError(f"frontend configuration: {exc}") from None
    readings = range_readings(recording) if config.use_range else None
    ranged = range_heights(recording, recording.frame_times, readings) if readings is not None else None
    heights, height_sigmas = (None, None) if ranged is None else ranged
    derotation = None
    if config.gyro_derotation and recording.has("imu0"):
        derotation = GyroDerotation(read_imu(recording), geometry)
    vo = VisualOdometry(frontend, geometry, derotation, max_bridge=config.max_bridge)
    if heights is not None and config.range_smoothing:
        vo.kept_motions = []
    total = len(recording)
    increments: list[VisualIncrement] = []
    frame_t, status, inliers, vel, ratio = [], [], [], [], []
    skipped: list[str] = []
    reasons: Counter = Counter()
    bad_run = 0
    threads = config.thread_count()

    def collect(inc: VisualIncrement | None) -> None:
        if inc is not None:
            increments.append(inc)
        if inc is not None and inc.ok and inc.dt > 0:
            vel.append(se2.log(inc.delta) / inc.dt)
            ratio.append(inc.height_ratio)
        else:
            vel.append(np.full(3, np.nan))
            ratio.append(np.nan)

    start = time.perf_counter()
    source = prepared_frames(frames if frames is not None else recording.frames(),
                             getattr(frontend, "prepare", None), threads)
    # with threads, the increments are computed in a thread of their own, one frame behind the frontend
    post = ThreadPoolExecutor(max_workers=1, thread_name_prefix="fusion-vo-geometry") if threads > 1 else None
    # and a frontend that can do part of its work in another thread (KLT: setting up the next frame's
    # tracking, told the next frame's timestamp; features: warping the reference) does so in one more
    ahead = None
    if threads > 1 and config.handoff and hasattr(frontend, "set_executor"):
        ahead = ThreadPoolExecutor(max_workers=1, thread_name_prefix="fusion-vo-ahead")
        frontend.set_executor(ahead)
    frame_times = recording.frame_times
    pending: deque = deque()
    with opencv_threads(threads), closing(source), _shut_down(post), _shut_down(ahead):
        for k, (frame, image) in enumerate(source):
            if frame.image is None:
                skipped.append(frame.error or frame.source)
                bad_run += 1
                if bad_run >= config.max_bad_start_frames and not frame_t:
                    raise InputError(f"the first {bad_run} frames cannot be used; first problem: {skipped[0]}")
                log.warning("skipping frame %d: %s", frame.index, frame.error)
                if progress:
                    progress(k + 1, total)
                continue
            bad_run = 0
            h = None if heights is None else float(heights[frame.index])
            h_sigma = 0.0 if height_sigmas is None else float(height_sigmas[frame.index])
            if ahead is not None and hasattr(frontend, "expect"):
                following = frame.index + 1
                frontend.expect(float(frame_times[following]) if 0 < following < len(frame_times) else None)
            motion = frontend.process(image, frame.t)
            frame_t.append(frame.t)
            status.append(motion.status.value)
            if motion.status.value not in ("ok", "first"):
                reasons[" ".join(str(motion.info.get("reason") or motion.status.value).split())] += 1
            inliers.append(motion.n_inliers)
            if post is None:
                collect(vo.finish(motion, h, h_sigma))
            else:
                pending.append(post.submit(vo.finish, motion, h, h_sigma))
                while pending and (pending[0].done() or len(pending) > 2 * threads + 2):
                    collect(pending.popleft().result())
            if progress:
                progress(k + 1, total)
        while pending:
            collect(pending.popleft().result())
    if not frame_t:
        raise InputError("no usable frame in the recording", recording.path / "cam0")
    frame_height = frame_height_sigma = height_note = None
    if heights is not None:
        used = np.searchsorted(frame_times, np.asarray(frame_t)).clip(0, len(frame_times) - 1)
        frame_height, frame_height_sigma = heights[used], height_sigmas[used]
    if vo.kept_motions is not None:
        smoothed = smoothed_heights(readings, vo.kept_motions)
        if smoothed is not None:  # the same motions again, each scaled by its frame's smoothed height
            kept, vo = vo.kept_motions, VisualOdometry(None, geometry, None, max_bridge=config.max_bridge)
            increments.clear()
            vel.clear()
            ratio.clear()
            for motion, h, h_sigma in zip(kept, smoothed.height, smoothed.sigma):
                collect(vo.finish(motion, float(h), float(h_sigma)))
            frame_height, frame_height_sigma = smoothed.height, smoothed.sigma
            height_note = _height_note(smoothed, readings.sigma)
            log.info("%s", height_note)
    increments, noise_note = _with_camera_noise(recording, config, increments)
    elapsed = time.perf_counter() - start
    return OdometryResult(
        increments=increments,
        frame_t=np.asarray(frame_t),
        status=status,
        inliers=np.asarray(inliers, dtype=np.int64),
        velocity=np.asarray(vel).reshape(-1, 3),
        height_ratio=np.asarray(ratio, dtype=np.float64),
        track=vo.track(),
        skipped=skipped,
        bridged_s=vo.bridged_s,
        held=vo.held,
        elapsed_s=elapsed,
        range_scaled=heights is not None,
        frame_height=frame_height,
        frame_height_sigma=frame_height_sigma,
        height_note=height_note,
        noise_note=noise_note,
        failure_reasons=reasons,
    )


def _with_camera_noise(recording: Recording, config: OdometryConfig, increments: list) -> tuple[list, str | None]:
    """``increments`` with the heading noise model of ``cam0/sensor.yaml`` when it states one for this frontend
    (``config.camera_noise``), and a note of what was done."""
    noise = CameraNoise.stated(recording) if config.camera_noise else None
    if noise is None:
        return increments, None
    if noise.frontend != config.frontend:
        note = (f"camera heading noise of cam0/sensor.yaml not used: it was measured with the {noise.frontend} "
                f"frontend, this run uses {config.frontend}")
        log.info("%s", note)
        return increments, note
    note = noise.describe()
    log.info("%s", note)
    return noise.apply(increments), note
