"""Figures of a run that need no ground truth: the tracks of every source, their headings and differences,
the normalised innovations against their chi-square band, and the influence of each input.

Like :mod:`fusion_vo.evaluation.plots` (whose colours, labels and figure helpers they share), every
function draws one PNG with matplotlib's object interface and writes it atomically; none needs evo.
Lengths are shown in the unit that fits them (:func:`length_unit`), and an axis whose values span more
than :data:`LOG_SPAN` decades' worth of ratio is logarithmic, so that one dominating track does not flatten
the others.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from fusion_vo.backends.result import Innovations
from fusion_vo.evaluation.headings import Headings
from fusion_vo.evaluation.innovations import BAND_PROBABILITY, band, groups
from fusion_vo.evaluation.plots import colour_of, label_of, new_figure, save_figure
from fusion_vo.geometry import se2
from fusion_vo.measurements import PoseData
from fusion_vo.sensors.gps import interpolate_poses

#: a positive axis is drawn logarithmically when its largest value exceeds its smallest by this ratio
LOG_SPAN = 30.0
#: a track whose extent is this many times the median extent of the others leaves the plan view's frame
DOMINANT = 10.0
#: fused tracks are drawn solid and thick, the sources' own tracks thinner and dashed
FUSED = ("ekf", "ekf_smoothed", "gtsam", "gtsam_online", "gtsam_fixed_lag")


def length_unit(values) -> tuple[float, str]:
    """``(factor, unit)`` for lengths in metres: millimetres when the largest is below 0.1 m, else metres."""
    finite = np.abs(np.asarray(values, dtype=np.float64))
    finite = finite[np.isfinite(finite)]
    return (1e3, "mm") if finite.size and finite.max() < 0.1 else (1.0, "m")


def use_log(values) -> bool:
    """Whether positive ``values`` span more than :data:`LOG_SPAN` (one dominates the others)."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v) & (v > 0)]
    return bool(v.size >= 2 and v.max() > LOG_SPAN * max(float(np.percentile(v, 10)), 1e-12))


def _extent(xy: np.ndarray) -> float:
    return float(np.max(np.ptp(xy, axis=0))) if len(xy) else 0.0


def plot_tracks(tracks: dict[str, PoseData], path: str | Path, title: str,
                gps: tuple[np.ndarray, str] | None = None) -> tuple[Path, list[str]]:
    """Plan view of every track (start: circle, end: triangle), with GPS fixes as grey dots.

    ``gps`` is ``(east-north (N, 2) in the tracks' frame, label)``. A track whose extent is :data:`DOMINANT`
    times the others' median leaves the frame (the frame fits the others) and is named in the legend.
    Returns the PNG and the names of the tracks that leave the frame.
    """
    fig, (ax,) = new_figure(height=6.5, width=8.0)
    extents = {name: _extent(track.xyyaw[:, :2]) for name, track in tracks.items()}
    others = sorted(extents.values())
    outside = []
    if len(others) >= 3:
        median = float(np.median(others))
        outside = [n for n, e in extents.items() if median > 0 and e > DOMINANT * median]
    inside = [n for n in tracks if n not in outside] or list(tracks)
    scale, unit = length_unit([extents[n] for n in inside] + ([_extent(gps[0])] if gps is not None else []))
    if gps is not None and len(gps[0]):
        ax.plot(gps[0][:, 0] * scale, gps[0][:, 1] * scale, ".", color=colour_of("gps"), ms=3, label=gps[1])
    for name, track in tracks.items():
        xy = track.xyyaw[:, :2] * scale
        colour = colour_of(name)
        fused = name in FUSED
        label = label_of(name) + (f" (leaves the frame: {extents[name]:.3g} m across)" if name in outside else "")
        ax.plot(xy[:, 0], xy[:, 1], color=colour, lw=1.6 if fused else 1.1, ls="-" if fused else "--", label=label)
        ax.plot(*xy[0], marker="o", color=colour, ms=7, mfc="white", mew=1.5)
        ax.plot(*xy[-1], marker="^", color=colour, ms=8)
    if outside:
        xy = np.vstack([tracks[n].xyyaw[:, :2] for n in inside]) * scale
        lo, hi = xy.min(axis=0), xy.max(axis=0)
        pad = 0.1 * max(float(np.max(hi - lo)), 1e-9)
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(f"x [{unit}]")
    ax.set_ylabel(f"y [{unit}]")
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    return save_figure(fig, path), outside


def plot_headings(tracks: dict[str, PoseData], headings: Headings | None, path: str | Path, t0: float) -> Path:
    """Heading over time of every track, the gyro's integrated heading and the AHRS heading [deg]."""
    fig, (ax,) = new_figure(height=4.2, width=9.0)
    for name, track in tracks.items():
        fused = name in FUSED
        ax.plot(track.t - t0, np.degrees(np.unwrap(track.xyyaw[:, 2])), color=colour_of(name),
                lw=1.5 if fused else 1.0, ls="-" if fused else "--", label=label_of(name))
    if headings is not None:
        ax.plot(headings.t - t0, np.degrees(headings.gyro), color=colour_of("gyro"), lw=1.0, ls=":",
                label=label_of("gyro"))
        if headings.ahrs is not None:
            ax.plot(headings.t - t0, np.degrees(headings.ahrs), color=colour_of("ahrs"), lw=1.0, ls="-.",
                    label=label_of("ahrs"))
    ax.set_xlabel("time [s]")
    ax.set_ylabel("heading [deg] (unwrapped)")
    ax.set_title("Heading of every source")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small", ncol=2)
    return save_figure(fig, path)


def track_differences(tracks: dict[str, PoseData], reference: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each track's horizontal distance [m] from ``reference`` at the reference's times within its span:
    name -> ``(t, d)`` (tracks that share fewer than two times are left out)."""
    ref = tracks[reference]
    out = {}
    for name, track in tracks.items():
        if name == reference or len(track) < 2:
            continue
        inside = (ref.t >= track.t[0]) & (ref.t <= track.t[-1])
        if np.count_nonzero(inside) < 2:
            continue
        est = interpolate_poses(track.t, track.xyyaw, ref.t[inside])
        out[name] = (ref.t[inside], np.linalg.norm(est[:, :2] - ref.xyyaw[inside, :2], axis=1))
    return out


def plot_differences(differences: dict[str, tuple[np.ndarray, np.ndarray]], reference: str, path: str | Path,
                     t0: float, title: str | None = None) -> Path:
    """Distance of each track from the reference over time (as estimated: not aligned), in mm or m; a log
    axis when one track dominates."""
    fig, (ax,) = new_figure(height=4.0, width=9.0)
    values = np.concatenate([d for _, d in differences.values()]) if differences else np.zeros(0)
    scale, unit = length_unit(values)
    log = use_log([d.max() for _, d in differences.values() if d.size])
    for name, (t, d) in differences.items():
        y = d * scale
        ax.plot(t - t0, np.where(y > 0, y, np.nan) if log else y, color=colour_of(name), lw=1.2,
                ls="-" if name in FUSED else "--", label=label_of(name))
    if log:
        ax.set_yscale("log")
    ax.set_xlabel("time [s]")
    ax.set_ylabel(f"distance from {label_of(reference)} [{unit}]" + (" (log)" if log else ""))
    ax.set_title(title or f"How far each track is from {label_of(reference)} (as estimated, not aligned)")
    ax.grid(True, alpha=0.3, which="both")
    if differences:
        ax.legend(loc="best", fontsize="small")
    return save_figure(fig, path)


def _running_mean(x: np.ndarray, n: int) -> np.ndarray:
    if len(x) < n:
        return np.full(len(x), np.nan)
    c = np.concatenate([[0.0], np.cumsum(x)])
    out = np.full(len(x), np.nan)
    out[n - 1:] = (c[n:] - c[:-n]) / n
    return out


def plot_nis(tables: dict[str, Innovations], backend: str, path: str | Path, t0: float, window: int = 25,
             gate: dict[int, float] | None = None) -> Path:
    """Each sensor's NIS over time for ``backend``: single values as dots (log axis; down-weighted orange,
    rejected red crosses), their running mean over ``window`` blocks (line), the 95 % band of that mean (shaded)
    and of a single value (dotted), and the gate (dashed, ``gate``: dof -> threshold)."""
    rows = [g for g in groups(tables) if g[0] == backend]
    fig, axes = new_figure(rows=max(len(rows), 1), height=2.3, width=9.0)
    table = tables.get(backend)
    for ax, (_, sensor, dof, idx) in zip(axes, rows):
        t = table.t[idx] - t0
        d2 = np.maximum(table.d2[idx], 1e-6)
        status = table.status[idx]
        n = min(window, len(d2))
        lo1, hi1 = band(dof)
        lon, hin = band(dof, n)
        ax.axhspan(lon, hin, color="tab:green", alpha=0.15, lw=0,
                   label=f"{100 * BAND_PROBABILITY:.0f} % band of a mean of {n}")
        ax.axhline(lo1, color="tab:green", ls=":", lw=0.8)
        ax.axhline(hi1, color="tab:green", ls=":", lw=0.8, label=f"{100 * BAND_PROBABILITY:.0f} % band of one value")
        if gate and dof in gate and math.isfinite(gate[dof]):
            ax.axhline(gate[dof], color="tab:red", ls="--", lw=0.8, label="gate")
        used = status == "used"
        ax.plot(t[used], d2[used], ".", ms=2, color="0.55", label="NIS of one block")
        for kind, marker, colour in (("down-weighted", ".", "tab:orange"), ("rejected", "x", "tab:red")):
            sel = status == kind
            if np.any(sel):
                ax.plot(t[sel], d2[sel], marker, ms=4, color=colour, label=f"{kind} ({int(sel.sum())})")
        ax.plot(t, _running_mean(d2, n), color="black", lw=1.0, label=f"mean of {n}")
        ax.set_yscale("log")
        ax.set_ylabel(f"{sensor}\nNIS ({dof} dof)")
        ax.grid(True, alpha=0.3, which="major")
    handles: dict = {}
    for ax in axes:  # one legend for all rows, below them
        for handle, text in zip(*ax.get_legend_handles_labels()):
            key = text.split(" (")[0] if text.startswith(("down-weighted", "rejected")) else text
            handles.setdefault(key, (handle, key))
    if handles:
        fig.legend([h for h, _ in handles.values()], [k for _, k in handles.values()], loc="outside lower center",
                   ncol=4, fontsize="small")
    axes[0].set_title(f"Normalised innovations of {label_of(backend)} against their chi-square band")
    axes[-1].set_xlabel("time [s]")
    return save_figure(fig, path)


def plot_influence(entries: list[dict], reference: str, path: str | Path) -> Path:
    """Horizontal bars per input: RMS and end-point distance of the track fused without it from the full
    ``reference`` track (log axis when one input dominates)."""
    usable = [e for e in entries if math.isfinite(e.get("rms_m", math.nan))]
    fig, (ax,) = new_figure(height=0.6 * max(len(usable), 1) + 1.6, width=8.0)
    values = [v for e in usable for v in (e["rms_m"], e["end_m"])]
    scale, unit = length_unit(values)
    log = use_log(values)
    y = np.arange(len(usable))
    floor = 1e-6 * scale
    ax.barh(y - 0.2, [max(e["rms_m"] * scale, floor) for e in usable], height=0.4, color="tab:blue", label="RMS")
    ax.barh(y + 0.2, [max(e["end_m"] * scale, floor) for e in usable], height=0.4, color="tab:orange",
            label="at the end")
    ax.set_yticks(y, [e["label"] for e in usable])
    ax.invert_yaxis()  # the first input on top
    if log:
        ax.set_xscale("log")
    ax.set_xlabel(f"distance of the track fused without the input from {label_of(reference)} [{unit}]"
                  + (" (log)" if log else ""))
    ax.set_title("How much each input moved the fused track (left out one at a time)")
    ax.grid(True, axis="x", alpha=0.3, which="both")
    ax.legend(loc="best", fontsize="small")
    return save_figure(fig, path)


def aligned_to(track: PoseData, reference: PoseData) -> PoseData:
    """``track`` carried onto ``reference`` by the least-squares rigid SE(2) fit of its positions at the
    reference's times within both spans (unchanged when they share fewer than three times)."""
    inside = (reference.t >= track.t[0]) & (reference.t <= track.t[-1])
    if np.count_nonzero(inside) < 3:
        return track
    est = interpolate_poses(track.t, track.xyyaw, reference.t[inside])
    yaw, offset = se2.fit_rigid_2d(est[:, :2], reference.xyyaw[inside, :2])
    c, s = math.cos(yaw), math.sin(yaw)
    xy = track.xyyaw[:, :2] @ np.array([[c, s], [-s, c]]) + offset
    return PoseData(track.t, np.column_stack([xy, track.xyyaw[:, 2] + yaw]))
