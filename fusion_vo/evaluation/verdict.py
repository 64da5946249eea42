"""The report's verdict in plain words: which input carries the scale, the heading and the position, how much
each input moved the result, and what was not used at all.

The sentences are read off measured figures, never guessed:

* each input's influence (:mod:`fusion_vo.evaluation.influence`): the input whose removal changes the distance
  travelled most carries the **scale**, the heading depends most on the one whose removal turns it most, the
  **position** on the one whose removal moves the track most (GPS, when fused, fixes the position in the world
  frame whatever the others do); the other inputs' figures follow in brackets;
* the calibration priors (``summary.json``): camera and wheels measure only the ratio of their scales, so when
  both are fused their common scale rests on the tighter of the two priors;
* the consistency check's episodes: a component contradicted over the whole recording was not used at all.

An input whose removal moves the track by less than :data:`NEGLIGIBLE_M` and turns it by less than
:data:`NEGLIGIBLE_DEG` is said to have no measurable influence.
"""

from __future__ import annotations

import math

from fusion_vo.evaluation.run_tables import POSSESSIVE, figure, length, stream_words

#: below these the influence of an input is not measurable (RMS of the position and heading differences)
NEGLIGIBLE_M = 1e-4
NEGLIGIBLE_DEG = 0.01


def _usable(entries: list[dict], key: str) -> list[dict]:
    return [e for e in entries if not e.get("error") and math.isfinite(e.get(key, math.nan))]


def _others(ranked: list[dict], text) -> str:
    """``" (the IMU: 7.1 deg, ...)"`` for the inputs after the first, or nothing."""
    rest = [f"the {e['label']}: {text(e)}" for e in ranked[1:]]
    return f" ({'; '.join(rest)})" if rest else ""


def carriers(influence: dict, sensors: list[str], priors: dict) -> list[str]:
    """The sentences on scale, heading and position (module docstring); empty without an influence table.

    Each names the input the fused track depends on most for that quantity, with the figure, and the others'
    figures after it: leaving an input out also changes what the consistency check can judge (without a third
    heading source it cannot tell which of two disagreeing ones lies), so the ranking is of the whole effect."""
    entries = influence.get("inputs") or []
    out = []
    for e in (e for e in entries if e.get("error")):
        out.append(f"Without the {e['label']} nothing can be fused ({e['error']}): it carries the whole estimate.")
    scale = sorted(_usable(entries, "distance_pct"), key=lambda e: -abs(e["distance_pct"]))
    if scale:
        text = (f"Scale: carried by the {scale[0]['label']}; leaving it out changes the distance travelled by "
                f"{figure(scale[0]['distance_pct'], True)} %" + _others(scale, lambda e: f"{figure(e['distance_pct'], True)} %") + ".")
        if "visual_scale" in priors and "wheel_scale" in priors:
            sv, sr = priors["visual_scale"]["sigma"], priors["wheel_scale"]["sigma"]
            text += (f" Camera and wheels measure only the ratio of their scales; their common scale rests on the "
                     f"tighter prior: the {'camera height' if sv < sr else 'wheel radius'} "
                     f"(\u03c3 {100 * min(sv, sr):.2g} % against {100 * max(sv, sr):.2g} %).")
        out.append(text)
    heading = sorted(_usable(entries, "heading_rms_deg"), key=lambda e: -e["heading_rms_deg"])
    if heading:
        out.append(f"Heading: depends most on the {heading[0]['label']}; leaving it out turns the fused heading by "
                   f"{figure(heading[0]['heading_rms_deg'])} deg RMS, {figure(heading[0]['heading_end_deg'], True)} deg at "
                   "the end" + _others(heading, lambda e: f"{figure(e['heading_rms_deg'])} deg") + ".")
    position = sorted(_usable(entries, "rms_m"), key=lambda e: -e["rms_m"])
    if "gps" in sensors:
        out.append("Position: the GPS fixes hold it in the world frame (East-North-Up at their datum); between fixes "
                   "the other inputs carry it.")
    elif position:
        out.append(f"Position: dead reckoned, nothing in this run measures it; it depends most on the "
                   f"{position[0]['label']}: without it the fused track is {length(position[0]['rms_m'])} RMS from this "
                   f"one, {length(position[0]['end_m'])} at the end" + _others(position, lambda e: length(e["rms_m"]))
                   + ".")
    quiet = [e["label"] for e in position if e["rms_m"] < NEGLIGIBLE_M and e.get("heading_rms_deg", 0.0) < NEGLIGIBLE_DEG]
    if quiet:
        out.append(f"No measurable influence ({length(NEGLIGIBLE_M)} and {NEGLIGIBLE_DEG:g} deg RMS): "
                   f"{', '.join(quiet)}; the other inputs already determine what {'it measures' if len(quiet) == 1 else 'they measure'}.")
    return out


def unused(episodes: list[dict], t0: float, t1: float, twist: bool = False) -> list[str]:
    """A sentence for each component the consistency check left out over the whole recording (``twist``: the
    wheels are an odometry twist)."""
    out = []
    for e in episodes:
        if float(e.get("start", math.inf)) <= t0 + 1e-3 and float(e.get("end", -math.inf)) >= t1 - 1e-3:
            sensor = "odometry twist's" if twist and e.get("sensor") == "wheel" else POSSESSIVE.get(
                str(e.get("sensor")), f"{e.get('sensor')}'s")
            out.append(f"The {sensor} {e.get('component')} was not used at all: it contradicted the "
                       f"{stream_words(e.get('against', ''), twist)} over the whole recording "
                       f"(NIS up to {float(e.get('max_nis', math.nan)):.3g}; see 'What was dropped or gated').")
    return out


def verdict(influence: dict | None, summary: dict, sensors: list[str], t0: float, t1: float) -> list[str]:
    """All verdict sentences of a run (module docstring); ``influence`` None when it was not computed."""
    fusion = summary.get("fusion") or {}
    out = []
    if influence is not None:
        out += carriers(influence, sensors, fusion.get("priors") or {})
    out += unused(fusion.get("inconsistent") or [], t0, t1, "odom" in sensors)
    return out
