"""Without the eval extra (evo), run writes its trajectories and its report, which says in one line that the
accuracy against ground truth was skipped and which extra it needs; evaluate rebuilds that report."""

from __future__ import annotations

from html import unescape
from pathlib import Path

from without_evo_job import run_all

#: the three commands, run from the session's start in the background (tests/background.py) or else by the test
BACKGROUND_COMMANDS = {"python:without_evo": ["{repo}/tests/ecosystem/without_evo_job.py", "{out}"]}
BACKGROUND_JOBS = {"test_run_and_evaluate_without_evo": ["python:without_evo"]}


def test_run_and_evaluate_without_evo(ahead_json, tmp_path):
    steps = ahead_json("python:without_evo", lambda: run_all(tmp_path / "without_evo"))
    folder = Path(steps["folder"])
    out = folder / "run"
    made = steps["made"]
    assert made["code"] == 0, made["stderr"]
    done = steps["done"]
    assert done["code"] == 0, done["stderr"]
    line = "No evaluation against ground truth: it needs evo (GPL-3.0), which is not installed: pip install 'fusion-vo[eval]'"
    assert f"note: {line}" in done["stdout"]
    assert (out / "ekf.tum").is_file() and (out / "vo.tum").is_file() and not (out / "metrics.json").exists()
    report = unescape((folder / "report_after_run.html").read_text())
    assert line in report and "<h2>Tracks</h2>" in report and "<h2>Influence of each input</h2>" in report
    again = steps["again"]
    assert again["code"] == 0, again["stderr"]
    assert f"note: {line}" in again["stdout"] and unescape((out / "report.html").read_text()) == report
