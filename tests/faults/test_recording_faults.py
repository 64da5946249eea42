"""A recording broken in one way at a time: ``fusion-vo run`` stops before any work with one line naming
the file and the line (or key), exit status 2, and writes nothing."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from fault_tools import assert_error, cli, snapshot


def _rows(path: Path) -> list[str]:
    return path.read_text().splitlines()


def _set_row(path: Path, index: int, text: str) -> int:
    """Replace data row ``index`` (0 = first row after the header) and return its 1-based line number."""
    lines = _rows(path)
    lines[index + 1] = text
    path.write_text("\n".join(lines) + "\n")
    return index + 2


def _field(path: Path, index: int, column: int) -> str:
    return _rows(path)[index + 1].split(",")[column]


def nan_in_wheel(rec):
    p = rec / "wheel0" / "data.csv"
    t = _field(p, 5, 0)
    return "wheel0/data.csv", _set_row(p, 5, f"{t},nan,12")


def too_few_fields_in_imu(rec):
    p = rec / "imu0" / "data.csv"
    return "imu0/data.csv", _set_row(p, 7, _field(p, 7, 0) + ",0.1,0.2")


def word_in_imu(rec):
    p = rec / "imu0" / "data.csv"
    row = _rows(p)[4].split(",")
    row[3] = "fast"
    return "imu0/data.csv", _set_row(p, 3, ",".join(row))


def duplicate_frame_time(rec):
    p = rec / "cam0" / "data.csv"
    return "cam0/data.csv", _set_row(p, 3, _field(p, 2, 0) + "," + _field(p, 3, 1))


def frame_listed_twice(rec):
    """Two rows naming one image: a pair of identical frames reads as a standstill while the robot drives."""
    p = rec / "cam0" / "data.csv"
    return "cam0/data.csv", _set_row(p, 4, _field(p, 4, 0) + "," + _field(p, 3, 1))


def decreasing_wheel_time(rec):
    p = rec / "wheel0" / "data.csv"
    row = _rows(p)[11].split(",")
    row[0] = _field(p, 2, 0)
    return "wheel0/data.csv", _set_row(p, 10, ",".join(row))


def negative_timestamp(rec):
    p = rec / "imu0" / "data.csv"
    row = _rows(p)[1].split(",")
    row[0] = "-5"
    return "imu0/data.csv", _set_row(p, 0, ",".join(row))


def absolute_frame_path(rec):
    p = rec / "cam0" / "data.csv"
    return "cam0/data.csv", _set_row(p, 4, _field(p, 4, 0) + ",/etc/hostname")


def frame_path_leaving_the_recording(rec):
    p = rec / "cam0" / "data.csv"
    return "cam0/data.csv", _set_row(p, 6, _field(p, 6, 0) + ",../../imu0/data.csv")


def timestamp_near_2_63(rec):
    p = rec / "imu0" / "data.csv"
    n = len(_rows(p)) - 2
    row = _rows(p)[-1].split(",")
    row[0] = str(2**63 - 10)
    return "imu0/data.csv", _set_row(p, n, ",".join(row))


def ground_truth_with_one_row(rec):
    p = rec / "state_groundtruth_estimate0" / "data.csv"
    p.write_text("\n".join(_rows(p)[:2]) + "\n")
    return "state_groundtruth_estimate0/data.csv", None


def ground_truth_repeated_time(rec):
    p = rec / "state_groundtruth_estimate0" / "data.csv"
    row = _rows(p)[9].split(",")
    row[0] = _field(p, 7, 0)
    return "state_groundtruth_estimate0/data.csv", _set_row(p, 8, ",".join(row))


def ground_truth_bad_quaternion(rec):
    p = rec / "state_groundtruth_estimate0" / "data.csv"
    row = _rows(p)[3].split(",")
    row[4:8] = ["0", "0", "0", "0"]
    return "state_groundtruth_estimate0/data.csv", _set_row(p, 2, ",".join(row))


def _shift_stream(path: Path, seconds: float) -> None:
    lines = _rows(path)
    out = [lines[0]]
    for line in lines[1:]:
        t, rest = line.split(",", 1)
        out.append(f"{int(t) + int(seconds * 1e9)},{rest}")
    path.write_text("\n".join(out) + "\n")


def imu_on_another_clock(rec):
    _shift_stream(rec / "imu0" / "data.csv", 1000.0)
    return "do not overlap", None


def ground_truth_on_another_clock(rec):
    _shift_stream(rec / "state_groundtruth_estimate0" / "data.csv", -5000.0)
    return "state_groundtruth_estimate0/data.csv", None


def missing_frame_list(rec):
    (rec / "cam0" / "data.csv").unlink()
    return "cam0/data.csv", None


def imu_symlink_loop(rec):
    p = rec / "imu0" / "data.csv"
    p.unlink()
    os.symlink("data.csv", p)
    return "imu0/data.csv: symbolic link loop", None


def wheel_broken_link(rec):
    p = rec / "wheel0" / "data.csv"
    p.unlink()
    os.symlink("/nonexistent/wheel.csv", p)
    return "wheel0/data.csv: broken symbolic link", None


def frame_list_is_a_folder(rec):
    p = rec / "cam0" / "data.csv"
    p.unlink()
    p.mkdir()
    return "cam0/data.csv: is a folder", None


def binary_imu_file(rec):
    (rec / "imu0" / "data.csv").write_bytes(b"\x89PNG\r\n\x1a\n\xff\xfe\x00garbage")
    return "imu0/data.csv", None


def empty_frame_list(rec):
    (rec / "cam0" / "data.csv").write_text("#timestamp [ns],filename\n")
    return "cam0/data.csv: no frames listed", None


def one_frame(rec):
    p = rec / "cam0" / "data.csv"
    p.write_text("\n".join(_rows(p)[:2]) + "\n")
    return "cam0/data.csv: 1 frame listed", None


def no_frame_folder(rec):
    import shutil

    shutil.rmtree(rec / "cam0" / "data")
    return "cam0", None


def camera_yaml_missing_key(rec):
    p = rec / "cam0" / "sensor.yaml"
    p.write_text("\n".join(ln for ln in p.read_text().splitlines() if not ln.startswith("intrinsics")) + "\n")
    return "cam0/sensor.yaml", None


def camera_yaml_not_yaml(rec):
    (rec / "cam0" / "sensor.yaml").write_text("intrinsics: [1, 2\nresolution: {\n")
    return "cam0/sensor.yaml", None


def wheel_yaml_negative_radius(rec):
    p = rec / "wheel0" / "sensor.yaml"
    p.write_text(p.read_text().replace("wheel_radius_left: 0.05", "wheel_radius_left: -0.05"))
    return "wheel0/sensor.yaml", None


def bad_bit_depth(rec):
    p = rec / "cam0" / "sensor.yaml"
    p.write_text(p.read_text() + "bit_depth: 11\n")
    return "cam0/sensor.yaml", None


def wheel_tick_beyond_2_53(rec):
    p = rec / "wheel0" / "data.csv"
    return "wheel0/data.csv", _set_row(p, 6, _field(p, 6, 0) + ",99999999999999999999999,12")


def imu_yaml_noise_not_a_number(rec):
    p = rec / "imu0" / "sensor.yaml"
    text = p.read_text()
    assert "gyroscope_noise_density:" in text
    p.write_text("\n".join("gyroscope_noise_density: low" if ln.startswith("gyroscope_noise_density:") else ln
                           for ln in text.splitlines()) + "\n")
    return "imu0/sensor.yaml: 'gyroscope_noise_density' must be a number", None


def imu_yaml_noise_nan(rec):
    p = rec / "imu0" / "sensor.yaml"
    p.write_text("\n".join("gyroscope_random_walk: .nan" if ln.startswith("gyroscope_random_walk:") else ln
                           for ln in p.read_text().splitlines()) + "\n")
    return "imu0/sensor.yaml: 'gyroscope_random_walk' must be non-negative", None


FAULTS = [nan_in_wheel, too_few_fields_in_imu, word_in_imu, duplicate_frame_time, frame_listed_twice,
          decreasing_wheel_time,
          negative_timestamp, absolute_frame_path, frame_path_leaving_the_recording, timestamp_near_2_63,
          ground_truth_with_one_row, ground_truth_repeated_time, ground_truth_bad_quaternion,
          imu_on_another_clock, ground_truth_on_another_clock, missing_frame_list, imu_symlink_loop,
          wheel_broken_link, frame_list_is_a_folder, binary_imu_file, empty_frame_list, one_frame, no_frame_folder,
          camera_yaml_missing_key, camera_yaml_not_yaml, wheel_yaml_negative_radius, bad_bit_depth,
          wheel_tick_beyond_2_53, imu_yaml_noise_not_a_number, imu_yaml_noise_nan]


@pytest.mark.parametrize("fault", FAULTS, ids=[f.__name__ for f in FAULTS])
def test_broken_recording_is_one_line_naming_the_file_and_nothing_is_written(fault, recording, tmp_path, capsys,
                                                                             monkeypatch):
    where, line = fault(recording)
    before = snapshot(tmp_path)
    out = tmp_path / "out"

    def no_work(*args, **kwargs):  # every fault must be found before visual odometry starts
        raise AssertionError("visual odometry started on a broken recording")

    monkeypatch.setattr("fusion_vo.pipeline.run_visual_odometry", no_work)
    status, _, err = cli(capsys, "run", recording, "--out", out)
    assert_error(status, err, where if line is None else f"{where}:{line}")
    assert not out.exists()
    assert snapshot(tmp_path) == before  # nothing written, nothing left behind (no lock, no staging folder)


def test_clock_error_names_both_streams_and_their_spans(recording, tmp_path, capsys):
    imu_on_another_clock(recording)
    status, _, err = cli(capsys, "run", recording, "--out", tmp_path / "out", "--sensors", "wheel,imu")
    assert_error(status, err, "wheel", "imu", "do not overlap", "s to ")


def test_a_stream_not_used_may_be_broken(recording, tmp_path, capsys):
    imu_symlink_loop(recording)
    status, _, err = cli(capsys, "run", recording, "--out", tmp_path / "out", "--sensors", "wheel",
                         "--backend", "none", "--no-evaluate")
    assert status == 0, err
    assert (tmp_path / "out" / "wheel.tum").is_file()
