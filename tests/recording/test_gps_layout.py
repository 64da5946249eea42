"""gps0/: reading fixes into ENU at the datum, skipping unusable fixes, defaults without sensor.yaml."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from fusion_vo.errors import InputError
from fusion_vo.recording import Recording
from fusion_vo.recording.gps import DEFAULT_HORIZONTAL_SIGMA, HEADER, enu_to_geodetic, format_rows
from fusion_vo.sensors.gps import read_fixes

DATUM = (47.3977, 8.5456, 488.0)


def write_gps(root: Path, enu, status, cov_type, cov, yaml_data: dict | None) -> Path:
    enu = np.asarray(enu, float)
    geo = enu_to_geodetic(enu, DATUM)
    t_ns = 1_000_000_000 + np.arange(len(enu)) * 200_000_000
    lines = format_rows(t_ns, geo, enu, status, cov_type, cov)
    (root / "gps0").mkdir(parents=True)
    (root / "gps0" / "data.csv").write_text("\n".join([HEADER, *lines]) + "\n")
    if yaml_data is not None:
        (root / "gps0" / "sensor.yaml").write_text(yaml.safe_dump(yaml_data))
    return root


def test_fixes_are_read_in_enu_with_their_covariance_and_lever_arm(tmp_path):
    enu = np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 0.5], [10.0, -2.0, 1.0]])
    T = np.eye(4)
    T[:3, 3] = [-0.2, 0.1, 0.9]
    write_gps(tmp_path, enu + [5.0, 6.0, 0.0], [0, 2, 1], [2, 2, 0], [[0.04, 0.01, 0.09], [0.25, 0, 0.25], [0, 0, 0]],
              {"T_BS": {"cols": 4, "rows": 4, "data": T.ravel().tolist()}, "horizontal_sigma_m": 1.5,
               "datum": {"latitude": DATUM[0], "longitude": DATUM[1], "altitude": DATUM[2]}})
    rec = Recording(tmp_path)
    assert "gps0" in rec.streams()
    gps = read_fixes(rec)
    np.testing.assert_allclose(gps.enu, enu + [5.0, 6.0, 0.0], atol=1e-3)  # configured datum: not the first fix
    np.testing.assert_allclose(gps.covariance[0], [[0.04, 0.01], [0.01, 0.09]])
    np.testing.assert_allclose(gps.covariance[2], np.eye(2) * 1.5**2)  # covariance unknown: the default sigma
    np.testing.assert_allclose(gps.lever_arm, [-0.2, 0.1, 0.9])
    np.testing.assert_array_equal(gps.status, [0, 2, 1])
    np.testing.assert_allclose(gps.t, [1.0, 1.2, 1.4])
    assert gps.skipped == {} and gps.notes == []
    fix = gps.samples()[1]
    assert fix.t == pytest.approx(1.2) and fix.enu == pytest.approx([8.0, 10.0], abs=1e-3)
    np.testing.assert_allclose(fix.covariance, np.eye(2) * 0.25)


def test_no_fix_nan_and_zero_covariance_are_skipped_and_counted(tmp_path):
    enu = np.column_stack([np.arange(7.0), np.zeros(7), np.zeros(7)])
    cov = np.tile([0.04, 0.0, 0.04], (7, 1))
    cov[3] = 0.0                        # zero covariance
    cov[4] = [np.nan, 0.0, 0.04]        # NaN covariance
    write_gps(tmp_path, enu, [-1, 0, 0, 0, 0, 0, -1], [2] * 7, cov, {"horizontal_sigma_m": 2.0})
    text = (tmp_path / "gps0" / "data.csv").read_text().splitlines()
    fields = text[6].split(",")
    fields[1] = "nan"                   # NaN latitude on line 7 (the 6th fix)
    text[6] = ",".join(fields)
    (tmp_path / "gps0" / "data.csv").write_text("\n".join(text) + "\n")
    gps = read_fixes(Recording(tmp_path))
    assert gps.skipped == {"no fix": 2, "NaN": 2, "zero covariance": 1}
    assert len(gps) == 2
    np.testing.assert_allclose(gps.t, [1.2, 1.4])
    # the datum is the first usable fix, not the skipped first row
    np.testing.assert_allclose(gps.enu[:, 0], [0.0, 1.0], atol=1e-3)
    assert any("2 GPS fixes skipped (no fix; first on line 2)" in n for n in gps.notes)
    assert any("datum (ENU origin) at the first fix" in n for n in gps.notes)


def test_missing_sensor_yaml_uses_the_documented_defaults_and_says_so(tmp_path):
    write_gps(tmp_path, [[0, 0, 0], [1, 1, 0]], [0, 0], [0, 0], np.zeros((2, 3)), None)
    gps = read_fixes(Recording(tmp_path))
    assert gps.horizontal_sigma == DEFAULT_HORIZONTAL_SIGMA
    np.testing.assert_allclose(gps.covariance[1], np.eye(2) * DEFAULT_HORIZONTAL_SIGMA**2)
    np.testing.assert_allclose(gps.lever_arm, 0.0)
    assert any("sensor.yaml not found" in n and "antenna at the body origin" in n for n in gps.notes)


def test_six_column_files_of_older_imports_are_read(tmp_path):
    (tmp_path / "gps0").mkdir()
    (tmp_path / "gps0" / "data.csv").write_text(
        "#timestamp [ns],latitude [deg],longitude [deg],altitude [m],e [m],n [m],u [m]\n"
        f"100,{DATUM[0]},{DATUM[1]},{DATUM[2]},0,0,0\n200,{DATUM[0] + 1e-5},{DATUM[1]},{DATUM[2]},0,1.11,0\n")
    gps = read_fixes(Recording(tmp_path))
    assert gps.enu[1, 1] == pytest.approx(1.112, abs=0.01)


@pytest.mark.parametrize("yaml_data, message", [
    ({"horizontal_sigma_m": "wide"}, "horizontal_sigma_m: expected a number, got 'wide'"),
    ({"horizontal_sigma_m": 0}, "horizontal_sigma_m must be positive, not 0"),
    ({"datum": [1, 2]}, r"datum: expected a mapping of key: value, got \[1, 2\]"),
    ({"T_BS": [1, 2, 3]}, r"T_BS must be a 4x4 matrix \(cols: 4, rows: 4, data: \[16 numbers\]\)"),
])
def test_bad_sensor_yaml_names_the_file_and_key(tmp_path, yaml_data, message):
    write_gps(tmp_path, [[0, 0, 0]], [0], [0], np.zeros((1, 3)), yaml_data)
    with pytest.raises(InputError, match=message) as err:
        read_fixes(Recording(tmp_path))
    assert err.value.path == tmp_path / "gps0" / "sensor.yaml"


def test_every_fix_unusable_is_an_error_naming_the_file(tmp_path):
    write_gps(tmp_path, [[0, 0, 0], [1, 0, 0]], [-1, -1], [0, 0], np.zeros((2, 3)), {})
    with pytest.raises(InputError, match="no usable GPS fix") as err:
        read_fixes(Recording(tmp_path))
    assert err.value.path == tmp_path / "gps0" / "data.csv"


def test_malformed_row_names_the_line(tmp_path):
    write_gps(tmp_path, [[0, 0, 0], [1, 0, 0]], [0, 0], [0, 0], np.zeros((2, 3)), {})
    p = tmp_path / "gps0" / "data.csv"
    p.write_text(p.read_text() + "1600000000,abc,8,400,0,0,0,0,0,0,0,0\n")
    with pytest.raises(InputError, match="'abc' is not a number") as err:
        read_fixes(Recording(tmp_path))
    assert err.value.line == 4
