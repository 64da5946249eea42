"""The HTML report is rendered from its jinja2 template with the run's notes, counts and configuration."""

from __future__ import annotations

import re

from fusion_vo.evaluation.report import count_rows, render_report

METRICS = {"ekf": {"ate_m": 0.0123, "end_pct": 0.5, "heading_deg": 1.25, "revolutions": 0.1,
                   "drift": [{"length_m": 1.0, "segments": 3, "trans_pct": 0.4, "rot_deg_per_m": 0.2}], "legs": []}}
COUNTS = {"ekf": {"camera": {"used": 57, "gated": 2, "late": 1}, "wheel": {"used": 140, "missing": 3}},
          "gtsam": {"camera": {"used": 59, "gated": 0, "late": 0}}}


def _cells(html_text: str, section: str) -> list[list[str]]:
    part = html_text.split(f"<h2>{section}</h2>", 1)[1].split("<h2>", 1)[0]
    return [re.findall(r"<td>(.*?)</td>", row) for row in re.findall(r"<tr>(.*?)</tr>", part) if "<td>" in row]


def test_report_shows_notes_counts_and_configuration():
    notes = ["camera lost from 19.40 s in to 23.90 s in; the other sensors carried the estimate",
             "a <script> in a note stays text & is escaped"]
    config = {"sequence": "/data/rec", "frontend": "klt", "fusion": {"ekf": {"accel_sigma": 0.5}}}
    text = render_report("fusion-vo run r1", config, METRICS, {"A figure": b"\x89PNG..."}, {"frames": 60},
                         notes=notes, counts=COUNTS)
    assert text.startswith("<!DOCTYPE html>") and text.rstrip().endswith("</html>")
    assert "<li>camera lost from 19.40 s in to 23.90 s in; the other sensors carried the estimate</li>" in text
    assert "<script>" not in text and "a &lt;script&gt; in a note stays text &amp; is escaped" in text
    assert _cells(text, "Measurements per sensor") == [
        ["ekf", "camera", "57", "2", "1", "\u2013"], ["ekf", "wheel", "140", "\u2013", "\u2013", "3"],
        ["gtsam", "camera", "59", "0", "0", "\u2013"]]
    assert "<th>used</th><th>gated</th><th>late</th><th>missing</th>" in text
    assert _cells(text, "Errors against ground truth")[0][:2] == ["ekf", "0.0123"]
    assert _cells(text, "Drift over segments (KITTI style)") == [["ekf", "1", "3", "0.40", "0.20"]]
    assert _cells(text, "Visual frontend") == [["frames", "60"]]
    pre = text.split("<h2>Configuration</h2>", 1)[1]
    assert "fusion:\n  ekf:\n    accel_sigma: 0.5" in pre and "Recording: <code>/data/rec</code>" in text
    assert text.count('src="data:image/png;base64,') == 1


def test_report_without_notes_or_counts_leaves_those_sections_out():
    text = render_report("r", {}, METRICS, {})
    assert "<h2>Notes</h2>" not in text and "Measurements per sensor" not in text and "<h2>Figures</h2>" not in text
    assert "<pre>(none)</pre>" in text
    assert count_rows(None) == (["backend", "sensor"], [])


def test_further_sections_replace_the_ground_truth_table():
    text = render_report("r", {}, {}, {}, sections=[("Errors against GPS fixes", ["trajectory", "RMS [m]"],
                                                      [["ekf", "0.42"]], ["3 fixes skipped (no fix)"])])
    assert "Errors against ground truth" not in text
    assert _cells(text, "Errors against GPS fixes") == [["ekf", "0.42"]]
    assert "<p>3 fixes skipped (no fix)</p>" in text
