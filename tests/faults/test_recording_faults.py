"""A recording broken in one way at a time: ``fusion-vo run`` stops before any work with one line naming
the file and the line (or key), exit status 2, and writes nothing."""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import pytest

from fault_tools import assert_error, cli, snapshot
from fusion_vo.sensors.gps import read_fixes
from fusion_vo.sensors.imu import read_imu
from fusion_vo.sensors.wheel import read_ticks, read_twist


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
    return "imu0/sensor.yaml: gyroscope_noise_density: expected a number, got 'low'", None


def imu_yaml_noise_nan(rec):
    p = rec / "imu0" / "sensor.yaml"
    p.write_text("\n".join("gyroscope_random_walk: .nan" if ln.startswith("gyroscope_random_walk:") else ln
                           for ln in p.read_text().splitlines()) + "\n")
    return "imu0/sensor.yaml: gyroscope_random_walk must be a finite number, not nan", None


def gps_folder_without_data(rec):
    """GPS is not fused by default and scores a run only without ground truth: a gps0/ without its data.csv
    would be left out without a word (range0/ without one is an error too)."""
    (rec / "gps0").mkdir()
    return "gps0/data.csv: file not found", None


def extra_field_in_wheel(rec):
    p = rec / "wheel0" / "data.csv"
    return "wheel0/data.csv", _set_row(p, 4, _rows(p)[5] + ",7")


def trailing_comma_in_wheel(rec):
    p = rec / "wheel0" / "data.csv"
    return "wheel0/data.csv", _set_row(p, 4, _rows(p)[5] + ",")


def third_column_in_frame_list(rec):
    p = rec / "cam0" / "data.csv"
    return "cam0/data.csv", _set_row(p, 3, _rows(p)[4] + ",extra")


def _wheel_timestamp(rec, text):
    p = rec / "wheel0" / "data.csv"
    row = _rows(p)[6].split(",")
    row[0] = text(row[0])
    return "wheel0/data.csv", _set_row(p, 5, ",".join(row))


def float_timestamp_in_wheel(rec):
    return _wheel_timestamp(rec, lambda t: f"{int(t):.10e}")  # 1.6000000001e+18: integral, still not one


def timestamp_with_decimal_point(rec):
    return _wheel_timestamp(rec, lambda t: t + ".0")


def timestamp_with_digit_separators(rec):
    return _wheel_timestamp(rec, lambda t: t[:4] + "_" + t[4:])


def header_only_imu(rec):
    p = rec / "imu0" / "data.csv"
    p.write_text(_rows(p)[0] + "\n")
    return "imu0/data.csv: no data rows", None


def empty_imu(rec):
    (rec / "imu0" / "data.csv").write_text("")
    return "imu0/data.csv: no data rows", None


def one_row_wheel(rec):
    p = rec / "wheel0" / "data.csv"
    p.write_text("\n".join(_rows(p)[:2]) + "\n")
    return "wheel0/data.csv:2: only 1 data row", None


def _set_value(path: Path, index: int, column: int, text: str) -> int:
    """Replace field ``column`` (0 = the timestamp) of data row ``index``; returns its line number."""
    row = _rows(path)[index + 1].split(",")
    row[column] = text
    return _set_row(path, index, ",".join(row))


# finite but absurd numbers: each once gave exit status 0 and a silently wrong answer
def ground_truth_x_1e300(rec):
    """One ground-truth row with x = 1e300 scored the run 'end 0.00 %'."""
    p = rec / "state_groundtruth_estimate0" / "data.csv"
    return "state_groundtruth_estimate0/data.csv", _set_value(p, 4, 1, "1e300")


def gyro_rate_1e300(rec):
    p = rec / "imu0" / "data.csv"
    return "imu0/data.csv", _set_value(p, 9, 3, "1e300")


def acceleration_1e30(rec):
    p = rec / "imu0" / "data.csv"
    return "imu0/data.csv", _set_value(p, 3, 5, "-1e30")


def range_of_1e300_m(rec):
    """A range0/ is read with the camera (as its height) before any work."""
    t = [int(_field(rec / "imu0" / "data.csv", i, 0)) for i in range(0, 40, 4)]
    rows = [f"{ti},{1e300 if i == 6 else 0.1}" for i, ti in enumerate(t)]
    (rec / "range0").mkdir()
    (rec / "range0" / "data.csv").write_text("#timestamp [ns],distance [m]\n" + "\n".join(rows) + "\n")
    return "range0/data.csv", 8


FAULTS = [nan_in_wheel, too_few_fields_in_imu, word_in_imu, duplicate_frame_time, frame_listed_twice,
          decreasing_wheel_time,
          negative_timestamp, absolute_frame_path, frame_path_leaving_the_recording, timestamp_near_2_63,
          ground_truth_with_one_row, ground_truth_repeated_time, ground_truth_bad_quaternion,
          imu_on_another_clock, ground_truth_on_another_clock, missing_frame_list, imu_symlink_loop,
          wheel_broken_link, frame_list_is_a_folder, binary_imu_file, empty_frame_list, one_frame, no_frame_folder,
          camera_yaml_missing_key, camera_yaml_not_yaml, wheel_yaml_negative_radius, bad_bit_depth,
          wheel_tick_beyond_2_53, imu_yaml_noise_not_a_number, imu_yaml_noise_nan,
          gps_folder_without_data, extra_field_in_wheel, trailing_comma_in_wheel, third_column_in_frame_list,
          float_timestamp_in_wheel, timestamp_with_decimal_point, timestamp_with_digit_separators,
          header_only_imu, empty_imu, one_row_wheel,
          ground_truth_x_1e300, gyro_rate_1e300, acceleration_1e30, range_of_1e300_m]


# ---------------------------------------------------------------------- sensor.yaml values
def _edit_yaml(path: Path, change) -> None:
    """Apply ``change(data)`` to a ``sensor.yaml`` (read and written back as YAML)."""
    import yaml

    data = yaml.safe_load(path.read_text())
    change(data)
    path.write_text(yaml.safe_dump(data, sort_keys=False))


def _yaml_fault(name: str, folder: str, change, expected: str):
    """A fault that edits ``FOLDER/sensor.yaml`` with ``change(data)`` and expects ``expected`` after its name."""
    def fault(rec):
        _edit_yaml(rec / folder / "sensor.yaml", change)
        return f"{folder}/sensor.yaml: {expected}", None

    fault.__name__ = name
    return fault


def _set(key, value):
    return lambda data: data.__setitem__(key, value)


def _pose_entry(index, value):
    return lambda data: data["T_BS"]["data"].__setitem__(index, value)


def imu_yaml_missing(rec):
    """datasets/README.md: a stream's missing sensor.yaml is an error (as for wheel0/ and cam0/), not an
    identity mounting and default noise assumed without a word."""
    (rec / "imu0" / "sensor.yaml").unlink()
    return "imu0/sensor.yaml: file not found", None


#: what a T_BS whose rotation part is scaled or mirrored is
_NO_ROTATION = "T_BS must have a rotation matrix as its rotation part (orthonormal, determinant +1)"

SENSOR_YAML_FAULTS = [
    _yaml_fault("imu_T_BS_nan", "imu0", _pose_entry(0, float("nan")), "T_BS must hold finite numbers"),
    _yaml_fault("imu_T_BS_scaled", "imu0", _pose_entry(0, 3.0), _NO_ROTATION),
    _yaml_fault("imu_T_BS_shrunk", "imu0", _pose_entry(0, 0.5), _NO_ROTATION),
    _yaml_fault("imu_T_BS_mirror", "imu0", _pose_entry(0, -1.0), _NO_ROTATION),
    _yaml_fault("imu_T_BS_bottom_row", "imu0", _pose_entry(12, 0.5),
                "T_BS must have the bottom row [0, 0, 0, 1], not [0.5, 0.0, 0.0, 1.0]"),
    _yaml_fault("camera_T_BS_height_1e300", "cam0", _pose_entry(11, 1e300),
                "T_BS must have a translation within 1000 m (a lever arm), not 1e+300 m"),
    _yaml_fault("camera_T_BS_lever_arm_1e300", "cam0", _pose_entry(3, 1e300), "T_BS must have a translation within"),
    *[_yaml_fault(f"{key}_true", folder, _set(key, True), f"{key}: expected a number, got True")
      for folder, key in (("wheel0", "ticks_per_revolution"), ("wheel0", "wheel_radius_left"),
                          ("wheel0", "wheel_base"), ("wheel0", "radius_sigma"), ("cam0", "height_sigma"),
                          ("imu0", "gyroscope_noise_density"), ("imu0", "rate_hz"), ("cam0", "rate_hz"))],
    _yaml_fault("camera_rate_a_word", "cam0", _set("rate_hz", "fast"), "rate_hz: expected a number, got 'fast'"),
    _yaml_fault("camera_rate_negative", "cam0", _set("rate_hz", -20), "rate_hz must be positive, not -20"),
    _yaml_fault("focal_length_1e308", "cam0", _set("intrinsics", [1e308, 1e308, 79.5, 59.5]),
                "intrinsics: focal lengths 1e+308, 1e+308 px are not a camera's for a 160x120 image"),
    _yaml_fault("focal_length_1e-9", "cam0", _set("intrinsics", [1e-9, 1e-9, 79.5, 59.5]),
                "intrinsics: focal lengths 1e-09, 1e-09 px are not a camera's for a 160x120 image"),
    _yaml_fault("resolution_fractional", "cam0", _set("resolution", [160.5, 120]),
                "resolution[0]: expected an integer, got 160.5"),
    _yaml_fault("principal_point_far_outside", "cam0", _set("intrinsics", [200, 200, 5000, -3000]),
                "the intrinsics"),
    _yaml_fault("distortion_1e300", "cam0", _set("distortion_coefficients", [1e300, 0, 0, 0]),
                "distortion_coefficients[0]: must be at most 1000000, not 1e+300"),
    _yaml_fault("height_sigma_1e300", "cam0", _set("height_sigma", 1e300), "height_sigma must be at most 1000, not"),
    _yaml_fault("gyro_noise_1e300", "imu0", _set("gyroscope_noise_density", 1e300),
                "gyroscope_noise_density must be at most 1000, not 1e+300"),
    _yaml_fault("wheel_base_1e-300", "wheel0", _set("wheel_base", 1e-300), "wheel_base must be at least 1e-06, not"),
    _yaml_fault("wheel_radius_1e300", "wheel0", _set("wheel_radius_right", 1e300),
                "wheel_radius_right must be at most 1000, not 1e+300"),
    _yaml_fault("wheel_key_missing", "wheel0", lambda data: data.pop("wheel_base"), "missing key 'wheel_base'"),
    _yaml_fault("bit_depth_9", "cam0", _set("bit_depth", 9), "bit_depth: expected one of 8, 10, 12, 14 or 16, got 9"),
    _yaml_fault("coefficients_with_model_none", "cam0", _set("distortion_model", "none"),
                "distortion_coefficients are not all zero but distortion_model is 'none'"),
    imu_yaml_missing,
    # finite but absurd: fx = fy = 1e-9 ended a run 1.9e11 m away (above); a fractional resolution was cut down
    # silently (above)
    _yaml_fault("focal_length_1e6", "cam0", _set("intrinsics", [1e6, 1e6, 79.5, 59.5]), "intrinsics: focal lengths"),
    _yaml_fault("resolution_1e9", "cam0", _set("resolution", [160, 10**9]),
                "resolution[1]: must be at most 100000, not 1000000000"),
    _yaml_fault("camera_500_m_high", "cam0", _pose_entry(11, 500.0), "camera height must be in (0, 100] m, not 500"),
    _yaml_fault("camera_T_BS_bottom_row", "cam0", _pose_entry(15, 2.0),
                "T_BS must have the bottom row [0, 0, 0, 1], not [0.0, 0.0, 0.0, 2.0]"),
]
FAULTS += SENSOR_YAML_FAULTS


def wheel_yaml_integer_of_5001_digits(rec):
    """Python refuses to convert it ('Exceeds the limit (4300 digits)'): an internal error."""
    p = rec / "wheel0" / "sensor.yaml"
    text = p.read_text()
    assert "ticks_per_revolution: 4096" in text
    p.write_text(text.replace("ticks_per_revolution: 4096", "ticks_per_revolution: " + "9" * 5001))
    line = 1 + text[:text.index("ticks_per_revolution")].count("\n")
    return "wheel0/sensor.yaml", line


FAULTS.append(wheel_yaml_integer_of_5001_digits)


def latin_1_byte_in_the_imu_header(rec):
    """'not a text CSV file' named no line."""
    p = rec / "imu0" / "data.csv"
    data = p.read_bytes()
    p.write_bytes(data[:10] + b"\xe9" + data[11:])  # one byte of the header's first column name
    return "imu0/data.csv:1: not a text CSV file: byte 0xe9 is not UTF-8", None


def latin_1_byte_in_a_frame_name(rec):
    p = rec / "cam0" / "data.csv"
    lines = p.read_bytes().split(b"\n")
    lines[4] = lines[4][:-5] + b"\xe9.png"
    p.write_bytes(b"\n".join(lines))
    return "cam0/data.csv:5: not a text CSV file: byte 0xe9", None


FAULTS += [latin_1_byte_in_the_imu_header, latin_1_byte_in_a_frame_name]


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


def _gps_with_a_jump(rec: Path, jump_s: float) -> int:
    """``gps0/``: 20 fixes over the wheels' span, the fifth unusable (no fix: skipped by the reader) and those from
    the tenth on ``jump_s`` later; the line of the tenth fix."""
    from fusion_vo.recording.gps import HEADER, enu_to_geodetic, format_rows

    t_wheel = np.loadtxt(rec / "wheel0" / "data.csv", delimiter=",", comments="#", usecols=0, dtype=np.int64)
    t_ns = np.linspace(t_wheel[0], t_wheel[-1], 20).astype(np.int64)
    t_ns[9:] += int(jump_s * 1e9)
    enu = np.zeros((len(t_ns), 3))
    status = np.zeros(len(t_ns), int)
    status[4] = -1
    rows = format_rows(t_ns, enu_to_geodetic(enu, (45.0, 7.0, 200.0)), enu, status, np.full(len(t_ns), 2),
                       np.tile([0.25, 0.0, 0.25], (len(t_ns), 1)))
    (rec / "gps0").mkdir()
    (rec / "gps0" / "data.csv").write_text("\n".join([HEADER, *rows]) + "\n")
    return 11  # the header is line 1


def test_fixes_on_another_clock_are_named_with_their_line_as_every_stream_is(recording, tmp_path, capsys):
    """GPS, read by its sensor's reader as every stream is, gets the checks of the run's inputs: a jump of two days
    inside ``gps0/data.csv`` names the file and the line of the fix after the jump (counted in the file's rows, not
    in the usable fixes the reader keeps), before any work."""
    line = _gps_with_a_jump(recording, 2 * 86400.0)
    status, _, err = cli(capsys, "run", recording, "--out", tmp_path / "out", "--sensors", "wheel,gps",
                         "--backend", "none", "--no-evaluate")
    assert_error(status, err, f"gps0/data.csv:{line}", "timestamp jumps by 172800 s")
    assert not (tmp_path / "out").exists()


def test_a_stream_not_used_may_be_broken(recording, tmp_path, capsys):
    imu_symlink_loop(recording)
    status, _, err = cli(capsys, "run", recording, "--out", tmp_path / "out", "--sensors", "wheel",
                         "--backend", "none", "--no-evaluate")
    assert status == 0, err
    assert (tmp_path / "out" / "wheel.tum").is_file()


def test_replay_of_a_gps_folder_without_data_names_the_file(recording, tmp_path, capsys):
    where, _ = gps_folder_without_data(recording)
    status, _, err = cli(capsys, "replay", recording, "--out", tmp_path / "out")
    assert_error(status, err, where)
    assert not (tmp_path / "out").exists()


def test_a_byte_order_mark_is_read_like_any_csv(recording, pristine_run, tmp_path, capsys):
    """Excel writes a UTF-8 byte order mark before the header: it is no part of the first field."""
    for folder in ("cam0", "imu0", "wheel0", "state_groundtruth_estimate0"):
        p = recording / folder / "data.csv"
        p.write_bytes(b"\xef\xbb\xbf" + p.read_bytes())
    status, _, err = cli(capsys, "run", recording, "--out", tmp_path / "out", "--backend", "ekf", "--no-evaluate")
    assert status == 0, err
    assert (tmp_path / "out" / "ekf.tum").read_text() == (pristine_run / "ekf.tum").read_text()


def test_ground_truth_may_have_further_columns(recording):
    """datasets/README.md: further ground-truth columns are ignored (EuRoC's has velocities and biases)."""
    from fusion_vo.recording.reader import read_groundtruth_csv

    p = recording / "state_groundtruth_estimate0" / "data.csv"
    before = read_groundtruth_csv(p)
    p.write_text("\n".join(_rows(p)[:1] + [row + ",0.5,0.25," for row in _rows(p)[1:]]) + "\n")
    after = read_groundtruth_csv(p)
    assert np.array_equal(after.t, before.t) and np.array_equal(after.xyyaw, before.xyyaw)


def test_a_frame_that_is_a_fifo_is_skipped_with_a_warning(recording, tmp_path, capsys, caplog):
    """Reading a FIFO blocks until something writes to it: a run would wait forever."""
    import threading

    frame = sorted((recording / "cam0" / "data").iterdir())[5]
    frame.unlink()
    os.mkfifo(frame)
    blocked = []

    def unblock():  # a reader stuck on the FIFO gets end of file (and the test fails instead of hanging)
        try:
            os.close(os.open(frame, os.O_WRONLY | os.O_NONBLOCK))
            blocked.append(True)
        except OSError:  # nobody has it open for reading
            pass

    timer = threading.Timer(60.0, unblock)
    timer.start()
    try:
        status, out, err = cli(capsys, "run", recording, "--out", tmp_path / "out", "--backend", "none",
                               "--no-evaluate")
    finally:
        timer.cancel()
    assert not blocked, "the run blocked on a FIFO"
    assert status == 0, err
    assert f"{frame.name}: not a regular file" in caplog.text
    assert "1 skipped (unreadable)" in out


@pytest.mark.parametrize("folder, key, known", [("cam0", "hieght_sigma", "height_sigma"),
                                                ("wheel0", "radius_sgma", "radius_sigma"),
                                                ("imu0", "gyroscope_noise_densty", "gyroscope_noise_density")])
def test_a_misspelt_sensor_yaml_key_is_a_warning_naming_the_file_and_the_key_meant(recording, caplog, folder, key,
                                                                                  known):
    """EuRoC files carry keys the library does not read (comment, sensor_type ...): an unknown key is no
    error, but one close to a key that file type reads is named with a warning, never silently ignored."""
    import logging

    from fusion_vo.recording import Recording

    _edit_yaml(recording / folder / "sensor.yaml", lambda data: data.update({key: 0.001, "comment": "x",
                                                                              "rostopic": "/a"}))
    rec = Recording(recording)
    with caplog.at_level(logging.WARNING):
        {"cam0": lambda: rec.camera, "wheel0": lambda: read_ticks(rec), "imu0": lambda: read_imu(rec)}[folder]()
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert warnings == [f"{recording / folder / 'sensor.yaml'}: unknown key '{key}' (did you mean '{known}'?)"]


def test_zero_coefficients_with_model_none_and_an_empty_imu_yaml_are_accepted(recording, caplog):
    """Coefficients that are all zero go with ``distortion_model: none``; an empty imu0/sensor.yaml uses the
    identity mounting and the configuration's noise, with a warning naming the file."""
    import logging

    from fusion_vo.recording import Recording

    _edit_yaml(recording / "cam0" / "sensor.yaml",
               lambda data: data.update({"distortion_model": "none", "distortion_coefficients": [0, 0, 0, 0]}))
    (recording / "imu0" / "sensor.yaml").write_text("")
    rec = Recording(recording)
    with caplog.at_level(logging.WARNING):
        assert not rec.camera.has_distortion
        imu = read_imu(rec)
    assert np.array_equal(imu.T_BS, np.eye(4)) and imu.noise == {}
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1 and warnings[0].startswith(f"{recording / 'imu0' / 'sensor.yaml'}: no T_BS")


@pytest.mark.parametrize("text, expected", [
    ("T_BS: {cols: 4, rows: 4, data: [-1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0.4, 0, 0, 0, 1]}", _NO_ROTATION),
    ("T_BS: {cols: 4, rows: 4, data: [1, 0, 0, .nan, 0, 1, 0, 0, 0, 0, 1, 0.4, 0, 0, 0, 1]}",
     "T_BS must hold finite numbers"),
    ("horizontal_sigma_m: true", "horizontal_sigma_m: expected a number, got True"),
    ("horizontal_sigma_m: 0", "horizontal_sigma_m must be positive, not 0"),
    ("datum: {latitude: 91, longitude: 0}", "datum: latitude must be at most 90, not 91"),
    ("datum: {longitude: 8}", "missing key 'datum.latitude'"),
])
def test_gps_yaml_pose_and_numbers_are_checked_like_every_sensor_yaml(tmp_path, text, expected):
    from fusion_vo.errors import InputError
    from fusion_vo.recording.gps import _sensor_yaml

    p = tmp_path / "sensor.yaml"
    p.write_text(text + "\n")
    with pytest.raises(InputError, match=re.escape(expected)) as info:
        _sensor_yaml(p)
    assert info.value.path == p


#: values beyond their physical range in the streams a run reads only when asked for: (stream, header, row, message)
PHYSICAL_RANGE_FAULTS = [
    ("odom0", "#timestamp [ns],vx [m/s],vy [m/s],wz [rad/s]", "{t},1e300,0,0", "speed [m/s] 1e+300 is beyond ±100"),
    ("odom0", "#timestamp [ns],vx [m/s],vy [m/s],wz [rad/s]", "{t},0.1,0,-500", "yaw rate [rad/s] -500 is beyond ±100"),
    ("gps0", "#timestamp [ns],latitude [deg],longitude [deg],altitude [m],e [m],n [m],u [m]",
     "{t},47.4,8.5,1e300,0,0,0", "altitude [m] 1e+300 is beyond ±100000"),
    ("gps0", "#timestamp [ns],latitude,longitude,altitude,e,n,u,status,covariance_type,cov_ee,cov_en,cov_nn",
     "{t},47.4,8.5,400,0,0,0,0,2,1e300,0,1", "covariance [m^2] 1e+300 is beyond ±1e+12"),
]


@pytest.mark.parametrize("stream, header, row, expected", PHYSICAL_RANGE_FAULTS)
def test_a_recorded_value_beyond_its_physical_range_names_the_file_and_line(recording, stream, header, row, expected):
    """The streams a run reads only when asked for (odometry twist, GPS): read here directly."""
    from fusion_vo.errors import InputError
    from fusion_vo.recording import Recording

    t = [int(_field(recording / "imu0" / "data.csv", i, 0)) for i in range(0, 30, 3)]
    good = row.replace("1e300", "1").replace("-500", "0.1")
    rows = [(row if i == 4 else good).format(t=ti) for i, ti in enumerate(t)]
    (recording / stream).mkdir()
    path = recording / stream / "data.csv"
    path.write_text(header + "\n" + "\n".join(rows) + "\n")
    rec = Recording(recording)
    with pytest.raises(InputError) as info:
        read_twist(rec) if stream == "odom0" else read_fixes(rec)
    assert str(info.value).startswith(f"{path}:6: {expected}")


def test_a_requested_sensor_whose_every_reading_is_gated_is_a_warning(recording, tmp_path, capsys, caplog):
    """A range0/ all at 1000 m, asked for with --sensors: exit 0 without a word (only summary.json said
    'used 0, gated 82')."""
    import json
    import logging

    t = [int(_field(recording / "imu0" / "data.csv", i, 0)) for i in range(0, len(_rows(recording / "imu0" / "data.csv")) - 1, 2)]
    (recording / "range0").mkdir()
    (recording / "range0" / "data.csv").write_text("#timestamp [ns],distance [m]\n" +
                                                   "".join(f"{ti},1000.0\n" for ti in t))
    with caplog.at_level(logging.WARNING):
        status, out, err = cli(capsys, "run", recording, "--out", tmp_path / "out", "--sensors", "camera,wheel,imu,range",
                               "--backend", "ekf", "--no-evaluate")
    assert status == 0, err
    note = "range contributed nothing to the ekf, ekf_smoothed estimate: none of its measurements was used ("
    assert f"note: {note}" in out and "gated)" in out
    assert any(note in n for n in json.loads((tmp_path / "out" / "summary.json").read_text())["notes"])
    assert any(note in r.getMessage() for r in caplog.records if r.levelno == logging.WARNING)
    assert "contributed nothing" not in out.replace(note, "")  # the other sensors did contribute


def test_ground_truth_with_two_poses_at_the_drive_s_end_names_it_not_the_clocks(recording, tmp_path, capsys):
    """Two poses, the first at the drive's end: the run failed naming OUT/vo.tum (a file the failed run does
    not keep) and asked whether the clocks differ."""
    p = recording / "state_groundtruth_estimate0" / "data.csv"
    lines = _rows(p)
    last = lines[-1].split(",")
    p.write_text("\n".join([lines[0], lines[-1], ",".join([str(int(last[0]) + 10**9)] + last[1:])]) + "\n")
    status, _, err = cli(capsys, "run", recording, "--out", tmp_path / "out", "--backend", "ekf")
    assert_error(status, err, f"{p}: only 0 of its 2 poses lie within the time span of trajectory",
                 "the evaluation needs two")
    assert "clock" not in err and str(tmp_path / "out") not in err
    assert not (tmp_path / "out").exists()
