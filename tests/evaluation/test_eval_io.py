"""Readers and writers of fusion_vo.evaluation.io: good files parse, bad rows name file and line."""

import json

import numpy as np
import pytest

from fusion_vo.errors import InputError
from fusion_vo.evaluation import io


def test_tum_roundtrip_of_values(tmp_path):
    path = tmp_path / "vo.tum"
    path.write_text("# t x y z qx qy qz qw\n1.0 0 0 0 0 0 0 1\n\n1.5 1 2 0 0 0 0.7071068 0.7071068\n")
    traj = io.read_tum(path)
    assert traj.name == "vo"
    np.testing.assert_allclose(traj.timestamps, [1.0, 1.5])
    np.testing.assert_allclose(traj.positions_xyz[1], [1, 2, 0])
    np.testing.assert_allclose(traj.orientations_quat_wxyz[1], [0.7071068, 0, 0, 0.7071068], atol=1e-7)


@pytest.mark.parametrize("text, line, message", [
    ("1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 1\n", 2, "expected 8 columns"),
    ("1.0 0 0 0 0 0 0 1\n2.0 0 x 0 0 0 0 1\n", 2, "expected numbers"),
    ("1.0 0 0 0 0 0 0 1\n2.0 0 nan 0 0 0 0 1\n", 2, "non-finite"),
    ("1.0 0 0 0 0 0 0 0\n", 1, "norm 0.000, not 1"),
    ("1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 2e-6 0\n", 2, "norm 0.000, not 1"),  # not turned into 180 degrees
    ("1.0 0 0 0 0 0 0 1.2\n", 1, "norm 1.200, not 1"),
    ("2.0 0 0 0 0 0 0 1\n1.0 0 0 0 0 0 0 1\n", 2, "earlier than the one before"),
])
def test_malformed_tum_rows_are_located(tmp_path, text, line, message):
    path = tmp_path / "ekf.tum"
    path.write_text(text)
    with pytest.raises(InputError, match=message) as info:
        io.read_tum(path)
    assert info.value.path == path and info.value.line == line


def test_repeated_timestamp_keeps_the_last_pose(tmp_path):
    path = tmp_path / "ekf.tum"
    path.write_text("1.0 0 0 0 0 0 0 1\n1.0 5 0 0 0 0 0 1\n2.0 6 0 0 0 0 0 1\n")
    traj = io.read_tum(path)
    np.testing.assert_allclose(traj.positions_xyz[:, 0], [5, 6])


def test_missing_and_empty_tum(tmp_path):
    with pytest.raises(InputError, match="not found"):
        io.read_tum(tmp_path / "none.tum")
    (tmp_path / "empty.tum").write_text("# nothing\n")
    with pytest.raises(InputError, match="no poses"):
        io.read_tum(tmp_path / "empty.tum")


def test_groundtruth_in_nanoseconds_with_extra_columns(tmp_path):
    path = tmp_path / "state_groundtruth_estimate0" / "data.csv"
    path.parent.mkdir()
    path.write_text("#timestamp [ns],p_x,p_y,p_z,q_w,q_x,q_y,q_z,v_x\n"
                    "1403636579758555392,1,2,3,1,0,0,0,9\n1403636579763555584,1,2,3,0,0,0,1,9\n")
    traj = io.read_groundtruth(tmp_path)  # the recording folder works too
    np.testing.assert_allclose(traj.timestamps - traj.timestamps[0], [0.0, 0.005], atol=1e-6)
    np.testing.assert_allclose(traj.orientations_quat_wxyz[1], [0, 0, 0, 1])
    path.write_text("#timestamp\n1,1,2,3,1,0,0,0\n2,1,2,3,1,0,0\n")
    with pytest.raises(InputError, match="expected a timestamp and 7 pose values") as info:
        io.read_groundtruth(path)
    assert info.value.line == 3


def test_velocities_csv(tmp_path):
    path = tmp_path / "velocities.csv"
    path.write_text("t,vx,vy,yaw_rate,status,inliers\n0.0,,,,first,0\n0.05,0.2,0.0,0.1,ok,57\n"
                    "0.1,nan,nan,nan,too_few_features,3\n")
    frames = io.read_velocities(path)
    assert frames.status == ["first", "ok", "too_few_features"]
    assert frames.ok.tolist() == [False, True, False]
    assert frames.inliers.tolist() == [0, 57, 3]
    assert frames.vx[1] == pytest.approx(0.2)
    path.write_text("t,vx,vy,yaw_rate,status,inliers\n0.0,0,0,0,lost,0\n")
    with pytest.raises(InputError, match="unknown status") as info:
        io.read_velocities(path)
    assert info.value.line == 2


def test_find_trajectories_orders_known_names_first(tmp_path):
    for name in ("zeta", "gtsam", "vo", "ekf"):
        (tmp_path / f"{name}.tum").write_text("")
    assert list(io.find_trajectories(tmp_path)) == ["vo", "ekf", "gtsam", "zeta"]
    with pytest.raises(InputError, match="run folder not found"):
        io.find_trajectories(tmp_path / "missing")
    (tmp_path / "sub").mkdir()
    with pytest.raises(InputError, match="no trajectories"):
        io.find_trajectories(tmp_path / "sub")


def test_metrics_json_is_valid_with_nan(tmp_path):
    path = io.write_metrics(tmp_path / "metrics.json", {"vo": {"ate_m": np.float64(0.5), "heading_per_rev_deg":
                                                                float("nan"), "poses": np.int64(3)}})
    assert json.loads(path.read_text()) == {"vo": {"ate_m": 0.5, "heading_per_rev_deg": None, "poses": 3}}
    assert [p.name for p in tmp_path.iterdir()] == ["metrics.json"]  # no temporary left behind
