"""``fusion-vo bench``: usage errors are one line with status 2; a short run prints both sides and the ratios."""

import pytest

from fusion_vo.benchmark import (BASELINE_SCRIPT, EndToEnd, bound_table, first_frames, load_baseline, run_benchmark,
                                 wall_bound_ms)
from fusion_vo.cli.main import main
from fusion_vo.recording import Recording
from fusion_vo.simulation.standard import make_standard


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
def short(tmp_path_factory):
    return make_standard("short", tmp_path_factory.mktemp("rec") / "short")


def test_first_frames_links_the_first_n(short, tmp_path):
    part = Recording(first_frames(short, 7, tmp_path / "part"))
    full = Recording(short)
    assert len(part) == 7
    assert list(part.frame_times) == list(full.frame_times[:7])
    a, b = next(part.frames(start=6)), next(full.frames(start=6))
    assert (a.image == b.image).all()


@pytest.mark.slow
def test_short_benchmark_prints_both_sides_and_ratios(short):
    assert BASELINE_SCRIPT.is_file()
    lines = []
    rows = run_benchmark(short, ["klt"], load_baseline(), [1, 2], repeats=1, max_frames=40, stages=False,
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
    """``bench_frontends.py --variant 'klt:{...}'``: the row's runs get those options (and bad ones are
    one-line usage errors)."""
    import sys
    from pathlib import Path

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
    monkeypatch.syspath_prepend(str(Path(BASELINE_SCRIPT).parent))
    from bench_frontends import main as bench_main

    for bad in ('klt:{"fb_skip_ratio": 2}', "klt:[1", 'bogus:{}'):
        monkeypatch.setattr(sys, "argv", ["bench_frontends.py", "--variant", bad])
        with pytest.raises(SystemExit) as exc:
            bench_main()
        assert exc.value.code == 2


def test_klt_profile_times_every_stage(short, monkeypatch, capsys):
    """``benchmarks/profile_klt.py``: every stage is reached (one forward pass and one fit per measured
    frame), and the stages and the rest add up to the calling thread's total."""
    import sys
    from pathlib import Path

    import frontends.direct as direct
    import frontends.klt as klt
    import frontends.tracking as tracking
    import fusion_vo.odometry as odometry
    import fusion_vo.recording.reader as reader

    monkeypatch.syspath_prepend(str(Path(BASELINE_SCRIPT).parent))
    import profile_klt

    # the profile wraps these in place: put them back afterwards
    for owner, name in [(tracking, "cv2"), (klt, "track_forward"), (klt, "check_backward"),
                        (klt, "estimate_similarity"), (klt, "exposure_correction"), (klt.KltFrontend, "_detect"),
                        (direct.DenseFallback, "verify"), (odometry.VisualOdometry, "finish"),
                        (reader, "read_image")]:
        monkeypatch.setattr(owner, name, getattr(owner, name))

    monkeypatch.setattr(sys, "argv", ["profile_klt.py", "--sequence", str(short), "--frames", "25"])
    assert profile_klt.main() == 0
    rows = {}
    for line in capsys.readouterr().out.splitlines():
        cells = [c.strip() for c in line.strip("|").split("|")]
        if len(cells) == 5 and cells[1][:1].isdigit():
            rows[cells[0]] = cells
    assert int(rows["decode"][3]) == 25
    assert int(rows["forward LK"][3]) == int(rows["similarity"][3]) >= 24
    assert int(rows["LK"][3]) >= 2 * 24  # forward and backward passes
    top = ["decode", "forward LK", "backward check", "similarity", "exposure", "new corners", "dense check",
           "derotation, geometry"]
    parts = sum(float(rows[k][1]) for k in top) + float(rows[next(k for k in rows if k.startswith("everything"))][1])
    assert parts == pytest.approx(float(rows["all"][1]), abs=0.01)


def test_handoff_benchmark_runs_both_ways_and_compares_them(short, monkeypatch, capsys):
    """``benchmarks/bench_handoff.py``: each frontend with and without its hand-off thread, same results."""
    import sys
    from pathlib import Path

    monkeypatch.syspath_prepend(str(Path(BASELINE_SCRIPT).parent))
    import bench_handoff

    monkeypatch.setattr(sys, "argv", ["bench_handoff.py", "--sequence", str(short), "--frames", "12",
                                      "--repeats", "1"])
    assert bench_handoff.main() == 0
    out = capsys.readouterr().out
    for fe in ("klt", "features"):
        for way in ("on", "off"):
            assert f"| {fe} | {way} |" in out
    assert out.count("identical bit for bit") == 4 and "DIFFERENT" not in out
    # the comparison itself can tell results apart
    from fusion_vo.odometry import OdometryConfig, run_visual_odometry

    a = run_visual_odometry(Recording(short), OdometryConfig(threads=1), frames=Recording(short).frames(stop=8))
    b = run_visual_odometry(Recording(short), OdometryConfig(threads=1), frames=Recording(short).frames(stop=8))
    assert bench_handoff.same(a, b)
    import dataclasses

    b.increments[3] = dataclasses.replace(b.increments[3], delta=b.increments[3].delta + 1e-12)
    assert not bench_handoff.same(a, b)
