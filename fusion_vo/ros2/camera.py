"""The node's camera pipeline: frames to visual increments on a thread of its own.

Image callbacks only convert the message and :meth:`CameraPipeline.put` the frame into a bounded queue;
one worker thread runs :class:`~fusion_vo.odometry.VisualOdometry` on the frames in order and hands each
increment (with the camera noise model of the calibration, when it states one) to the fusion. When the
queue is full the oldest waiting frame is dropped and counted, so a slow frontend loses frames (the next
increment spans the gap) but never holds up the other inputs, which go to the fusion from their own
callbacks. A frame not newer than the last one taken is skipped and counted (the frontend needs frames
in time order).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque

import numpy as np

log = logging.getLogger(__name__)


class CameraPipeline:
    """Bounded queue of ``(t, image, arrival)`` and the thread that turns them into visual increments.

    Parameters
    ----------
    vo : VisualOdometry
    fusion : StreamingFusion
    capacity : int
        Frames that may wait; a further one pushes the oldest out (``dropped``).
    noise : CameraNoise, optional
        Heading noise model applied to each increment (``cam0/sensor.yaml`` ``camera_noise``).
    """

    def __init__(self, vo, fusion, capacity: int, noise=None):
        self.vo, self.fusion, self.noise = vo, fusion, noise
        self.capacity = int(capacity)
        self._queue: deque = deque()
        self._cond = threading.Condition()
        self._stop = False
        self.dropped = 0  # frames pushed out of the full queue
        self.out_of_order = 0  # frames not newer than the last one taken
        self.frames = 0  # frames the frontend processed
        self.failed = 0  # frames the frontend could not measure (counted by the fusion as missing)
        self.errors = 0  # frames whose processing raised (logged once)
        self.latency_ms: deque = deque(maxlen=1000)  # arrival to increment handed to the fusion [ms]
        self._last_t = -np.inf
        self._busy = False  # a frame taken from the queue and not yet handed on
        self._thread = threading.Thread(target=self._run, name="fusion-vo-camera", daemon=True)
        self._thread.start()

    def put(self, t: float, image: np.ndarray) -> None:
        with self._cond:
            if len(self._queue) >= self.capacity:
                self._queue.popleft()
                self.dropped += 1
            self._queue.append((t, image, time.perf_counter()))
            self._cond.notify()

    def backlog(self) -> int:
        """Frames waiting in the queue or being measured."""
        with self._cond:
            return len(self._queue) + int(self._busy)

    def stop(self, timeout: float = 1.0) -> None:
        with self._cond:
            self._stop = True
            self._queue.clear()
            self._cond.notify()
        self._thread.join(timeout)

    def _run(self) -> None:
        while True:
            with self._cond:
                self._busy = False
                while not self._queue and not self._stop:
                    self._cond.wait()
                if self._stop:
                    return
                t, image, arrival = self._queue.popleft()
                self._busy = True
            if t <= self._last_t:
                self.out_of_order += 1
                continue
            self._last_t = t
            try:
                motion, inc = self.vo.process(image, t)
                self.frames += 1
                if inc is None:
                    continue
                if not inc.ok:
                    self.failed += 1
                elif self.noise is not None:
                    inc = self.noise.apply([inc])[0]
                self.fusion.add_visual(inc)
                self.latency_ms.append((time.perf_counter() - arrival) * 1e3)
            except Exception:  # a frontend bug must not end the thread: logged once, counted
                self.errors += 1
                if self.errors == 1:
                    log.exception("camera frame at t=%.3f could not be processed", t)
