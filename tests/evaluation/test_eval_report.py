"""A whole run folder: metrics.json, figures and a report that renders in a browser."""

import json
import re
import subprocess
from pathlib import Path

import pytest

from fusion_vo.evaluation import compare_runs, evaluate_run

from eval_synthetic import make_run

CHROMIUM = Path("/usr/bin/chromium")

# Written into a copy of the report: counts the images the browser decoded once the page has loaded.
PROBE = ('<script>window.addEventListener("load", () => {const all = [...document.images];'
         'document.body.setAttribute("data-rendered", all.filter(i => i.complete && i.naturalWidth > 0).length'
         ' + "/" + all.length);});</script></body>')


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    run_dir, seq = make_run(tmp_path_factory.mktemp("eval"))
    return run_dir, seq, evaluate_run(run_dir)


def test_metrics_json_has_the_key_figures(run):
    run_dir, _, metrics = run
    stored = json.loads((run_dir / "metrics.json").read_text())
    assert list(stored) == ["vo", "wheel", "ekf"]
    for figures in stored.values():
        assert {"ate_m", "end_pct", "heading_deg", "rpe_1m_pct", "ate_anchored_m", "drift", "legs"} <= set(figures)
    # the EKF stand-in has a third of the visual errors
    assert stored["ekf"]["ate_m"] < stored["vo"]["ate_m"]
    assert stored["vo"]["legs"][0]["error_pct"] == pytest.approx(3.0, abs=0.05)
    assert stored == json.loads(json.dumps(metrics))


def test_figures_and_a_self_contained_report(run):
    run_dir, _, _ = run
    for name in ("trajectories", "velocities", "heading", "error_distance", "frontend"):
        png = (run_dir / f"{name}.png").read_bytes()
        assert png.startswith(b"\x89PNG") and len(png) > 10_000
    text = (run_dir / "report.html").read_text()
    # against ground truth: trajectories, velocities, heading, error growth; the sources' tracks, headings and
    # differences; the frontend
    assert text.count('src="data:image/png;base64,') == 8
    assert not re.search(r'(src|href)="(?!data:)', text)  # nothing outside the file
    assert "frontend: klt" in text and "<td>vo</td>" in text


def render_count(html_file: Path, profile: Path) -> str:
    """Open a file in headless Chromium and return the probe's 'decoded/total' image count."""
    command = [str(CHROMIUM), "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
               "--disable-component-update", "--disable-sync", "--no-first-run", f"--user-data-dir={profile}",
               "--virtual-time-budget=5000", "--dump-dom", html_file.as_uri()]
    dom = subprocess.run(command, capture_output=True, text=True, timeout=90).stdout
    found = re.search(r'data-rendered="([^"]*)"', dom)
    assert found, "Chromium returned no DOM with the probe's result"
    return found.group(1)


@pytest.mark.skipif(not CHROMIUM.exists(), reason="needs /usr/bin/chromium (Debian packages chromium, "
                                                  "chromium-driver)")
def test_report_images_render_in_chromium(run, tmp_path):
    run_dir, _, _ = run
    text = (run_dir / "report.html").read_text()
    page = tmp_path / "page.html"
    page.write_text(text.replace("</body>", PROBE))
    assert render_count(page, tmp_path / "profile") == "8/8"
    # the probe can tell: one corrupted image is not counted
    broken = tmp_path / "broken.html"
    broken.write_text(text.replace('src="data:image/png;base64,iVBOR', 'src="data:image/png;base64,AAAA', 1)
                      .replace("</body>", PROBE))
    assert render_count(broken, tmp_path / "profile2") == "7/8"


def test_compare_two_runs(run, tmp_path):
    run_dir, seq, _ = run
    other, _ = make_run(run_dir.parent, scale=1.10, name="scaled")
    table = compare_runs([run_dir, other], tmp_path / "out")
    assert list(table) == ["run", "scaled"]
    assert table["scaled"]["vo"]["rpe_1m_pct"] > table["run"]["vo"]["rpe_1m_pct"]
    assert (tmp_path / "out" / "compare.png").read_bytes().startswith(b"\x89PNG")
    assert json.loads((tmp_path / "out" / "compare.json").read_text())["run"]["ekf"]["ate_m"] > 0
