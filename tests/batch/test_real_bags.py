"""A batch over two real robot logs (robot_localization's Jackal and Husky bags, wheel odometry and IMU)."""

from pathlib import Path

import numpy as np

from fusion_vo.batch import run_batch
from fusion_vo.config import RunConfig
from fusion_vo.pipeline import run_pipeline
from fusion_vo.recording.rosbag import import_bag, parse_static_tf

DATA = Path(__file__).parents[1] / "data" / "robot_localization"
HUSKY_IMU = "0 -0.3 0.52 -1.570796327 0 1.570796327 base_link imu_link"  # robot_localization's launch file


def test_batch_of_real_bags_equals_single_runs(client, tmp_path):
    jackal = tmp_path / "jackal"
    husky = tmp_path / "husky"
    import_bag(DATA / "test2.bag", jackal)
    import_bag(DATA / "test1_140s_to_152s.bag", husky, static_tfs=[parse_static_tf(HUSKY_IMU)])
    config = RunConfig(backend="ekf")
    frame = run_batch([jackal, husky], config, client, out=tmp_path / "batch")
    assert list(frame.drop_duplicates("recording")["recording"]) == ["jackal", "husky"]
    assert (frame["status"] == "ok").all() and frame["ate_m"].isna().all()  # no ground truth in these logs
    for rec in (jackal, husky):
        single = run_pipeline(rec, tmp_path / "single" / rec.name, config)
        assert list(frame[frame["recording"] == rec.name]["trajectory"]) == single.trajectories
        for name in single.trajectories:
            batch_tum = np.loadtxt(tmp_path / "batch" / rec.name / f"{name}.tum")
            single_tum = np.loadtxt(tmp_path / "single" / rec.name / f"{name}.tum")
            # the same numbers up to rounding: a worker's BLAS has one thread, this process's may have more
            assert batch_tum.shape == single_tum.shape and len(batch_tum) > 100, (rec.name, name)
            np.testing.assert_allclose(batch_tum, single_tum, rtol=0, atol=1e-9, err_msg=f"{rec.name} {name}")
