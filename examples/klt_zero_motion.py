"""The zero-motion KLT test of thesis section 3.3 (figures 3.3-3.5) on a generated standstill recording.

In the thesis neither the camera nor the floor moved, yet the tracked features' x and y positions
jumped between frames (feature #90 "moved" from (156.99, 177.08) to (343.98, 123.02) pixels) and the
algorithm reported large displacements. A correct tracker must see no motion beyond the image noise.

Here the simulator renders a robot standing still over a photographed gravel floor (the standard
recording ``standstill``: 5 s, sensor noise, no motion), in the three lighting variants of
``thesis_table_5_1.py`` (good light; a fixed specular highlight; dark: a quarter of the exposure and three
times the noise). For each, the script

1. tracks Shi-Tomasi corners of the first frame through every frame with OpenCV's pyramidal
   Lucas-Kanade (``cv2.calcOpticalFlowPyrLK``, frame to frame, as the thesis did) and reports how far
   they wander; for good light it plots their x and y positions over time (figures 3.3 and 3.4) and
   the corners of the first and last frame (figure 3.5) into ``klt_zero_motion.png``;
2. runs the project's visual odometry with both frontends and prints the estimated motion per frame
   (mean and largest translation [mm], largest rotation [deg]) and the position the visual track has
   drifted to at the end [mm]. Target: below 0.1 mm per frame.

Run::

    python examples/klt_zero_motion.py [--out DIR] [--seed N] [--quick] [--realistic]

``--realistic`` renders through the independent camera (``examples/common.py``); its renderer has no
specular highlight, so the spotlight rows are left out.

The plot is written to ``DIR/klt_zero_motion.png`` (``--out`` defaults to a temporary folder, so pass
it to keep the plot).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import cv2
import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from common import (FRONTENDS, LIGHTING, example_parser, fmt, format_table, generate, output_dir,  # noqa: E402
                    realistic_options)
from fusion_vo.odometry import OdometryConfig, run_visual_odometry  # noqa: E402
from fusion_vo.recording import Recording  # noqa: E402

#: features drawn in the plot
PLOTTED_FEATURES = 12


def track_corners(rec: Recording, max_corners: int = 100) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Track the first frame's corners frame to frame with pyramidal Lucas-Kanade.

    Returns
    -------
    t : ndarray, shape (F,)
        Frame times [s].
    xy : ndarray, shape (F, N, 2)
        Position of each corner in each frame [px] (NaN once lost).
    alive : ndarray, shape (N,), bool
        Corners tracked through all frames.
    first : ndarray
        The first image.
    """
    times, positions = [], []
    prev = pts = first = None
    status = None
    for frame in rec.frames():
        if frame.image is None:
            continue
        img = frame.image
        if prev is None:
            first = img
            pts = cv2.goodFeaturesToTrack(img, maxCorners=max_corners, qualityLevel=0.01, minDistance=12)
            status = np.ones(len(pts), bool)
        else:
            nxt, st, _ = cv2.calcOpticalFlowPyrLK(prev, img, pts, None, winSize=(21, 21), maxLevel=3)
            status &= st.ravel().astype(bool)
            pts = nxt
        xy = pts.reshape(-1, 2).astype(np.float64).copy()
        xy[~status] = np.nan
        times.append(frame.t)
        positions.append(xy)
        prev = img
    return np.asarray(times), np.asarray(positions), status, first


def plot_tracks(t: np.ndarray, xy: np.ndarray, alive: np.ndarray, first: np.ndarray, path: Path) -> None:
    """Figures 3.3-3.5: x and y of some tracked features over time (relative to their first position),
    and all corners of the first frame (circles) with their tracked positions in the last (plus signs)."""
    chosen = np.nonzero(alive)[0][:PLOTTED_FEATURES]
    fig = plt.figure(figsize=(13, 6))
    grid = fig.add_gridspec(2, 2, width_ratios=(1.3, 1.0))
    ax_x = fig.add_subplot(grid[0, 0])
    ax_y = fig.add_subplot(grid[1, 0], sharex=ax_x)
    rel_t = t - t[0]
    for axis, (ax, name) in enumerate(zip((ax_x, ax_y), ("x", "y"))):
        for i in chosen:
            ax.plot(rel_t, xy[:, i, axis] - xy[0, i, axis], lw=1, label=f"feature {i}")
        ax.set_ylabel(f"{name} - {name}(0) [px]")
        ax.grid(alpha=0.3)
    spread = float(np.nanmax(np.abs(xy[:, chosen] - xy[:1, chosen]))) if len(chosen) else 0.0
    ax_x.set_title(f"Tracked feature positions (largest excursion {spread:.3f} px)")
    ax_y.set_xlabel("time [s]")
    ax_x.legend(ncol=4, fontsize=7, loc="upper right")
    ax_img = fig.add_subplot(grid[:, 1])
    ax_img.imshow(first, cmap="gray", vmin=0, vmax=255)
    ax_img.plot(xy[0, :, 0], xy[0, :, 1], "o", mfc="none", mec="red", ms=7, label="first frame")
    ax_img.plot(xy[-1, alive, 0], xy[-1, alive, 1], "+", color="deepskyblue", ms=7, label="last frame")
    ax_img.set_title("Corners in the first and the last frame")
    ax_img.legend(fontsize=8, loc="lower right")
    ax_img.set_axis_off()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def motion_row(vo) -> list[str]:
    """Frames, failures, motion per frame and end drift of a visual odometry run (table cells)."""
    ok = [inc for inc in vo.increments if inc.ok]
    moves = np.array([1e3 * math.hypot(inc.delta[0], inc.delta[1]) for inc in ok] or [np.nan])
    turns = np.array([math.degrees(abs(inc.delta[2])) for inc in ok] or [np.nan])
    end = vo.track.xyyaw[-1]
    return [str(vo.n_frames), str(sum(vo.failures.values())), fmt(np.mean(moves), 5), fmt(np.max(moves), 5),
            fmt(np.max(turns), 5), fmt(1e3 * math.hypot(end[0], end[1]), 4), fmt(math.degrees(abs(end[2])), 4),
            "yes" if np.max(moves) < 0.1 else "no"]


def main(argv=None) -> int:
    parser = example_parser(__doc__.split("\n\n")[0])
    args = parser.parse_args(argv)
    options = {"duration": 2.0} if args.quick else {}
    with output_dir(args.out) as out:
        t_start = time.perf_counter()
        corner_rows, motion_rows = [], []
        png = out / "klt_zero_motion.png"
        for light, lighting in LIGHTING.items():
            if args.realistic:
                lighting = realistic_options(light)
                if lighting is None:
                    continue
            seq = generate("standstill", out / f"standstill-{light.replace(' ', '-')}", args.seed,
                           **options, **lighting)
            rec = Recording(seq)
            t, xy, alive, first = track_corners(rec)
            if not corner_rows:
                plot_tracks(t, xy, alive, first, png)
            excursion = np.abs(xy[:, alive] - xy[:1, alive])
            step = np.linalg.norm(np.diff(xy[:, alive], axis=0), axis=2)
            corner_rows.append([light, str(len(rec)), str(xy.shape[1]), str(int(alive.sum())),
                                fmt(np.max(excursion[..., 0]), 4), fmt(np.max(excursion[..., 1]), 4),
                                fmt(np.mean(step), 4), fmt(np.max(step), 4)])
            for frontend in FRONTENDS:
                vo = run_visual_odometry(rec, OdometryConfig(frontend=frontend))
                motion_rows.append([light, frontend] + motion_row(vo))
            print(f"{light}: {len(rec)} frames done ({time.perf_counter() - t_start:.0f} s)", flush=True)
        print()
        print(format_table("Figures 3.3-3.5: corners tracked by OpenCV pyramidal LK while standing still",
                           ["lighting", "frames", "corners", "tracked to end", "max |dx| px", "max |dy| px",
                            "mean step px", "max step px"], corner_rows))
        print()
        print(format_table("Estimated motion per frame while standing still",
                           ["lighting", "frontend", "frames", "failed", "mean mm/frame", "max mm/frame",
                            "max deg/frame", "end drift mm", "end yaw deg", "< 0.1 mm"], motion_rows))
        print(f"\nwrote {png} (good light)" if args.out is not None else "\n(pass --out DIR to keep the plot)")
        print(f"total time {time.perf_counter() - t_start:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
