"""The report's tables of one run, from its ``summary.json``, ``innovations.csv`` and ``influence.json``:
calibration states (prior and posterior), what was dropped or gated and when, the pauses, and each input's
influence. Every function returns ``(headers, rows)`` of strings, in units that fit the values."""

from __future__ import annotations

import math

import numpy as np

from fusion_vo.backends.result import Innovations
from fusion_vo.evaluation.plots import label_of

DASH = "\u2013"


def length(value: float) -> str:
    """A length [m] in mm below 0.1 m, else in m, to three significant digits."""
    if value is None or not math.isfinite(value):
        return DASH
    return f"{value * 1e3:.3g} mm" if abs(value) < 0.1 else f"{value:.3g} m"


def figure(value: float, signed: bool = False) -> str:
    """Three significant digits; a magnitude below 5e-4 (rounding noise of a figure that is zero) as 0."""
    if value is None or not math.isfinite(value):
        return DASH
    if abs(value) < 5e-4:
        return "0"
    return f"{value:+.3g}" if signed else f"{value:.3g}"


#: the consistency check's names of the streams, in words
STREAM_WORDS = {"gyro": "gyro", "ahrs": "AHRS", "wheel": "wheels", "camera": "camera", "imu": "IMU"}
POSSESSIVE = {"wheel": "wheels'", "imu": "IMU's", "camera": "camera's"}


def stream_words(names: str, twist: bool = False) -> str:
    """``"gyro, ahrs"`` -> ``"gyro and AHRS"`` (the wheels are the odometry twist on a robot that has one)."""
    words = [STREAM_WORDS.get(n.strip(), n.strip()) for n in str(names).split("(")[0].split(",") if n.strip()]
    if twist:
        words = ["odometry twist" if w == "wheels" else w for w in words]
    tail = f" ({str(names).split('(', 1)[1]}" if "(" in str(names) else ""
    return (" and ".join([", ".join(words[:-1]), words[-1]]) if len(words) > 1 else "".join(words)) + tail


def seconds_in(t: float, t0: float) -> str:
    return f"{t - t0:.1f}"


# --------------------------------------------------------------------------- calibration
#: state -> (name, what it is, factor to the shown unit, unit, format)
STATES = {
    "visual_scale": ("visual scale", "configured over true camera height (1: the height is right)", 1.0, "", "{:.4f}"),
    "camera_height": ("camera height", "height of the camera over the floor", 1e3, "mm", "{:.2f}"),
    "wheel_scale": ("wheel scale", "configured over true wheel radius (1: the radius is right)", 1.0, "", "{:.4f}"),
    "wheel_base_factor": ("wheel-base factor", "true over configured wheel base: scales the wheels' turn", 1.0, "",
                          "{:.4f}"),
    "wheel_base": ("wheel base", "effective track width of the wheels", 1.0, "m", "{:.4f}"),
    "gyro_bias": ("gyro bias", "offset of the gyro's yaw rate", 180.0 / math.pi, "deg/s", "{:.4f}"),
    "ahrs_offset": ("AHRS heading offset", "AHRS north against the run's heading at the end", 180.0 / math.pi, "deg",
                    "{:.2f}"),
}
#: backends whose calibration is shown, in this order (the smoother's end state is the filter's)
CALIBRATION_BACKENDS = ("ekf", "gtsam", "gtsam_online")


def _value(key: str, mean, sigma) -> str:
    if mean is None or not isinstance(mean, (int, float)) or not math.isfinite(mean):
        return DASH
    _, _, factor, unit, fmt = STATES.get(key, (key, "", 1.0, "", "{:.4g}"))
    text = fmt.format(mean * factor)
    if isinstance(sigma, (int, float)) and math.isfinite(sigma):
        text += " \u00b1 " + fmt.format(sigma * factor)
    return f"{text} {unit}".rstrip()


def calibration_table(fusion: dict) -> tuple[list[str], list[list[str]]]:
    """Every calibration state the run estimated: prior and posterior (mean ± σ) per backend, and whether the
    data informed it (the EKF's posterior σ against the prior's, and how many prior σ it moved).

    ``fusion`` is ``summary.json``'s ``fusion`` (``calibration``, ``priors``, ``time_offsets``). The camera
    height's σ is the visual scale's carried through ``h / k_v``. A robot whose odometry is a twist has a
    yaw-rate factor instead of a wheel base.
    """
    calibration = fusion.get("calibration") or {}
    priors = fusion.get("priors") or {}
    backends = [b for b in CALIBRATION_BACKENDS if calibration.get(b)]
    keys: list[str] = []
    for b in backends:
        keys += [k for k in calibration[b] if not k.endswith("_sigma") and k not in keys]
    twist = any("wheel_base_factor" in calibration[b] and "wheel_base" not in calibration[b] for b in backends)
    headers = ["state", "meaning", "prior"] + [label_of(b) for b in backends] + ["informed by the data?"]
    rows = []
    for key in sorted(keys, key=lambda k: list(STATES).index(k) if k in STATES else len(STATES)):
        name, meaning = STATES.get(key, (key, "a sensor's own state"))[:2]
        if key == "wheel_base_factor" and twist:
            name, meaning = "odometry yaw-rate factor", "true over reported yaw rate of the odometry twist"
        prior = priors.get(key) or {}
        row = [name, meaning, _value(key, prior.get("mean"), prior.get("sigma"))]
        for b in backends:
            est = calibration[b]
            sigma = est.get(f"{key}_sigma")
            if key == "camera_height" and "visual_scale_sigma" in est and est.get("visual_scale"):
                sigma = est["camera_height"] * est["visual_scale_sigma"] / est["visual_scale"]
            row.append(_value(key, est.get(key), sigma))
        row.append(_informed(key, prior, calibration.get(backends[0], {})))
        rows.append(row)
    for key, value in (fusion.get("time_offsets") or {}).items():
        if key == "odom_delay" and isinstance(value, (int, float)):
            rows.append(["odometry delay", "odometry twist behind the gyro (its timestamps corrected)",
                         "none: measured from the yaw rates", f"{value * 1e3:.0f} ms (all backends)"]
                        + [""] * (len(backends) - 1) + ["yes"])
    return headers, rows


def _informed(key: str, prior: dict, estimate: dict) -> str:
    sigma0, mean0 = prior.get("sigma"), prior.get("mean")
    mean, sigma = estimate.get(key), estimate.get(f"{key}_sigma")
    if key == "camera_height":
        sigma = None if not estimate.get("visual_scale") else (
            estimate.get("visual_scale_sigma", math.nan) * estimate.get("camera_height", math.nan) / estimate["visual_scale"])
    if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in (sigma0, mean0, mean, sigma)) or sigma0 <= 0:
        return DASH
    ratio = sigma / sigma0
    moved = (mean - mean0) / sigma0
    if ratio > 0.9 and abs(moved) < 0.5:
        return f"no: the prior stands (\u03c3 {100 * ratio:.0f} % of the prior's)"
    return f"yes: \u03c3 {100 * ratio:.2g} % of the prior's, moved {figure(moved, True)} prior \u03c3"


# --------------------------------------------------------------------------- dropped and gated
def dropped_table(episodes: list[dict], t0: float, t1: float, twist: bool = False) -> tuple[list[str], list[list[str]]]:
    """The consistency check's episodes: which component, against what, when (seconds from the start), how
    long, the largest NIS, and whether it was the whole recording (``twist``: the wheels are an odometry twist)."""

    headers = ["sensor", "component", "contradicted", "from [s in]", "to [s in]", "duration [s]", "largest NIS",
               "extent"]
    rows = []
    for e in episodes:
        start, end = float(e.get("start", math.nan)), float(e.get("end", math.nan))
        whole = start <= t0 + 1e-3 and end >= t1 - 1e-3
        sensor = str(e.get("sensor", ""))
        rows.append(["odometry twist" if twist and sensor == "wheel" else sensor, str(e.get("component", "")),
                     stream_words(str(e.get("against", "")), twist),
                     seconds_in(start, t0), seconds_in(end, t0), f"{end - start:.1f}", f"{e.get('max_nis', math.nan):.3g}",
                     "whole recording: not used at all" if whole else "not used in this span"])
    return headers, rows


def gated_spans(table: Innovations, t0: float, join: float = 1.0, limit: int = 40) -> tuple[list[str], list[list[str]], int]:
    """Spans of down-weighted or rejected blocks per sensor and outcome (blocks less than ``join`` seconds
    apart are one span): ``(headers, rows, spans left out beyond limit)``."""
    headers = ["sensor", "outcome", "from [s in]", "to [s in]", "blocks", "largest NIS"]
    spans = []
    for sensor in dict.fromkeys(table.sensor):
        for outcome in ("down-weighted", "rejected"):
            sel = np.flatnonzero((table.sensor == sensor) & (table.status == outcome))
            if not sel.size:
                continue
            t = table.t[sel]
            cuts = np.flatnonzero(np.diff(t) > join) + 1
            for part in np.split(np.arange(len(sel)), cuts):
                idx = sel[part]
                spans.append((float(table.t[idx[0]]), [str(sensor), outcome, seconds_in(table.t[idx[0]], t0),
                                                       seconds_in(table.t[idx[-1]], t0), str(len(idx)),
                                                       f"{float(np.max(table.d2[idx])):.3g}"]))
    spans.sort(key=lambda s: s[0])
    rows = [row for _, row in spans]
    return headers, rows[:limit], max(0, len(rows) - limit)


def pauses_table(pauses: list[dict], t0: float) -> tuple[list[str], list[list[str]]]:
    """Pauses in every stream at which the estimate was split, and how the pieces were joined."""
    headers = ["from [s in]", "to [s in]", "duration [s]", "joined by"]
    rows = [[seconds_in(float(p["start"]), t0), seconds_in(float(p["end"]), t0), f"{float(p['seconds']):.2f}",
             str(p.get("joined", ""))] for p in pauses if "start" in p and "end" in p and "seconds" in p]
    return headers, rows


# --------------------------------------------------------------------------- influence
def influence_table(influence: dict) -> tuple[list[str], list[list[str]]]:
    """Per input left out: the distance of the track fused without it from the full one (RMS, largest, at the
    end), the heading difference (RMS, at the end), the change of the distance travelled, and the CPU time."""
    headers = ["input left out", "RMS", "largest", "at the end", "heading RMS [deg]", "heading at the end [deg]",
               "distance travelled [%]", "compared", "CPU [s]"]
    rows = []
    for e in influence.get("inputs", []):
        if e.get("error"):
            rows.append([e["label"], f"cannot be fused without it: {e['error']}"] + [DASH] * 6
                        + [f"{e.get('seconds', math.nan):.2f}"])
            continue
        rows.append([e["label"], length(e["rms_m"]), length(e["max_m"]), length(e["end_m"]),
                     figure(e["heading_rms_deg"]), figure(e["heading_end_deg"], True), figure(e["distance_pct"], True),
                     "SE(2)-aligned" if e.get("aligned") else "as estimated", f"{e.get('seconds', math.nan):.2f}"])
    return headers, rows
