"""Scoring trajectories against GPS fixes, for recordings without ground truth (no evo needed).

For each trajectory the antenna's position ``h(x(t_i)) = p(t_i) + R(ψ(t_i)) l`` (the lever arm ``l`` of
``gps0/sensor.yaml``, poses interpolated at the fix times ``t_i`` within the trajectory) is compared with
the fixes ``z_i`` in East-North-Up at the datum:

* when the run did not fuse GPS (``gps`` not among ``run.yaml``'s ``sensors``) the trajectory lives in a
  frame of its own: the antenna positions are first carried onto the fixes by the weighted
  least-squares rigid transform (SE(2): heading and offset, no scale), reweighted so that multipath
  jumps in the fixes do not bend it (:func:`fusion_vo.sensors.gps.robust_fit_rigid_2d`);
* when it did, the trajectory is already in ENU and is scored as it is.

The figures are the RMS, median and largest horizontal distance ``|h(x(t_i)) - z_i|`` over every fix in
the trajectory's span. They include the fixes' own noise and any multipath jump in them: a jump shows in
the RMS and the maximum, while the median stays a measure of the track. Fixes further from the track
than 5 robust standard deviations (``5 · 1.4826 · median``) are counted as outliers, and the RMS is also
given without them.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from fusion_vo.errors import InputError
from fusion_vo.evaluation.io import read_tum_poses
from fusion_vo.evaluation.plots import colour_of, label_of, save_figure
from fusion_vo.geometry import se2
from fusion_vo.measurements import GpsData
from fusion_vo.sensors.gps import interpolate_poses, predict, robust_fit_rigid_2d

logger = logging.getLogger(__name__)

#: (key in metrics.json, header, format) of the GPS figures
GPS_COLUMNS = (
    ("gps_rms_m", "RMS [m]", "{:.3f}"),
    ("gps_rms_inliers_m", "RMS inliers [m]", "{:.3f}"),
    ("gps_median_m", "median [m]", "{:.3f}"),
    ("gps_max_m", "max [m]", "{:.3f}"),
    ("gps_fixes", "fixes", "{:d}"),
    ("gps_outliers", "outliers", "{:d}"),
)


@dataclass
class GpsScore:
    """A trajectory against the fixes: figures and the antenna track in ENU (as plotted)."""

    t: np.ndarray
    antenna: np.ndarray
    fixes: np.ndarray
    aligned: bool
    yaw_deg: float

    @property
    def errors(self) -> np.ndarray:
        return np.linalg.norm(self.antenna - self.fixes, axis=1)

    @property
    def outliers(self) -> np.ndarray:
        """Fixes further than 5 robust standard deviations (``1.4826 · median``) from the track."""
        e = self.errors
        return e > 5.0 * 1.4826 * float(np.median(e))

    @property
    def figures(self) -> dict:
        e = self.errors
        inl = ~self.outliers
        return {"gps_rms_m": float(np.sqrt(np.mean(e**2))), "gps_rms_inliers_m": float(np.sqrt(np.mean(e[inl]**2))),
                "gps_outliers": int(np.count_nonzero(~inl)), "gps_median_m": float(np.median(e)),
                "gps_max_m": float(np.max(e)), "gps_fixes": int(len(e)),
                "gps_frame": "SE(2)-aligned" if self.aligned else "ENU (GPS fused)",
                "gps_alignment_yaw_deg": self.yaw_deg}


def gps_was_fused(config: dict) -> bool:
    """Whether a run fused GPS, from the ``sensors`` it recorded in ``run.yaml``."""
    return "gps" in (config.get("sensors") or [])


def score_track(t: np.ndarray, xyyaw: np.ndarray, gps: GpsData, fused: bool) -> GpsScore | None:
    """Score one trajectory against the fixes within its time span (module docstring).

    Returns ``None`` when fewer than 3 fixes fall within the trajectory.
    """
    inside = np.flatnonzero((gps.t >= t[0]) & (gps.t <= t[-1]))
    if len(inside) < 3:
        return None
    antenna = predict(interpolate_poses(t, xyyaw, gps.t[inside]), gps.lever_arm)
    fixes = gps.enu[inside, :2]
    yaw = 0.0
    if not fused:
        w = 2.0 / np.trace(gps.covariance[inside], axis1=1, axis2=2)
        yaw, offset, _ = robust_fit_rigid_2d(antenna, fixes, w)
        c, s = math.cos(yaw), math.sin(yaw)
        antenna = antenna @ np.array([[c, s], [-s, c]]) + offset
    return GpsScore(gps.t[inside], antenna, fixes, not fused, math.degrees(yaw))


def evaluate_against_gps(run_dir: Path, files: dict[str, Path], gps: GpsData, config: dict,
                         source: Path | None = None) -> tuple[dict[str, dict], dict[str, Path]]:
    """Score every trajectory file of a run against the fixes and draw ``gps.png``.

    ``source`` (the fixes' file) is named in the error raised when no trajectory overlaps the fixes in
    time, as when the fixes are stamped on another clock.

    Returns
    -------
    metrics : dict
        Trajectory name -> GPS figures (for ``metrics.json``).
    images : dict
        Caption -> PNG path.
    """
    fused = gps_was_fused(config)
    scores: dict[str, GpsScore] = {}
    spans = []
    for name, path in files.items():
        poses = read_tum_poses(path)
        spans.append((float(poses.t[0]), float(poses.t[-1])))
        xyyaw = np.column_stack([poses.xyz[:, :2], se2.yaw_of_quaternion(poses.quat_wxyz)])
        score = score_track(poses.t, xyyaw, gps, fused)
        if score is None:
            logger.warning("%s: fewer than 3 GPS fixes within its time span, not scored", path)
            continue
        scores[name] = score
    if not scores:
        lo, hi = min(a for a, _ in spans), max(b for _, b in spans)
        raise InputError(f"no trajectory has 3 GPS fixes within its time span (fixes {gps.t[0]:.3f} to {gps.t[-1]:.3f} s, "
                         f"trajectories {lo:.3f} to {hi:.3f} s): are the fixes on another clock?", source)
    metrics = {name: s.figures for name, s in scores.items()}
    caption = ("Trajectories (antenna positions, each SE(2)-aligned to the fixes) and the GPS fixes in ENU"
               if not fused else "Trajectories (antenna positions, GPS fused: not aligned) and the GPS fixes in ENU")
    images = {caption: plot_fixes(gps, scores, run_dir / "gps.png")}
    return metrics, images


def plot_fixes(gps: GpsData, scores: dict[str, GpsScore], path: Path) -> Path:
    """Plan view of the fixes (grey dots) and the scored antenna tracks, in ENU metres."""
    fig = Figure(figsize=(8, 7), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    ax.plot(gps.enu[:, 0], gps.enu[:, 1], ".", color="0.55", markersize=4, label=f"GPS fixes ({len(gps)})")
    for name, s in scores.items():
        ax.plot(s.antenna[:, 0], s.antenna[:, 1], "-", color=colour_of(name), linewidth=1.3,
                label=f"{label_of(name)}: RMS {s.figures['gps_rms_m']:.2f} m")
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    return save_figure(fig, path)


def gps_frame(metrics: dict[str, dict]) -> str:
    """How the trajectories were compared with the fixes: ``SE(2)-aligned`` or ``ENU (GPS fused)``."""
    return next((f["gps_frame"] for f in metrics.values() if "gps_frame" in f), "")


def gps_table(metrics: dict[str, dict]) -> tuple[list[str], list[list[str]]]:
    """Headers and rows of the GPS figures, one row per trajectory that has them."""
    headers = ["trajectory"] + [h for _, h, _ in GPS_COLUMNS]
    rows = []
    for name, figures in metrics.items():
        if "gps_rms_m" not in figures:
            continue
        rows.append([name] + [fmt.format(figures[key]) if figures.get(key) is not None else "\u2013"
                              for key, _, fmt in GPS_COLUMNS])
    return headers, rows
