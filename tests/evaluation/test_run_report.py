"""The report of a run without ground truth: robot_localization's Jackal log (tests/data/robot_localization/test2.bag,
BSD), imported and run as a new user would, then rebuilt, broken and compared."""

from __future__ import annotations

import json
import re
import shutil
from html import unescape
from pathlib import Path

import numpy as np
import pytest

from fusion_vo.cli.main import main
from fusion_vo.evaluation.innovations import band, read_innovations

#: the run every test reads, made ahead in the background (tests/background.py; the import is tests/conftest.py's),
#: into a folder named ``out`` as the report's rebuilt copy is (the report names the run by its folder)
BACKGROUND_COMMANDS = {"run_report/out": ["-q", "run", "{fusion-vo:jackal_log}", "--out", "{out}", "--backend", "ekf"]}
BACKGROUND_JOBS = {"*": ["fusion-vo:jackal_log", "fusion-vo:run_report/out"]}


@pytest.fixture(scope="module")
def jackal(jackal_log, ahead, tmp_path_factory):
    """test2.bag imported by ``fusion-vo import-bag`` into ``jackal_log`` (tests/conftest.py), run with the EKF."""

    def here():
        out = tmp_path_factory.mktemp("jackal") / "out"
        assert main(["-q", "run", str(jackal_log), "--out", str(out), "--backend", "ekf"]) == 0
        return out

    return jackal_log, ahead("fusion-vo:run_report/out", here)


def section(text: str, heading: str) -> str:
    """The HTML between ``<h2>heading</h2>`` and the next ``<h2>``."""
    return text.split(f"<h2>{heading}</h2>", 1)[1].split("<h2>", 1)[0]


def cells(html_part: str) -> list[list[str]]:
    return [[unescape(c) for c in re.findall(r"<td>(.*?)</td>", row)]
            for row in re.findall(r"<tr>(.*?)</tr>", html_part) if "<td>" in row]


def test_a_run_without_ground_truth_has_a_report_with_every_section(jackal):
    seq, out = jackal
    text = (out / "report.html").read_text()
    assert "<h1>jackal_log</h1>" in text  # the recording's name, not the run folder's
    for heading in ("In short", "Accuracy", "Tracks", "Influence of each input", "Consistency: normalised innovations (NIS)",
                    "What was dropped or gated", "Calibration", "Notes", "Definitions", "Configuration"):
        assert f"<h2>{heading}</h2>" in text, heading
    assert "no ground truth and no GPS fixes" in section(text, "Accuracy")
    assert "<details><summary>" in section(text, "Configuration")
    for term in ("ATE", "RPE", "Drift", "NIS"):
        assert f"<dt>{term}</dt>" in section(text, "Definitions")
    figures = re.findall(r'src="data:image/png;base64,', text)
    assert len(figures) == 5  # tracks, headings, differences, influence, NIS of the EKF
    for name in ("tracks", "headings", "differences", "influence", "nis_ekf"):
        assert (out / f"{name}.png").read_bytes().startswith(b"\x89PNG"), name
    assert not (out / "metrics.json").exists()


def test_the_verdict_says_what_carries_the_estimate_and_what_was_left_out(jackal):
    _, out = jackal
    verdict = [unescape(v) for v in re.findall(r"<li>(.*?)</li>", section((out / "report.html").read_text(), "In short"))]
    assert any(v.startswith("Scale: carried by the odometry twist; leaving it out changes the distance travelled "
                            "by -100 %") for v in verdict), verdict
    assert any(v.startswith("Heading: depends most on the IMU (gyro and AHRS)") for v in verdict), verdict
    assert any(v.startswith("The odometry twist's yaw rate was not used at all: it contradicted the gyro and AHRS "
                            "over the whole recording") for v in verdict), verdict
    summary = json.loads((out / "summary.json").read_text())
    note = next(n for n in summary["notes"] if "yaw rate inconsistent" in n)
    assert "over the whole recording" in note and "not used at all" in note and "0.0 s in" not in note
    # a twist has no wheel base: none is estimated, noted or reported
    assert not any("wheel base" in n for n in summary["notes"]), summary["notes"]
    assert "wheel_base" not in summary["fusion"]["calibration"]["ekf"]


def test_the_nis_table_holds_the_innovations_file(jackal):
    _, out = jackal
    tables = read_innovations(out / "innovations.csv")
    assert list(tables) == ["ekf"]
    rows = {(r[0], r[1], int(r[2])): r for r in cells(section((out / "report.html").read_text(),
                                                               "Consistency: normalised innovations (NIS)"))}
    expected = {}
    for t, sensor, d2, dof, status in zip(*(getattr(tables["ekf"], k) for k in ("t", "sensor", "d2", "dof", "status"))):
        expected.setdefault(("ekf", sensor, int(dof)), []).append((d2, status))
    assert set(rows) == set(expected)
    for key, values in expected.items():
        d2 = np.array([v[0] for v in values])
        row = rows[key]
        assert int(row[3]) == len(values)
        assert [int(c) for c in row[4:7]] == [sum(v[1] == s for v in values) for s in ("used", "down-weighted", "rejected")]
        assert float(row[7]) == pytest.approx(d2.mean(), rel=1e-2)
        lo, hi = band(key[2])
        assert float(row[10]) == pytest.approx(100 * np.mean((d2 >= lo) & (d2 <= hi)), abs=0.05)
    # the file's rows are the filter's counts: every block it used, down-weighted or rejected
    counts = json.loads((out / "summary.json").read_text())["fusion"]["counts"]["ekf"]
    for sensor in {k[1] for k in expected}:
        blocks = [v for k, vs in expected.items() if k[1] == sensor for v in vs]
        assert sum(v[1] != "rejected" for v in blocks) == counts[sensor]["used"], sensor


def test_the_calibration_table_has_prior_and_posterior_of_every_state(jackal):
    _, out = jackal
    fusion = json.loads((out / "summary.json").read_text())["fusion"]
    rows = cells(section((out / "report.html").read_text(), "Calibration"))
    by_name = {r[0]: r for r in rows}
    states = [k for k in fusion["calibration"]["ekf"] if not k.endswith("_sigma")]
    assert set(states) == set(fusion["priors"]) == {"gyro_bias", "wheel_base_factor"}
    gyro = by_name["gyro bias"]
    prior, estimate = fusion["priors"]["gyro_bias"], fusion["calibration"]["ekf"]
    assert gyro[2] == f"{np.degrees(prior['mean']):.4f} \u00b1 {np.degrees(prior['sigma']):.4f} deg/s"
    assert gyro[3] == f"{np.degrees(estimate['gyro_bias']):.4f} \u00b1 {np.degrees(estimate['gyro_bias_sigma']):.4f} deg/s"
    # the yaw-rate factor of a twist whose yaw rate was never used: the prior stands
    factor = by_name["odometry yaw-rate factor"]
    assert factor[2] == "1.0000 \u00b1 0.3000" and factor[-1].startswith("no: the prior stands")
    assert len(rows) == 2


def test_evaluate_rebuilds_the_same_report_from_the_folder(jackal, tmp_path, capsys):
    seq, out = jackal
    copy = tmp_path / "out"
    shutil.copytree(out, copy)
    before = {p.name: p.read_bytes() for p in copy.iterdir() if p.suffix in (".html", ".png")}
    (copy / "report.html").unlink()
    assert main(["evaluate", str(copy)]) == 0
    printed = capsys.readouterr().out
    assert "verdict: Scale: carried by the odometry twist" in printed and "no ground truth and no GPS fixes" in printed
    after = {p.name: p.read_bytes() for p in copy.iterdir() if p.suffix in (".html", ".png")}
    assert after == before


def _broken_copy(out: Path, tmp_path: Path) -> Path:
    copy = tmp_path / "broken"
    shutil.copytree(out, copy)
    return copy


def test_a_missing_file_the_run_wrote_is_named(jackal, tmp_path, capsys):
    _, out = jackal
    copy = _broken_copy(out, tmp_path)
    (copy / "influence.json").unlink()
    assert main(["evaluate", str(copy)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"fusion-vo: error: {copy / 'influence.json'}: file not found (summary.json lists it among the files "
                   "the run wrote)"]
    assert (copy / "report.html").read_bytes() == (out / "report.html").read_bytes()  # the old report stands


def test_an_optional_file_absent_leaves_its_section_out_with_a_sentence(jackal, tmp_path):
    _, out = jackal
    copy = _broken_copy(out, tmp_path)
    summary = json.loads((copy / "summary.json").read_text())
    summary["files"] = [f for f in summary["files"] if f not in ("innovations.csv", "influence.json")]
    (copy / "summary.json").write_text(json.dumps(summary))
    (copy / "innovations.csv").unlink()
    (copy / "influence.json").unlink()
    assert main(["-q", "evaluate", str(copy)]) == 0
    text = (copy / "report.html").read_text()
    assert "The folder has no innovations.csv" in text and "The folder has no influence.json" in text
    assert "<th>mean NIS</th>" not in text and "Scale:" not in text
    assert not (copy / "nis_ekf.png").exists() and not (copy / "influence.png").exists()


def test_a_malformed_innovations_row_is_named_by_line(jackal, tmp_path, capsys):
    _, out = jackal
    copy = _broken_copy(out, tmp_path)
    lines = (copy / "innovations.csv").read_text().splitlines()
    lines[4] = lines[4].replace("used", "maybe")
    (copy / "innovations.csv").write_text("\n".join(lines) + "\n")
    assert main(["evaluate", str(copy)]) == 2
    assert capsys.readouterr().err.strip() == (f"fusion-vo: error: {copy / 'innovations.csv'}:5: unknown status 'maybe' "
                                               "(expected one of used, down-weighted, rejected)")


def test_compare_runs_without_ground_truth(jackal, tmp_path, capsys):
    _, out = jackal
    moved = tmp_path / "moved"
    shutil.copytree(out, moved)
    rows = [ln.split() for ln in (moved / "ekf.tum").read_text().splitlines() if not ln.startswith("#")]
    (moved / "ekf.tum").write_text("".join(f"{r[0]} {float(r[1]) + 0.25:.9f} {' '.join(r[2:])}\n" for r in rows))
    assert main(["compare", str(out), str(moved), "--out", str(tmp_path / "cmp")]) == 0
    printed = capsys.readouterr().out
    table = json.loads((tmp_path / "cmp" / "compare.json").read_text())
    assert table["moved"]["ekf"]["diff_rms_m"] == pytest.approx(0.25, abs=1e-6)
    assert table["moved"]["ekf_smoothed"]["diff_rms_m"] == pytest.approx(0.0, abs=1e-9)
    assert "ate_m" not in table["out"]["ekf"]
    assert (tmp_path / "cmp" / "compare_differences.png").read_bytes().startswith(b"\x89PNG")
    assert "Distance from the same trajectory of out" in printed and printed.count("Scale: carried by the odometry twist") == 2
