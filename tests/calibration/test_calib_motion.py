"""Height, lever arm and wheel calibration on generated recordings with known true values."""

from __future__ import annotations

import numpy as np
import pytest

from fusion_vo.calibration.height import height_from_drive
from fusion_vo.calibration.lever_arm import fixed_point, lever_arm_from_turn
from fusion_vo.calibration.motion import frame_motions
from fusion_vo.calibration.wheels import umbmark, wheels_from_groundtruth
from fusion_vo.cli.main import main
from fusion_vo.config.files import load_yaml
from fusion_vo.errors import InputError
from fusion_vo.recording import Recording
from fusion_vo.sensors.wheel import read_ticks
from fusion_vo.simulation import simulate

#: a small camera seeing few frames: the wheel tests only need the encoders and the ground truth
NO_CAMERA = dict(width=80, height=48, fu=60.0, fv=60.0, cu=39.5, cv=23.5, camera_rate=0.2, supersample=1,
                 imu_rate=20.0, gt_rate=50.0)
WHEEL_ERRORS = dict(slip=0.0, radius_error_left=0.003, radius_error_right=-0.003, base_error=0.015, side=1.0)


def test_lever_arm_from_turn(tmp_path):
    seq = simulate(tmp_path / "turn", profile="turn_in_place", seed=3, angle=0.8, lateral_offset=0.03,
                   tilt_x_deg=2.0)
    motions, geometry = frame_motions(Recording(seq))
    r = lever_arm_from_turn([m.matrix for m in motions if m.ok], geometry)
    assert abs(r.lever_arm[0] - 0.25) < 0.005 and abs(r.lever_arm[1] - 0.03) < 0.005
    assert np.all(r.std > 0) and np.all(r.std < 0.005)
    assert r.turned_deg == pytest.approx(np.degrees(0.8), abs=2.0)
    # the CLI writes the lever arm into the camera file
    out = tmp_path / "sensor.yaml"
    assert main(["calibrate", "lever-arm", str(seq), "--out", str(out)]) == 0
    T = np.asarray(load_yaml(out)["T_BS"]["data"]).reshape(4, 4)
    assert np.allclose(T[:2, 3], [0.25, 0.03], atol=0.005)


def test_fixed_point_rejects_outliers():
    rng = np.random.default_rng(0)
    p = np.array([300.0, 1200.0])
    mats = []
    for k in range(40):
        a = rng.uniform(0.02, 0.05)
        R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        t = p - R @ p + rng.normal(0, 0.05, 2)
        if k % 10 == 0:
            t += 25.0  # a bad frame
        mats.append(np.column_stack([R, t]))
    fp = fixed_point(mats)
    assert np.linalg.norm(fp.point - p) < 3.0
    assert fp.inliers.sum() == 36
    with pytest.raises(InputError, match="turn in place"):
        fixed_point([np.column_stack([np.eye(2), [1.0, 0.0]])] * 10)


def test_height_from_straight_drive(tmp_path):
    seq = simulate(tmp_path / "straight", profile="straight", seed=3, length=0.3, camera_height=0.11)
    motions, geometry = frame_motions(Recording(seq))
    r = height_from_drive(motions, geometry.rectifier.f, geometry.rectifier.c, 0.3, 0.0005)
    assert abs(r.height - 0.11) < 0.001
    assert 0 < r.height_std < 0.001
    with pytest.raises(SystemExit) as exc:  # a usage error naming --distance
        main(["calibrate", "height", str(seq), "--distance", "-1"])
    assert exc.value.code == 2


@pytest.fixture(scope="module")
def squares(tmp_path_factory):
    folder = tmp_path_factory.mktemp("umbmark")
    cw = simulate(folder / "cw", profile="umbmark_cw", seed=1, **NO_CAMERA, **WHEEL_ERRORS)
    ccw = simulate(folder / "ccw", profile="umbmark_ccw", seed=2, **NO_CAMERA, **WHEEL_ERRORS)
    truth = load_yaml(cw / "simulation.yaml")["truth"]
    return Recording(cw), Recording(ccw), truth


def _assert_recovered(config, truth, tol=0.002):
    for key in ("wheel_radius_left", "wheel_radius_right", "wheel_base"):
        assert abs(getattr(config, key) / truth[key] - 1) < tol, key


def test_wheels_from_groundtruth(squares):
    cw, _, truth = squares
    r = wheels_from_groundtruth(read_ticks(cw), cw.groundtruth())
    _assert_recovered(r.config, truth)
    assert abs(r.config.wheel_base / 0.3 - 1) > 0.01  # the nominal value was off and has moved


def test_umbmark(squares, tmp_path):
    cw, ccw, truth = squares
    r = umbmark((read_ticks(cw), cw.groundtruth()), (read_ticks(ccw), ccw.groundtruth()))
    _assert_recovered(r.config, truth)
    assert r.details["Ed"] == pytest.approx(truth["wheel_radius_right"] / truth["wheel_radius_left"], rel=0.002)
    out = tmp_path / "wheel.yaml"
    assert main(["calibrate", "wheels", str(cw.path), "--method", "umbmark", "--ccw", str(ccw.path),
                 "--out", str(out)]) == 0
    written = load_yaml(out)
    assert written["ticks_per_revolution"] == 4096
    assert written["wheel_base"] == pytest.approx(truth["wheel_base"], rel=0.002)


def test_umbmark_needs_second_run(squares, capsys):
    cw, _, _ = squares
    assert main(["calibrate", "wheels", str(cw.path), "--method", "umbmark"]) == 2
    assert "--ccw" in capsys.readouterr().err
