"""Without the eval extra (evo), run writes its trajectories and its report, which says in one line that the
accuracy against ground truth was skipped and which extra it needs; evaluate rebuilds that report."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from html import unescape
from pathlib import Path

from evo_blocker import BLOCK_EVO

ROOT = Path(__file__).resolve().parents[2]

_SCRIPT = BLOCK_EVO + textwrap.dedent("""
    from fusion_vo.cli.main import main
    sys.exit(main(sys.argv[1:]))
""")


def _cli(*args):
    return subprocess.run([sys.executable, "-c", _SCRIPT, *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=300)


def test_run_and_evaluate_without_evo(tmp_path):
    rec, out = tmp_path / "rec", tmp_path / "run"
    made = _cli("simulate", str(rec), "--profile", "random", "--duration", "1", "-O", "width=320", "-O", "height=180",
                "-O", "fu=210", "-O", "fv=210", "-O", "cu=159.5", "-O", "cv=89.5")
    assert made.returncode == 0, made.stderr
    done = _cli("-q", "run", str(rec), "--out", str(out), "--backend", "ekf")
    assert done.returncode == 0, done.stderr
    line = "No evaluation against ground truth: it needs evo (GPL-3.0), which is not installed: pip install 'fusion-vo[eval]'"
    assert f"note: {line}" in done.stdout
    assert (out / "ekf.tum").is_file() and (out / "vo.tum").is_file() and not (out / "metrics.json").exists()
    report = unescape((out / "report.html").read_text())
    assert line in report and "<h2>Tracks</h2>" in report and "<h2>Influence of each input</h2>" in report
    again = _cli("evaluate", str(out))
    assert again.returncode == 0, again.stderr
    assert f"note: {line}" in again.stdout and unescape((out / "report.html").read_text()) == report
