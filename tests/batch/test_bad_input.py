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
    assert all(c.frontend == "features" and c.features.harris_k == s.values["features.harris_k"]
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


# ------------------------------------------------------------------ how many sets a grid gives; unused frontend keys
@pytest.mark.parametrize("text, needles", [
    # drew a trillion samples (it never finished): now refused before any draw
    ("random: 1000000000000\nranges:\n  fusion.max_gap: {low: 0.1, high: 0.3}\n", ["'random'", "1 to 10000"]),
    ("grid:\n  features.ratio: [0.7, 0.8]\n", ["grid key 'features.ratio'", "the runs use the klt frontend"]),
])
def test_a_grid_too_large_or_of_an_unused_frontend_is_one_line_naming_the_file(text, needles, recordings, tmp_path,
                                                                               capsys):
    good, _ = recordings
    grid = tmp_path / "GRID.yaml"
    grid.write_text(text)
    out = tmp_path / "out"
    start = time.perf_counter()
    _fails(capsys, ["sweep", str(good[0]), "--grid", str(grid), "--out", str(out)], str(grid), *needles)
    assert time.perf_counter() - start < 10.0
    assert not out.exists()


def test_the_number_of_parameter_sets_is_bounded():
    from fusion_vo.batch.grid import MAX_SETS

    ranges = {"fusion.max_gap": {"low": 0.1, "high": 0.3}}
    with pytest.raises(InputError, match=f"'random' must be a number of samples from 1 to {MAX_SETS}, not 10001"):
        parse_grid({"random": MAX_SETS + 1, "ranges": ranges}, RunConfig())
    values = [0.1 * i for i in range(1, 101)]  # 100 x 101 combinations
    with pytest.raises(InputError, match="'grid' gives 10100 parameter sets"):
        parse_grid({"grid": {"fusion.max_gap": values, "fusion.reorder_window": [0.0, *values]}}, RunConfig())


def test_a_key_of_a_frontend_the_runs_do_not_use_is_an_error_unless_the_frontend_is_swept(tmp_path):
    """``features.ratio: [0.7, 0.8]`` with the KLT frontend ran the same set twice and listed the key as swept."""
    from fusion_vo.batch.optimize import load_search

    with pytest.raises(InputError, match="'direct.min_sigma' is an option of the direct frontend, but the runs use "
                                         "the features frontend"):
        parse_grid({"grid": {"direct.min_sigma": [0.1, 0.2]}, "fixed": {"frontend": "features"}}, RunConfig())
    assert len(parse_grid({"grid": {"features.ratio": [0.7, 0.8]}}, RunConfig(frontend="features")).sets) == 2
    # with the frontend swept too, only the sets whose frontend reads the key differ in it
    grid = parse_grid({"grid": {"frontend": ["klt", "features"], "features.ratio": [0.7, 0.8]}}, RunConfig())
    assert [s.values for s in grid.sets] == [{"frontend": "klt", "features.ratio": None},
                                             {"frontend": "features", "features.ratio": 0.7},
                                             {"frontend": "features", "features.ratio": 0.8}]
    assert grid.configs[0].features == RunConfig().features and grid.configs[2].features.ratio == 0.8
    with pytest.raises(InputError, match="the runs use the klt and direct frontends"):
        parse_grid({"grid": {"frontend": ["klt", "direct"], "features.ratio": [0.7, 0.8]}}, RunConfig())
    path = tmp_path / "search.yaml"
    path.write_text("ranges:\n  features.ratio: {low: 0.6, high: 0.9}\n")
    with pytest.raises(InputError, match="'features.ratio' is an option of the features frontend"):
        load_search(path, RunConfig(), trials=5)
    with pytest.raises(InputError, match="--trials must be a number from 1 to 10000"):
        load_search(path, RunConfig(frontend="features"), trials=10**12)
    assert list(load_search(path, RunConfig(frontend="features"), trials=5).params) == ["features.ratio"]
