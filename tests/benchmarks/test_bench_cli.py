"""``fusion-vo bench``: usage errors are one line with status 2; a short run prints both sides and the ratios;
the plain OpenCV script it measures against is part of the package, so nothing of the source tree is read."""

import subprocess
import sys
import textwrap
from pathlib import Path

import cv2
import numpy as np
import pytest

from fusion_vo import baseline
from fusion_vo.benchmark import EndToEnd, bound_table, first_frames, run_benchmark, wall_bound_ms
from fusion_vo.cli.main import main
from fusion_vo.recording import Recording


@pytest.mark.parametrize("argv, key", [
    (["--frames", "0"], "--frames"),
    (["--frames", "1"], "--frames"),
    (["--frames", "-3"], "--frames"),
    (["--frontend", "bogus"], "--frontend"),
    (["--frontend", "klt,bogus"], "--frontend"),
    (["--frontend", ","], "--frontend"),
    (["--threads", "0"], "--threads"),
    (["--threads", "1,-2"], "--threads"),
    (["--repeats", "0"], "--repeats"),
])
def test_bad_options_are_one_line_usage_errors(argv, key, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["bench", *argv])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and key in err and "Traceback" not in err


def test_a_folder_without_frames_is_a_one_line_error(tmp_path, capsys):
    assert main(["bench", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "cam0/data.csv" in err


@pytest.fixture(scope="module")
def short(standard_recording):
    return standard_recording("short")


def test_first_frames_links_the_first_n(short, tmp_path):
    part = Recording(first_frames(short, 7, tmp_path / "part"))
    full = Recording(short)
    assert len(part) == 7
    assert list(part.frame_times) == list(full.frame_times[:7])
    a, b = next(part.frames(start=6)), next(full.frames(start=6))
    assert (a.image == b.image).all()


@pytest.mark.slow
def test_short_benchmark_prints_both_sides_and_ratios(short):
    lines = []
    rows = run_benchmark(short, ["klt"], baseline.run, [1, 2], repeats=1, max_frames=40, stages=False,
                         out=lines.append)
    default, single, one, two = rows
    assert default.baseline and single.baseline and (default.threads, single.threads) == (None, 1)
    assert default.frames == single.frames == 40 and default.failed == single.failed == 0
    assert (one.threads, two.threads) == (1, 2) and one.failed == two.failed == 0
    for row in (one, two):
        assert row.ratio == [pytest.approx(row.fps[0] / max(default.fps[0], single.fps[0]))]
        assert len(row.rss_mb) == 4 and all(m > 10 for m in row.rss_mb)
    table = "\n".join(lines)
    for label in ("plain OpenCV script, OpenCV's default threads", "plain OpenCV script, OpenCV on 1 thread",
                  "klt, 1 thread |", "klt, 2 threads |"):
        assert f"| {label}" in table
    assert "shortest possible wall time per frame" in table and "| klt, 2 threads | " in table.split("what the CPU")[1]


def test_the_bound_is_the_calling_threads_cpu_or_the_total_over_the_cores():
    # the plain script's bounds: max(6, 9 / 2) = 6 beside 10 on one thread, then max(8, 16 / 2) = 8 beside 9
    plain = EndToEnd("plain OpenCV script", None, 100, baseline=True, cpu_ms=[9.0, 16.0], thread_ms=[6.0, 8.0])
    single = EndToEnd("plain OpenCV script", 1, 100, baseline=True, cpu_ms=[10.0, 9.0], thread_ms=[10.0, 9.0])
    one = EndToEnd("klt", 1, 100, cpu_ms=[4.0, 5.0], thread_ms=[4.0, 5.0])
    two = EndToEnd("klt", 2, 100, cpu_ms=[4.6, 3.0], thread_ms=[2.2, 2.0])  # total / 2 vs the tracker
    features = EndToEnd('features:{"descriptor": "orb"}', 2, 100, cpu_ms=[3.0, 3.0], thread_ms=[1.0, 1.0])
    assert [wall_bound_ms(two, r, cores=2) for r in (0, 1)] == [pytest.approx(2.3), pytest.approx(2.0)]
    assert wall_bound_ms(two, 0, cores=1) == pytest.approx(4.6)  # two threads on one core
    lines = bound_table([plain, single, one, two, features], cores=2).splitlines()
    assert len(lines) == 5 and not any("plain OpenCV" in line for line in lines)
    cells = [[c.strip() for c in line.strip("|").split("|")] for line in lines[2:]]
    # ceilings: 6 / 4 = 1.5 and 8 / 5 = 1.6 against 3; 6 / 2.3 and 8 / 2.0 against 5; 6 / 1.5 and 8 / 1.5
    assert cells[0][2:] == ["4.50 (4.00-5.00) ms", "7.00 (6.00-8.00) ms", "1.55 (1.50-1.60)", "3", "no"]
    assert cells[1][4:] == ["3.30 (2.61-4.00)", "5", "no"]
    assert cells[2][4:] == ["4.67 (4.00-5.33)", "2", "yes"]


def test_a_variant_row_runs_the_frontend_with_its_options(short, monkeypatch):
    """A frontend given as ``'klt:{...}'`` (``benchmarks/frontend_speed.py end-to-end --variant``): the row's
    runs get those options."""
    import fusion_vo.benchmark as benchmark

    seen = []
    real = benchmark.run_visual_odometry
    monkeypatch.setattr(benchmark, "run_visual_odometry",
                        lambda rec, config, **kw: seen.append(config.frontend_options) or real(rec, config, **kw))
    lines = []
    rows = run_benchmark(short, ["klt", 'klt:{"fb_skip_ratio": 0.9}'], None, [1], repeats=1, max_frames=20,
                         stages=False, out=lines.append)
    assert [r.name for r in rows] == ["klt", 'klt:{"fb_skip_ratio": 0.9}'] and all(r.failed == 0 for r in rows)
    assert seen == [{}, {"fb_skip_ratio": 0.9}]
    assert not any("plain OpenCV" in line for line in lines)


def test_plain_script_measures_a_known_shift():
    """The baseline's per-frame step finds a pure image shift (and fails on a blank frame)."""
    rng = np.random.default_rng(0)
    prev = cv2.GaussianBlur((rng.random((240, 320)) * 255).astype(np.uint8), (5, 5), 1.5)
    cur = np.roll(prev, (2, 3), axis=(0, 1))  # 3 px right, 2 px down
    tx, ty, angle, scale = baseline.similarity_parameters(baseline.measure(prev, cur))
    assert abs(tx - 3.0) < 0.05 and abs(ty - 2.0) < 0.05 and abs(angle) < 1e-3 and abs(scale - 1.0) < 1e-3
    assert baseline.measure(np.zeros_like(prev), cur) is None


#: run ``fusion-vo bench`` and report every file or folder under ``benchmarks/`` that the process opens or lists
_AUDIT = textwrap.dedent("""
    import os, sys
    root = os.path.realpath(sys.argv[1])
    seen = []
    def hook(event, args):
        if event in ("open", "os.listdir", "os.scandir") and args and isinstance(args[0], (str, bytes, os.PathLike)):
            path = os.path.realpath(os.fsdecode(args[0]))
            if path == root or path.startswith(root + os.sep):
                seen.append(path)
    sys.addaudithook(hook)
    from fusion_vo.cli.main import main
    status = main(["bench", sys.argv[2], "--frontend", "klt", "--threads", "1", "--repeats", "1", "--frames", "8"])
    print("READ", seen)
    sys.exit(status)
""")


def test_bench_reads_nothing_under_benchmarks(short, tmp_path):
    """``fusion-vo bench`` measures the packaged plain script: it opens and lists nothing under ``benchmarks/``,
    which a wheel install does not have."""
    benchmarks = Path(__file__).resolve().parents[2] / "benchmarks"
    proc = subprocess.run([sys.executable, "-c", _AUDIT, str(benchmarks), str(short)], capture_output=True,
                          text=True, cwd=tmp_path, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "READ []" in proc.stdout, proc.stdout[-2000:]
    assert "| plain OpenCV script, OpenCV on 1 thread |" in proc.stdout
