"""Where the KLT frontend's time goes, stage by stage, on one thread.

Runs visual odometry over a recording (default: the standard random60 drive, generated) with one thread
and adds up the CPU time of the calling thread (``time.thread_time``) spent in each stage, by wrapping
the functions that implement it:

=================  ==========================================================================
decode             reading and decoding the frame (the recording's frame reader)
forward LK         ``frontends.tracking.track_forward`` (warping the reference on turns included)
  warp             of which ``cv2.warpAffine`` of the reference (and of the exposure thumbnails)
  LK               of which ``cv2.calcOpticalFlowPyrLK`` (forward and backward passes)
backward check     ``frontends.tracking.check_backward``
similarity         ``frontends.similarity.estimate_similarity`` (RANSAC, least squares, covariance)
exposure           ``frontends.tracking.exposure_correction``
new corners        ``KltFrontend._detect``
dense check        ``frontends.direct.DenseFallback.verify`` (point estimates with few inliers)
derotation, ...    ``VisualOdometry.finish`` (gyro derotation, ground geometry, the track)
=================  ==========================================================================

``warp`` and ``LK`` count every call of those kernels (forward and backward passes, the exposure
thumbnails); they are part of the stages above them. The wrappers cost a few microseconds per call; the
total is the calling thread's CPU time per frame of the whole run. Usage::

    python benchmarks/profile_klt.py [--sequence SEQ] [--frames N] [--options JSON]
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import cv2

import frontends.direct as direct
import frontends.klt as klt
import frontends.tracking as tracking
import fusion_vo.odometry as odometry
import fusion_vo.recording.reader as reader
from fusion_vo.recording import Recording
from fusion_vo.simulation.standard import make_standard

spent: collections.Counter = collections.Counter()
calls: collections.Counter = collections.Counter()


def _timed(label: str, fn):
    def wrapper(*args, **kwargs):
        start = time.thread_time()
        try:
            return fn(*args, **kwargs)
        finally:
            spent[label] += time.thread_time() - start
            calls[label] += 1
    return wrapper


class _Cv2:
    """``cv2`` for the tracking module, with the two kernels that matter timed."""

    def __init__(self):
        self.warpAffine = _timed("  warp", cv2.warpAffine)
        self.calcOpticalFlowPyrLK = _timed("  LK", cv2.calcOpticalFlowPyrLK)

    def __getattr__(self, name):
        return getattr(cv2, name)


def instrument() -> None:
    """Wrap the stages (this process only)."""
    tracking.cv2 = _Cv2()
    klt.track_forward = _timed("forward LK", tracking.track_forward)
    klt.check_backward = _timed("backward check", tracking.check_backward)
    klt.estimate_similarity = _timed("similarity", klt.estimate_similarity)
    klt.exposure_correction = _timed("exposure", klt.exposure_correction)
    klt.KltFrontend._detect = _timed("new corners", klt.KltFrontend._detect)
    direct.DenseFallback.verify = _timed("dense check", direct.DenseFallback.verify)
    odometry.VisualOdometry.finish = _timed("derotation, geometry", odometry.VisualOdometry.finish)
    reader.read_image = _timed("decode", reader.read_image)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sequence", help="recording (default: the standard random60, generated)")
    ap.add_argument("--frames", type=int, help="the first N frames only")
    ap.add_argument("--options", type=json.loads, default={}, help="KLT options as JSON")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="profile-klt-") as tmp:
        seq = Path(args.sequence) if args.sequence else make_standard("random60", Path(tmp) / "random60")
        rec = Recording(seq)
        frames = None if args.frames is None else rec.frames(stop=args.frames)
        config = odometry.OdometryConfig(frontend="klt", threads=1, frontend_options=args.options)
        odometry.run_visual_odometry(Recording(seq), config, frames=Recording(seq).frames(stop=20))  # warm-up
        instrument()
        load = os.getloadavg()[0]
        start = time.thread_time()
        result = odometry.run_visual_odometry(rec, config, frames=frames)
        total = time.thread_time() - start
    n = result.n_frames
    print(f"{seq}: {n} frames, KLT {json.dumps(args.options)}, one thread; load average {load:.2f} before, "
          f"{os.getloadavg()[0]:.2f} after; CPU time of the calling thread per frame")
    print("| stage | ms per frame | share | calls | ms per call |")
    print("|---|---|---|---|---|")
    order = ["decode", "forward LK", "  warp", "  LK", "backward check", "similarity", "exposure", "new corners",
             "dense check", "derotation, geometry"]
    for label in order:
        seconds = spent[label]
        per_call = f"{1e3 * seconds / calls[label]:.3f}" if calls[label] else "–"
        print(f"| {label} | {1e3 * seconds / n:.3f} | {100 * seconds / total:.0f} % | {calls[label]} | {per_call} |")
    other = total - sum(spent[label] for label in order if not label.startswith(" "))
    print(f"| everything else (Python between the stages, prediction, checks) | {1e3 * other / n:.3f} | "
          f"{100 * other / total:.0f} % | | |")
    print(f"| all | {1e3 * total / n:.3f} | 100 % | | |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
