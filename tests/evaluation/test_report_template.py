"""The HTML report is rendered from its jinja2 template with the run's notes, counts and configuration."""

from __future__ import annotations

import re

from fusion_vo.evaluation.report import ReportContent, count_rows, render_report

METRICS = {"ekf": {"ate_m": 0.0123, "end_pct": 0.5, "heading_deg": 1.25, "revolutions": 0.1,
                   "drift": [{"length_m": 1.0, "segments": 3, "trans_pct": 0.4, "rot_deg_per_m": 0.2}], "legs": []}}
COUNTS = {"ekf": {"camera": {"used": 57, "gated": 2, "late": 1}, "wheel": {"used": 140, "missing": 3}},
          "gtsam": {"camera": {"used": 59, "gated": 0, "late": 0}}}


def _cells(html_text: str, section: str, level: int = 2) -> list[list[str]]:
    part = html_text.split(f"<h{level}>{section}</h{level}>", 1)[1].split("<h", 1)[0]
    return [re.findall(r"<td>(.*?)</td>", row) for row in re.findall(r"<tr>(.*?)</tr>", part) if "<td>" in row]


def test_report_shows_notes_counts_and_configuration(tmp_path):
    notes = ["camera lost from 19.40 s in to 23.90 s in; the other sensors carried the estimate",
             "a <script> in a note stays text & is escaped"]
    config = {"sequence": "/data/rec", "frontend": "klt", "fusion": {"ekf": {"accel_sigma": 0.5}}}
    png = tmp_path / "a.png"
    png.write_bytes(b"\x89PNG...")
    content = ReportContent("rec", "Run r1", config, notes=notes, metrics=METRICS, counts=COUNTS,
                            frontend={"frames": 60}, verdict=["Scale: the wheels carry it."])
    content.figure("tracks", "A figure", png)
    text = render_report(content)
    assert text.startswith("<!DOCTYPE html>") and text.rstrip().endswith("</html>")
    assert "<li>camera lost from 19.40 s in to 23.90 s in; the other sensors carried the estimate</li>" in text
    assert "<script>" not in text and "a &lt;script&gt; in a note stays text &amp; is escaped" in text
    assert _cells(text, "Measurements per sensor", 3) == [
        ["ekf", "camera", "57", "2", "1", "\u2013"], ["ekf", "wheel", "140", "\u2013", "\u2013", "3"],
        ["gtsam", "camera", "59", "0", "0", "\u2013"]]
    assert "<th>used</th><th>gated</th><th>late</th><th>missing</th>" in text
    assert _cells(text, "Errors against ground truth", 3)[0][:2] == ["ekf", "0.0123"]
    assert _cells(text, "Drift over segments (KITTI style)", 3) == [["ekf", "1", "3", "0.40", "0.20"]]
    assert _cells(text, "Visual frontend") == [["frames", "60"]]
    pre = text.split("<h2>Configuration</h2>", 1)[1]
    assert "<details>" in pre and "fusion:\n  ekf:\n    accel_sigma: 0.5" in pre
    assert "Recording: <code>/data/rec</code>" in text and "<h1>rec</h1>" in text
    assert '<ul class="verdict">\n<li>Scale: the wheels carry it.</li>' in text
    assert text.count('src="data:image/png;base64,') == 1
    assert render_report(content) == text  # no clock time: the same content gives the same page


def test_report_without_notes_or_counts_leaves_those_sections_out():
    text = render_report(ReportContent("r", metrics=METRICS))
    assert "<h2>Notes</h2>" not in text and "Measurements per sensor" not in text and "<figure>" not in text
    assert "<pre>(none)</pre>" in text
    assert "No verdict" in text
    assert count_rows(None) == (["backend", "sensor"], [])


def test_further_sections_and_the_reason_for_no_accuracy():
    text = render_report(ReportContent("r", sections=[("Errors against GPS fixes", ["trajectory", "RMS [m]"],
                                                       [["ekf", "0.42"]], ["3 fixes skipped (no fix)"])]))
    assert "Errors against ground truth" not in text
    assert _cells(text, "Errors against GPS fixes", 3) == [["ekf", "0.42"]]
    assert "<p>3 fixes skipped (no fix)</p>" in text
    text = render_report(ReportContent("r", accuracy_line="The recording has no ground truth and no GPS fixes."))
    assert "<h2>Accuracy</h2>\n<p>The recording has no ground truth and no GPS fixes.</p>" in text
