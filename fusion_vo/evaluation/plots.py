"""Figures of a run: trajectories, velocities, heading, error growth and frontend health.

Every function draws one PNG with matplotlib's object interface (:class:`matplotlib.figure.Figure` and
the Agg canvas, no pyplot state) and writes it atomically. Each source has one colour everywhere
(:data:`COLOURS`); ground truth is black.
"""

from __future__ import annotations

import io
import logging
import zlib
from pathlib import Path

from typing import TYPE_CHECKING

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from PIL import Image
from PIL.PngImagePlugin import PngInfo

from fusion_vo.geometry.se2 import yaw_of_quaternion
from fusion_vo.evaluation.io import FRAME_STATUSES, FrameVelocities, write_atomic
from fusion_vo.outputs import PNG_SOFTWARE

if TYPE_CHECKING:  # evo (GPL-3.0, the ``eval`` extra) only for the trajectory plots, not for plot_matches
    from evo.core.trajectory import PoseTrajectory3D

    from fusion_vo.evaluation.metrics import TrajectoryErrors, Velocities

logger = logging.getLogger(__name__)

#: colour of each source in every figure
COLOURS = {
    "groundtruth": "black",
    "vo": "tab:blue",
    "wheel": "tab:orange",
    "ekf": "tab:green",
    "ekf_smoothed": "tab:olive",
    "gtsam": "tab:red",
    "gtsam_online": "tab:purple",
    "gyro": "tab:cyan",
    "ahrs": "tab:pink",
    "gps": "0.45",
}

#: legend label of each source
LABELS = {
    "groundtruth": "ground truth",
    "vo": "visual",
    "wheel": "wheel",
    "ekf": "EKF",
    "ekf_smoothed": "EKF smoothed",
    "gtsam": "GTSAM batch",
    "gtsam_online": "GTSAM online",
    "gyro": "gyro (integrated)",
    "ahrs": "AHRS",
    "gps": "GPS fixes",
}

_SPARE_COLOURS = ("tab:brown", "tab:gray", "gold", "navy", "teal", "maroon")
_RUN_COLOURS = ("tab:blue", "tab:red", "tab:green", "tab:orange", "tab:purple", "tab:brown",
                "tab:pink", "tab:cyan", "tab:olive", "tab:gray")
_STATUS_COLOURS = {"first": "tab:gray", "too_few_features": "tab:orange", "degenerate": "tab:purple",
                   "rejected": "tab:red", "bad_frame": "tab:brown"}


def colour_of(name: str) -> str:
    """Colour of a source; names outside :data:`COLOURS` get a fixed spare colour."""
    if name in COLOURS:
        return COLOURS[name]
    return _SPARE_COLOURS[zlib.crc32(name.encode()) % len(_SPARE_COLOURS)]


def label_of(name: str) -> str:
    """Legend label of a source."""
    return LABELS.get(name, name)


def new_figure(rows: int = 1, height: float = 4.0, width: float = 8.0, sharex: bool = True):
    """A figure (Agg canvas, constrained layout) with ``rows`` axes stacked vertically; returns (figure, axes)."""
    fig = Figure(figsize=(width, height * rows), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, 1, sharex=sharex, squeeze=False)[:, 0]
    return fig, axes


#: zlib level of the figures' PNG files (:func:`figure_png`)
PNG_COMPRESS_LEVEL = 3


def figure_png(fig: Figure) -> bytes:
    """``fig`` as PNG bytes: the pixels of ``fig.savefig(format="png")``, drawn once, as RGB at zlib level
    :data:`PNG_COMPRESS_LEVEL`, with the ``Software`` text :data:`~fusion_vo.outputs.PNG_SOFTWARE` (how the
    program's pictures are told from the user's).

    ``savefig`` draws a figure with a layout engine twice, once for the layout and once for the pixels; a
    report's figures spend most of their time there. The figures are opaque, so RGB at level 3 carries the same
    pixels as RGBA at Pillow's default level 6 in half the encoding time, for files about 10 % larger.
    """
    canvas = fig.canvas if isinstance(fig.canvas, FigureCanvasAgg) else FigureCanvasAgg(fig)
    canvas.draw()  # (lays the figure out and renders it)
    buffer = io.BytesIO()
    info = PngInfo()
    info.add_text("Software", PNG_SOFTWARE)
    Image.fromarray(np.asarray(canvas.buffer_rgba())[..., :3]).save(
        buffer, format="png", pnginfo=info, dpi=(fig.dpi, fig.dpi), compress_level=PNG_COMPRESS_LEVEL)
    return buffer.getvalue()


def save_figure(fig: Figure, path: str | Path) -> Path:
    """Write ``fig`` as PNG to ``path`` atomically (:func:`figure_png`)."""
    logger.debug("writing %s", path)
    return write_atomic(path, figure_png(fig))


def _xy(trajectory) -> np.ndarray:
    """Positions on the floor of an evo trajectory or of planar poses (:class:`~fusion_vo.measurements.PoseData`)."""
    if hasattr(trajectory, "xyyaw"):
        return np.asarray(trajectory.xyyaw)[:, :2]
    return trajectory.positions_xyz[:, :2]


def plot_trajectories(reference: PoseTrajectory3D | None, estimates: dict[str, PoseTrajectory3D],
                      path: str | Path, title: str = "Trajectories") -> Path:
    """Overlay the paths on the floor with start (circle) and end (triangle) marked.

    Parameters
    ----------
    reference : PoseTrajectory3D or None
        Ground truth, drawn in black.
    estimates : dict
        Source name -> trajectory (already in the reference's frame, e.g. anchored at its start).
    path : str or Path
        PNG to write.
    """
    fig, (ax,) = new_figure(height=6.5, width=7.5)
    series = ([("groundtruth", reference)] if reference is not None else []) + list(estimates.items())
    for name, trajectory in series:
        xy = _xy(trajectory)
        colour = colour_of(name)
        width = 2.2 if name == "groundtruth" else 1.4
        ax.plot(xy[:, 0], xy[:, 1], color=colour, lw=width, label=label_of(name))
        ax.plot(*xy[0], marker="o", color=colour, ms=8, mfc="white", mew=2)
        ax.plot(*xy[-1], marker="^", color=colour, ms=9)
    ax.plot([], [], "o", color="grey", mfc="white", mew=2, label="start")
    ax.plot([], [], "^", color="grey", label="end")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    return save_figure(fig, path)


def _start_time(stamps: list[np.ndarray], t0: float | None) -> float:
    if t0 is not None:
        return t0
    starts = [s[0] for s in stamps if s.size]
    return float(min(starts)) if starts else 0.0


def plot_velocities(reference: Velocities | None, estimates: dict[str, Velocities],
                    path: str | Path, t0: float | None = None) -> Path:
    """Forward velocity, lateral velocity and yaw rate over time, each source against ground truth.

    Time is shown from ``t0`` (default: the earliest sample).
    """
    fig, axes = new_figure(rows=3, height=2.6, width=9.0)
    rows = (("vx", "$v_x$ [m/s]", 1.0), ("vy", "$v_y$ [m/s]", 1.0), ("yaw_rate", "yaw rate [deg/s]",
                                                                       180.0 / np.pi))
    series = ([("groundtruth", reference)] if reference is not None else []) + list(estimates.items())
    series = [(name, vel) for name, vel in series if vel is not None and vel.t.size]
    t0 = _start_time([vel.t for _, vel in series], t0)
    for ax, (key, ylabel, factor) in zip(axes, rows):
        for name, vel in series:
            width = 2.0 if name == "groundtruth" else 1.0
            ax.plot(vel.t - t0, getattr(vel, key) * factor, color=colour_of(name), lw=width,
                    label=label_of(name), alpha=1.0 if name == "groundtruth" else 0.85)
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
    axes[0].set_title("Body velocities")
    if series:
        fig.legend(*axes[0].get_legend_handles_labels(), loc="outside lower center", ncol=len(series),
                   fontsize="small")
    axes[-1].set_xlabel("time [s]")
    return save_figure(fig, path)


def plot_heading(reference: PoseTrajectory3D | None, estimates: dict[str, PoseTrajectory3D],
                 path: str | Path, t0: float | None = None) -> Path:
    """Unwrapped heading (yaw) over time from ``t0`` (default: the earliest pose)."""
    fig, (ax,) = new_figure(height=4.0, width=9.0)
    series = ([("groundtruth", reference)] if reference is not None else []) + list(estimates.items())
    t0 = _start_time([trajectory.timestamps for _, trajectory in series], t0)
    for name, trajectory in series:
        yaw = np.degrees(np.unwrap(yaw_of_quaternion(trajectory.orientations_quat_wxyz)))
        ax.plot(trajectory.timestamps - t0, yaw, color=colour_of(name),
                lw=2.0 if name == "groundtruth" else 1.2, label=label_of(name))
    ax.set_xlabel("time [s]")
    ax.set_ylabel("heading [deg]")
    ax.set_title("Heading")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    return save_figure(fig, path)


def plot_error_vs_distance(results: dict[str, TrajectoryErrors], path: str | Path) -> Path:
    """Position error (estimate anchored at the start) against ground-truth distance travelled."""
    fig, (ax,) = new_figure(height=4.0, width=9.0)
    for name, result in results.items():
        ax.plot(result.distance, result.error_m, color=colour_of(name), lw=1.4, label=label_of(name))
    ax.set_xlabel("distance travelled [m]")
    ax.set_ylabel("position error [m]")
    ax.set_title("Error growth (anchored at the start)")
    ax.grid(True, alpha=0.3)
    if results:
        ax.legend(loc="upper left", fontsize="small")
    return save_figure(fig, path)


def plot_frontend(frames: FrameVelocities, path: str | Path) -> Path:
    """Inlier count per frame with the frames the frontend could not use marked by reason."""
    fig, (ax,) = new_figure(height=3.5, width=9.0)
    t = frames.t - (frames.t[0] if frames.t.size else 0.0)
    ax.plot(t, frames.inliers, color=COLOURS["vo"], lw=1.0, label="inliers")
    status = np.array(frames.status)
    top = max(1, int(frames.inliers.max())) if frames.inliers.size else 1
    for reason in FRAME_STATUSES[1:]:
        mask = status == reason
        if np.any(mask):
            ax.plot(t[mask], np.full(mask.sum(), -0.04 * top), "|", ms=12, mew=2,
                    color=_STATUS_COLOURS[reason], label=f"{reason} ({int(mask.sum())})")
    ok = int(np.sum(status == "ok"))
    ax.set_title(f"Visual frontend: {ok} of {len(status)} frames ok")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("inliers")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper right", fontsize="small", ncol=3)
    return save_figure(fig, path)


def plot_compare(reference: PoseTrajectory3D | None, runs: dict[str, dict], path: str | Path,
                 anchored: bool = True) -> Path:
    """Overlay the trajectories of several runs: one colour per run, one line style per source.

    ``runs`` maps run label -> source -> trajectory (evo, anchored at the ground-truth start, or planar poses
    as estimated: ``anchored`` False)."""
    styles = ("-", "--", "-.", ":")
    fig, (ax,) = new_figure(height=6.5, width=8.0)
    if reference is not None:
        xy = _xy(reference)
        ax.plot(xy[:, 0], xy[:, 1], color="black", lw=2.2, label=label_of("groundtruth"))
        ax.plot(*xy[0], marker="o", color="black", ms=8, mfc="white", mew=2)
    sources = sorted({s for run in runs.values() for s in run}, key=lambda s: (s not in LABELS, s))
    for k, (label, trajectories) in enumerate(runs.items()):
        colour = _RUN_COLOURS[k % len(_RUN_COLOURS)]
        for name, trajectory in trajectories.items():
            xy = _xy(trajectory)
            style = styles[sources.index(name) % len(styles)]
            ax.plot(xy[:, 0], xy[:, 1], color=colour, ls=style, lw=1.4, label=f"{label}: {label_of(name)}")
            ax.plot(*xy[-1], marker="^", color=colour, ms=8)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title("Runs compared (anchored at the ground-truth start)" if anchored
                 else "Runs compared (tracks as estimated)")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    return save_figure(fig, path)


def plot_matches(image: np.ndarray, matches, path: str | Path, title: str = "") -> Path:
    """Matched corners drawn on the current frame (thesis figures 4.8 and 5.7).

    Blue stars: corners in the previous frame; red circles: the same corners in the current frame; a line
    joins each pair, coloured for inliers of the estimated motion and grey for outliers.

    Parameters
    ----------
    image : ndarray
        The current frame (grey).
    matches : fusion_vo.evaluation.matches.FrameMatches
    path : str or Path
        PNG to write.
    """
    h, w = image.shape[:2]
    fig = Figure(figsize=(9.0, 9.0 * h / w + 0.6), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    ax.imshow(image, cmap="gray", interpolation="nearest")
    for mask, colour, label in ((~matches.inliers, "0.6", "outlier"), (matches.inliers, "yellow", "inlier")):
        if np.any(mask):
            p0, p1 = matches.previous[mask], matches.current[mask]
            xs = np.stack([p0[:, 0], p1[:, 0], np.full(len(p0), np.nan)], axis=1).ravel()
            ys = np.stack([p0[:, 1], p1[:, 1], np.full(len(p0), np.nan)], axis=1).ravel()
            ax.plot(xs, ys, color=colour, lw=1.0, label=f"{label} ({int(mask.sum())})")
    if len(matches.previous):
        ax.plot(matches.previous[:, 0], matches.previous[:, 1], "*", color="tab:blue", ms=7,
                label="previous frame")
        ax.plot(matches.current[:, 0], matches.current[:, 1], "o", mfc="none", mec="red", ms=7, mew=1.2,
                label="current frame")
    ax.set_xlim(-0.5, w - 0.5)
    ax.set_ylim(h - 0.5, -0.5)
    ax.set_title(title or f"{len(matches.previous)} matches, {matches.n_inliers} inliers")
    if len(matches.previous):  # nothing matched (a textureless floor): no legend, and no warning about it
        ax.legend(loc="upper right", fontsize="small", framealpha=0.8)
    ax.set_xlabel("u [px]")
    ax.set_ylabel("v [px]")
    return save_figure(fig, path)
