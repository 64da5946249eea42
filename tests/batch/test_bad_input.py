"""Bad input to batch and sweep: one line, exit status 2, nothing written, no cluster left behind."""

import sys
import time

import pytest

from fusion_vo.batch import plan_batch
from fusion_vo.batch.grid import parse_grid
from fusion_vo.cli.main import main
from fusion_vo.config import RunConfig
from fusion_vo.errors import InputError


def _fails(capsys, argv, *needles):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("fusion-vo: error: "), err
    for needle in needles:
        assert needle in err, (needle, err)
    return err


@pytest.mark.parametrize("text, needles", [
    ("grid:\n  klt.max_trackz: [40, 60]\n", ["klt.max_trackz", "max_tracks"]),
    ("grid:\n  harris_k: [0.04]\n", ["harris_k"]),
    ("grid:\n  features.harris_k: [0.04]\n  fusion.wheel.k_slip: [1, 2]\n", ["k_slip"]),
    ("grid: {}\n", ["empty"]),
    ("grid:\n  klt.threshold: []\n", ["klt.threshold", "no values"]),
    ("random: 4\nranges: {}\n", ["empty"]),
    ("random: 4\nranges:\n  klt.threshold: {low: 2.0}\n", ["klt.threshold"]),
    ("grid:\n  klt.max_tracks: [40, 5]\n", ["max_tracks=5"]),
])
def test_bad_grid(text, needles, recordings, tmp_path, capsys):
    good, _ = recordings
    grid = tmp_path / "GRID.yaml"
    grid.write_text(text)
    out = tmp_path / "out"
    _fails(capsys, ["sweep", str(good[0]), "--grid", str(grid), "--out", str(out)], str(grid), *needles)
    assert not out.exists()


def test_recording_listed_twice(recordings, tmp_path, capsys):
    good, _ = recordings
    out = tmp_path / "out"
    _fails(capsys, ["batch", str(good[0]), str(good[1]), str(good[0]) + "/", "--out", str(out)], "listed twice")
    assert not out.exists()


def test_missing_recording(recordings, tmp_path, capsys):
    good, _ = recordings
    _fails(capsys, ["batch", str(good[0]), str(tmp_path / "nowhere"), "--out", str(tmp_path / "out")],
           str(tmp_path / "nowhere"), "not found")
    assert not (tmp_path / "out").exists()


def test_out_is_a_file(recordings, tmp_path, capsys):
    good, _ = recordings
    out = tmp_path / "results"
    out.write_text("keep me")
    _fails(capsys, ["batch", str(good[0]), "--out", str(out)], str(out), "folder")
    assert out.read_text() == "keep me"


def test_unreachable_scheduler_fails_within_10_s(recordings, tmp_path, capsys):
    good, _ = recordings
    start = time.monotonic()
    _fails(capsys, ["batch", str(good[0]), "--out", str(tmp_path / "out"), "--scheduler", "tcp://127.0.0.1:9"],
           "tcp://127.0.0.1:9", "cannot reach")
    assert time.monotonic() - start < 10.0
    assert not (tmp_path / "out").exists()


def test_without_the_batch_extra(recordings, tmp_path, capsys, monkeypatch):
    good, _ = recordings
    monkeypatch.setitem(sys.modules, "distributed", None)  # import fails as if not installed
    _fails(capsys, ["batch", str(good[0]), "--out", str(tmp_path / "out")], "fusion-vo[batch]")


def test_random_samples_are_reproducible_and_inside_their_ranges():
    data = {"random": 30, "seed": 7, "ranges": {"features.harris_k": {"low": 0.01, "high": 0.2, "log": True},
                                                "features.max_corners": {"low": 50, "high": 60},
                                                "features.detector": ["harris", "fast"]},
            "fixed": {"frontend": "features"}}
    first, again = parse_grid(data, RunConfig()), parse_grid(data, RunConfig())
    assert [s.values for s in first.sets] == [s.values for s in again.sets]
    values = [s.values for s in first.sets]
    assert len(values) == 30 and all(0.01 <= v["features.harris_k"] <= 0.2 for v in values)
    assert {v["features.max_corners"] for v in values} <= set(range(50, 61))
    assert all(type(v["features.max_corners"]) is int for v in values)
    assert {v["features.detector"] for v in values} == {"harris", "fast"}
    assert all(c.frontend == "features" and c.features["harris_k"] == s.values["features.harris_k"]
               for c, s in zip(first.configs, first.sets))
    other = parse_grid({**data, "seed": 8}, RunConfig())
    assert [s.values for s in other.sets] != values


def test_plan_of_10000_recordings_is_fast(tmp_path):
    root = tmp_path / "fleet"
    paths = []
    for i in range(10_000):
        path = root / f"{i // 100:03d}" / f"drive{i:05d}"
        path.mkdir(parents=True)
        paths.append(path)
    start = time.perf_counter()
    tasks = plan_batch(paths, RunConfig(), tmp_path / "out")
    assert time.perf_counter() - start < 10.0
    assert len({t.run_dir for t in tasks}) == 10_000 and not (tmp_path / "out").exists()
    with pytest.raises(InputError, match="listed twice"):
        plan_batch(paths + [paths[5000]], RunConfig(), tmp_path / "out")


def test_thesis_sweep_example_expands_to_valid_sets():
    from pathlib import Path

    from fusion_vo.batch import load_grid

    grid = load_grid(Path(__file__).parents[2] / "examples" / "thesis_sweep.yaml", RunConfig())
    assert grid.keys == ["features.detector", "features.harris_k", "features.max_corners", "features.ratio",
                         "features.threshold"]
    assert len(grid.sets) == 108 and len({tuple(s.values.values()) for s in grid.sets}) == 108
    assert all(c.frontend == "features" and c.backend == "none" for c in grid.configs)
