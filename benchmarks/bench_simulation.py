"""Frames per second of the recording generator, single-threaded, per stage.

Renders ``--frames`` frames of a drive over the gravel floor with the simulator's renderer and the
default camera (640 x 360, mild distortion, 0.1 m high), then reports the CPU time per frame of

* ``render``: ray casting the floor (``Renderer.radiance``: ray transform, texture sampling, box filter);
* ``photometry``: gain, noise, rounding to 8 bits;
* ``png``: writing the PNG file (``--png-compression``, default 0 as the simulator);

and the total in frames per second. ``--tilt`` renders a tilted camera (perspective ray transform
instead of the affine one of a level camera); ``--blur N`` averages N renders per frame as motion blur
does. Times are CPU times of this single-threaded process, so they describe one core even on a busy
machine. Usage::

    python benchmarks/bench_simulation.py [--frames 200] [--supersample 2] [--tilt 3] [--blur 1]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # single-threaded numerical libraries (before numpy loads)

import argparse
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from fusion_vo.geometry.camera import CameraModel
from fusion_vo.simulation.floor import Floor
from fusion_vo.simulation.mount import body_pose, camera_mount
from fusion_vo.simulation.photometry import Photometric, Photometry
from fusion_vo.simulation.render import Renderer


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--supersample", type=int, default=2)
    parser.add_argument("--tilt", type=float, default=0.0, help="camera tilt about its x axis [deg]")
    parser.add_argument("--blur", type=int, default=1, help="renders averaged per frame")
    parser.add_argument("--png-compression", type=int, default=0)
    args = parser.parse_args()
    cv2.setNumThreads(1)

    t0 = time.process_time()
    floor = Floor.photographed("gravel")
    T_BS = camera_mount(0.25, 0.10, tilt_x_deg=args.tilt)
    camera = CameraModel(640, 360, 420.0, 420.0, 319.5, 179.5, "radial-tangential",
                         [-0.03, 0.01, 0.0005, -0.0003], T_BS)
    renderer = Renderer(camera, floor, args.supersample)
    photo = Photometric(Photometry(), camera.width, camera.height)
    setup = time.process_time() - t0
    rng = np.random.default_rng(0)
    # a drive of 15 mm and 1.2 degrees per frame, with a blur exposure of a fifth of that
    poses = [[body_pose(0.015 * (i + k / 5), 0.002 * (i + k / 5), 0.02 * (i + k / 5)) @ T_BS
              for k in range(args.blur)] for i in range(args.frames)]
    png = [cv2.IMWRITE_PNG_COMPRESSION, args.png_compression]
    if args.png_compression == 0:  # as the simulator: no row filters for stored (uncompressed) data
        png += [cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_NONE]
    render = photometry = write = 0.0
    with tempfile.TemporaryDirectory() as tmp:
        for i, frame_poses in enumerate(poses):
            t0 = time.process_time()
            radiance = renderer.radiance_blurred(frame_poses)
            t1 = time.process_time()
            image = photo.apply(radiance, 0.05 * i, rng)
            t2 = time.process_time()
            cv2.imwrite(str(Path(tmp) / f"{i:06d}.png"), image, png)
            t3 = time.process_time()
            render += t1 - t0
            photometry += t2 - t1
            write += t3 - t2
    n = args.frames
    total = render + photometry + write
    print(f"640x360, supersample {args.supersample}, tilt {args.tilt:g} deg, {args.blur} render(s) per frame, "
          f"{n} frames, setup {setup:.2f} s (texture, rays)")
    print(f"  render      {1000 * render / n:6.2f} ms/frame")
    print(f"  photometry  {1000 * photometry / n:6.2f} ms/frame")
    print(f"  png         {1000 * write / n:6.2f} ms/frame")
    print(f"  total       {1000 * total / n:6.2f} ms/frame = {n / total:.1f} frames/s (one core)")


if __name__ == "__main__":
    main()
