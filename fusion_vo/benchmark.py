"""Speed of the visual odometry chain on a recording, single-threaded.

Three timings per frontend, per frame:

``decode``     reading and decoding the PNG (``cv2.imread``)
``frontend``   the frontend's ``process`` on the decoded image
``geometry``   rectification is inside the frontend; this is the similarity -> body increment step

Times are CPU time of the process (``time.process_time``) with OpenCV limited to one thread, so the
figures do not depend on what else the machine is doing. Frames per second are reported with decode
included (the end-to-end figure) and excluded. Memory is
sampled as the process's resident set size after each quarter of the frames: flat in recording length
means the last quarter is no larger than the first.
"""

from __future__ import annotations

import logging
import resource
import time
from dataclasses import dataclass, field
from pathlib import Path

import cv2

from frontends import make_frontend
from fusion_vo.geometry.ground import GroundGeometry
from fusion_vo.recording import Recording

log = logging.getLogger(__name__)


@dataclass
class FrontendTiming:
    """Per-frame timings [ms] of one frontend over a recording."""

    frontend: str
    frames: int
    decode_ms: float
    frontend_ms: float
    geometry_ms: float
    ok_fraction: float
    rss_mb: list = field(default_factory=list)

    @property
    def fps_end_to_end(self) -> float:
        return 1000.0 / (self.decode_ms + self.frontend_ms + self.geometry_ms)

    @property
    def fps_without_decode(self) -> float:
        return 1000.0 / (self.frontend_ms + self.geometry_ms)


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def time_frontend(sequence: str | Path, frontend: str, max_frames: int | None = None,
                  options: dict | None = None) -> FrontendTiming:
    """Time decode + frontend + geometry over the frames of a recording (one thread)."""
    cv2.setNumThreads(1)
    rec = Recording(sequence)
    geometry = GroundGeometry(rec.camera)
    fe = make_frontend(frontend, options or {}, point_map=geometry.rectifier)
    n = len(rec) if max_frames is None else min(max_frames, len(rec))
    dec = fro = geo = 0.0
    ok = 0
    rss = []
    quarter = max(n // 4, 1)
    frames = rec.frames(stop=n)  # decoding happens in next(): timed as decode
    for i in range(n):
        a = time.process_time()
        frame = next(frames)
        b = time.process_time()
        motion = fe.process(frame.image, frame.t)
        c = time.process_time()
        if motion.ok:
            geometry.increment(motion)
            ok += 1
        d = time.process_time()
        dec += b - a
        fro += c - b
        geo += d - c
        if (i + 1) % quarter == 0:
            rss.append(round(_rss_mb(), 1))
    return FrontendTiming(frontend, n, 1000 * dec / n, 1000 * fro / n, 1000 * geo / n,
                          ok / max(n - 1, 1), rss)


def format_timing(t: FrontendTiming) -> str:
    return (f"{t.frontend:<9} {t.frames:5d} frames  decode {t.decode_ms:6.3f} ms  frontend {t.frontend_ms:6.3f} ms  "
            f"geometry {t.geometry_ms:6.3f} ms  ->  {t.fps_end_to_end:7.1f} frames/s end to end, "
            f"{t.fps_without_decode:7.1f} without decode; ok {100 * t.ok_fraction:5.1f} %; "
            f"peak RSS by quarter {t.rss_mb} MB")


def summary_table(timings: list[FrontendTiming]) -> str:
    return "\n".join(format_timing(t) for t in timings)

