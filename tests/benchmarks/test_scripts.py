"""The benchmark scripts run as a user runs them: each prints its ``--help``, rejects bad options with a usage
error, and a short run prints its table. They are run in subprocesses, from the session's start in the background
(tests/background.py) or else by the test itself; no test imports them."""

import json
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
FOLDER = REPO / "benchmarks"
SCRIPTS = sorted(p.name for p in FOLDER.glob("*.py") if p.name != "common.py")

#: runs each ``(script, argv)`` of argv[2] (JSON) as ``python benchmarks/SCRIPT ARGV...`` would from the folder
#: argv[1], in this one process (their imports are shared, so it takes seconds), and prints each exit status and its
#: output
_RUNNER = textwrap.dedent("""
    import contextlib, io, json, os, runpy, sys
    os.chdir(sys.argv[1])
    results = []
    for script, argv in json.loads(sys.argv[2]):
        out, err = io.StringIO(), io.StringIO()
        sys.argv = [script, *argv]
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                runpy.run_path(script, run_name="__main__")
                code = 0
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else 1
        results.append([script, code, out.getvalue(), err.getvalue()])
    print(json.dumps(results))
""")


def run_scripts(calls: list[tuple[str, list[str]]]) -> list[tuple[str, int, str, str]]:
    proc = subprocess.run([sys.executable, "-c", _RUNNER, str(FOLDER), json.dumps(calls)], capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


HELP = [(s, ["--help"]) for s in SCRIPTS]
BAD_OPTIONS = [("frontend_speed.py", ["end-to-end", "--variant", 'klt:{"fb_skip_ratio": 2}']),
               ("frontend_speed.py", ["cpu", "--configs", 'direct:{"nope": 1}']),
               ("fusion.py", ["--only", "nowhere"]),
               ("fusion.py", ["--set", "fusion.no_such_option=1"]),
               ("visual.py", ["independent", "--frontends", "klt,bogus"]),
               ("visual.py", ["lens", "--recordings", "nowhere"]),
               ("consistency.py", ["--seeds", "0"])]
CONSISTENCY = [("consistency.py", ["--seeds", "2", "--duration", "6"])]


def _scripts_job(calls) -> list[str]:
    """The background job (``python:`` ARGS) that runs ``calls`` as :func:`run_scripts` does."""
    return ["-c", _RUNNER, "{repo}/benchmarks", json.dumps(calls)]


def test_at_most_fifteen_benchmarks_each_with_a_help(ahead_json):
    assert 5 <= len(SCRIPTS) <= 15, SCRIPTS
    for script, code, out, err in ahead_json("python:bench_help", lambda: run_scripts(HELP)):
        assert code == 0, (script, err[-2000:])
        assert out.startswith("usage:") and len(out.splitlines()) > 10, (script, out[:500])  # and what it measures


def test_bad_options_are_usage_errors(ahead_json):
    results = ahead_json("python:bench_bad", lambda: run_scripts(BAD_OPTIONS))
    for (script, argv), (_, code, out, err) in zip(BAD_OPTIONS, results):
        assert code != 0, (script, argv, out[-500:])
        assert "Traceback" not in err, (script, argv, err[-2000:])
        assert "error: " in err.strip().splitlines()[-1], (script, argv, err[-2000:])


def test_consistency_prints_every_backend_and_sensor(ahead_json):
    ((_, code, out, err),) = ahead_json("python:bench_consistency", lambda: run_scripts(CONSISTENCY))
    assert code == 0, err[-2000:]
    rows = [[c.strip() for c in line.strip("|").split("|")] for line in out.splitlines() if line.startswith("| ")]
    nees = {r[0]: r for r in rows if len(r) == 5 and r[0] != "backend"}
    assert set(nees) == {"ekf", "ekf_smoothed", "gtsam", "gtsam_online"}
    nis = {(r[0], r[1]) for r in rows if len(r) == 8 and r[0] != "sensor"}
    assert nis == {(s, b) for s in ("camera", "wheel", "gyro") for b in ("ekf", "gtsam", "gtsam_online")}
    for r in nees.values():
        assert 0.5 < float(r[1]) < 20.0 and r[4] in ("consistent", "overconfident", "pessimistic"), r


#: ``python benchmarks/fusion.py --only short --seeds 1 --out DIR``, run from the session's start in the background
#: (tests/background.py) or else by the test itself
FUSION_SHORT = ["{repo}/benchmarks/fusion.py", "--only", "short", "--seeds", "1", "--out", "{out}"]
BACKGROUND_COMMANDS = {"python:fusion_short": FUSION_SHORT, "python:bench_help": _scripts_job(HELP),
                       "python:bench_bad": _scripts_job(BAD_OPTIONS),
                       "python:bench_consistency": _scripts_job(CONSISTENCY)}
BACKGROUND_JOBS = {"test_fusion_over_two_seeds_summarises_the_rows_it_printed": ["python:fusion_short"],
                   "test_at_most_fifteen_benchmarks_each_with_a_help": ["python:bench_help"],
                   "test_bad_options_are_usage_errors": ["python:bench_bad"],
                   "test_consistency_prints_every_backend_and_sensor": ["python:bench_consistency"]}


@pytest.mark.slow
def test_fusion_over_two_seeds_summarises_the_rows_it_printed(background, tmp_path):
    """``fusion.py --only short --seeds 1``: two rows, and the summary's means and comparisons are those of the
    rows (the relative differences against each seed's best input, the smoothers against their filters)."""
    if background is not None and "python:fusion_short" in background:
        stdout = background.result("python:fusion_short").stdout  # (exit status 0 checked there)
    else:
        argv = [a.replace("{repo}", str(REPO)).replace("{out}", str(tmp_path)) for a in FUSION_SHORT]
        proc = subprocess.run([sys.executable, *argv], capture_output=True, text=True, timeout=900, cwd=REPO)
        assert proc.returncode == 0, proc.stderr[-3000:]
        stdout = proc.stdout
    header, rows = None, []
    for line in stdout.splitlines():
        if line.startswith("| recording"):
            header = [c.strip() for c in line.strip("|").split("|")]
        elif line.startswith("| short"):
            rows.append(dict(zip(header, [c.strip() for c in line.split("|")[1:-1]])))
    assert [r["recording"] for r in rows] == ["short", "short (seed 112)"]
    ate = [{k: float(r[k]) for k in ("vo", "wheel", "best", "ekf", "ekf_smoothed", "gtsam", "gtsam_online")}
           for r in rows]
    for a in ate:
        assert a["best"] == min(a["vo"], a["wheel"]) and 0.0 < a["best"] < 1.0
    means = re.search(r"mean ATE \[mm\] (.*)", stdout).group(1)
    for key in ("vo", "ekf", "gtsam_online"):
        printed = float(re.search(rf"\b{key} ([0-9.]+)", means).group(1))
        assert abs(printed - (ate[0][key] + ate[1][key]) / 2) < 1.5e-3, (key, means)
    # the printed ATEs are rounded to 1 µm: the relative differences recomputed from them are known to that
    rel = [a["ekf_smoothed"] / a["ekf"] - 1 for a in ate]
    rounding = sum(1e-3 / a["ekf"] for a in ate) / 2
    rts = re.search(r"RTS vs EKF ([+-][0-9.]+) % on average, at most on (\d) of 2", stdout)
    assert abs(float(rts.group(1)) / 100 - sum(rel) / 2) <= rounding + 5e-4, (rts.group(0), rel)
    # a row whose difference is within the rounding may count either way
    assert sum(r <= -rounding for r in rel) <= int(rts.group(2)) <= sum(r <= rounding for r in rel)
