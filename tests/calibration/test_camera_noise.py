"""The camera's heading noise measured against ground truth: its size by turn, each frame's own error."""

import dataclasses
import shutil

import numpy as np
import pytest
import yaml

from fusion_vo.calibration.camera_noise import EDGES, CameraNoise, measure
from fusion_vo.errors import InputError
from fusion_vo.measurements import VisualIncrement


def _errors(n: int, frame: float, sigma_by_band: tuple, seed: int = 0):
    """Heading errors ``e_k - e_{k-1} + w_k`` of ``n`` chained increments whose turns fall in the bands of
    :data:`EDGES` in turn (a few hundred each), ``w``'s deviation by band."""
    rng = np.random.default_rng(seed)
    mids = np.array([0.001, 0.005, 0.011, 0.02, 0.05])
    band = np.tile(np.repeat(np.arange(len(EDGES)), 200), n // (200 * len(EDGES)) + 1)[:n]
    turns = mids[band] * rng.choice([-1.0, 1.0], n)
    e = rng.normal(0.0, frame, n + 1)
    w = rng.normal(0.0, 1.0, n) * np.asarray(sigma_by_band)[band]
    chained = np.ones(n, bool)
    chained[0] = False
    return np.diff(e) + w, turns, chained


def test_measures_the_frame_error_and_each_bands_own_error():
    own = (2e-6, 8e-6, 14e-6, 10e-6, 12e-6)
    errors, turns, chained = _errors(40_000, 6e-6, own)
    noise = measure(errors, turns, chained, "klt")
    assert noise.frame_sigma == pytest.approx(6e-6, rel=0.1)
    total = np.sqrt(np.square(own) + 2 * 6e-6**2)  # an increment's whole error: its own and its two frames'
    np.testing.assert_allclose(noise.heading_sigma, total, rtol=0.08)


def test_errors_that_do_not_cancel_state_no_frame_error():
    rng = np.random.default_rng(1)
    n = 20_000
    errors = rng.normal(0.0, 1e-5, n)
    noise = measure(errors, np.full(n, 0.001), np.ones(n, bool), "klt")
    assert noise.frame_sigma < 1.5e-6
    assert noise.heading_sigma[0] == pytest.approx(1e-5, rel=0.05)


def test_errors_that_persist_get_the_variance_of_their_growth():
    """Errors correlated over many frames (a slow heading error) grow faster than their per-increment RMS
    says; the fit over runs of up to 32 increments gives them more than that RMS."""
    rng = np.random.default_rng(2)
    n = 40_000
    slow = np.convolve(rng.normal(0.0, 1.0, n + 9), np.ones(10) / np.sqrt(10), mode="valid")[:n] * 1e-5
    noise = measure(slow, np.full(n, 0.001), np.ones(n, bool), "klt")
    rms = float(np.sqrt(np.mean(slow**2)))
    assert noise.heading_sigma[0] > 1.5 * rms


def _increment(turn: float, cov=None):
    cov = np.diag([1e-10, 2e-10, 4e-10]) if cov is None else cov
    return VisualIncrement(0.0, 0.05, np.array([0.001, 0.0, turn]), cov)


def test_apply_sets_each_increments_heading_variance_by_its_turn_and_keeps_correlations():
    noise = CameraNoise("klt", EDGES, (10e-6, 20e-6, 30e-6, 40e-6, 50e-6), 5e-6, 100)
    cov = np.array([[1e-10, 0, -5e-11], [0, 1e-10, 0], [-5e-11, 0, 4e-10]])
    out = noise.apply([_increment(0.001, cov), _increment(-0.02, cov),
                       dataclasses.replace(_increment(0.0), status="lost")])
    assert out[0].covariance[2, 2] == pytest.approx((10e-6) ** 2)
    assert out[1].covariance[2, 2] == pytest.approx((40e-6) ** 2)
    corr = out[0].covariance[0, 2] / np.sqrt(out[0].covariance[0, 0] * out[0].covariance[2, 2])
    assert corr == pytest.approx(-5e-11 / np.sqrt(1e-10 * 4e-10))
    assert out[0].covariance[0, 0] == 1e-10  # the translation as the frontend stated it
    assert out[0].frame_covariance[2, 2] == pytest.approx((5e-6) ** 2)
    assert out[2].frame_covariance is None and out[2].status == "lost"


def test_the_model_reads_back_and_a_bad_value_names_its_key(tmp_path):
    noise = CameraNoise("klt", EDGES, (10e-6, 20e-6, 30e-6, 40e-6, 50e-6), 5e-6, 100)
    assert CameraNoise.from_dict(yaml.safe_load(yaml.safe_dump(noise.to_dict()))) == noise
    path = tmp_path / "sensor.yaml"
    for change, message in (({"frame_sigma": "x"}, "camera_noise.frame_sigma: expected a number, got 'x'"),
                            ({"heading_sigma": [1e-5, 2e-5]}, "camera_noise: heading_sigma needs one number per edge "
                                                              "(5), not 2"),
                            ({"edges": [0.01, 0.002, 0.008, 0.015, 0.03]}, "camera_noise: edges must rise from 0"),
                            ({"heading_sigma": [1e-5, float("nan"), 1e-5, 1e-5, 1e-5]},
                             "camera_noise.heading_sigma[1]: must be a finite number, not nan"),
                            ({"frame_sigma": 1e300}, "camera_noise: frame_sigma must be at most 10, not 1e+300"),
                            ({"frontend": 3}, "camera_noise.frontend: expected a string, got 3"),
                            ({"sigma": 1}, "camera_noise.sigma: unknown key (known: frontend, edges")):
        with pytest.raises(InputError) as info:
            CameraNoise.from_dict({**noise.to_dict(), **change}, path)
        assert str(info.value).startswith(f"{path}: {message}") and info.value.path == path
    with pytest.raises(InputError, match="missing key 'camera_noise.frame_sigma'"):
        CameraNoise.from_dict({k: v for k, v in noise.to_dict().items() if k != "frame_sigma"}, path)


@pytest.fixture(scope="module")
def drives(tmp_path_factory):
    """Two short generated drives of the same camera: one to calibrate on, one to run."""
    from fusion_vo.simulation import simulate

    root = tmp_path_factory.mktemp("camera_noise")
    small = {"width": 160, "height": 120, "fu": 200.0, "fv": 200.0, "cu": 79.5, "cv": 59.5, "supersample": 1,
             "duration": 3.0}
    return [simulate(root / f"drive{seed}", profile="random", seed=seed, **small) for seed in (21, 22)]


def test_calibrate_writes_the_model_into_sensor_yaml_and_a_run_of_that_frontend_uses_it(drives, tmp_path, capsys):
    from fusion_vo.cli.main import main

    calibration, drive = drives
    rec = shutil.copytree(drive, tmp_path / "rec")
    target = rec / "cam0" / "sensor.yaml"
    before = yaml.safe_load(target.read_text())
    assert main(["calibrate", "camera-noise", str(calibration), "--out", str(target)]) == 0
    assert "each frame's own heading error" in capsys.readouterr().out
    after = yaml.safe_load(target.read_text())
    assert {k: v for k, v in after.items() if k != "camera_noise"} == before  # the camera's own keys kept
    stated = CameraNoise.from_dict(after["camera_noise"])
    assert stated.frontend == "klt" and stated.increments > 50

    assert main(["-q", "run", str(rec), "--out", str(tmp_path / "run"), "--backend", "ekf", "--no-evaluate"]) == 0
    notes = yaml.safe_load((tmp_path / "run" / "summary.json").read_text())["notes"]
    assert any(n.startswith("camera heading noise of cam0/sensor.yaml (klt") for n in notes)
    assert main(["-q", "run", str(rec), "--out", str(tmp_path / "features"), "--backend", "ekf", "--no-evaluate",
                 "--frontend", "features"]) == 0
    notes = yaml.safe_load((tmp_path / "features" / "summary.json").read_text())["notes"]
    assert any("measured with the klt frontend, this run uses features" in n for n in notes)


def test_a_bad_camera_noise_in_sensor_yaml_stops_the_run_before_any_work(drives, tmp_path, capsys):
    from fusion_vo.cli.main import main

    rec = shutil.copytree(drives[1], tmp_path / "rec")
    target = rec / "cam0" / "sensor.yaml"
    data = yaml.safe_load(target.read_text())
    data["camera_noise"] = {"frontend": "klt", "edges": [0.0], "heading_sigma": [-1.0], "frame_sigma": 0.0}
    target.write_text(yaml.safe_dump(data))
    assert main(["run", str(rec), "--out", str(tmp_path / "run"), "--backend", "ekf", "--no-evaluate"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cam0/sensor.yaml" in err[0] and "camera_noise.heading_sigma" in err[0]
    assert not (tmp_path / "run").exists()


def test_calibrate_needs_ground_truth(drives, tmp_path, capsys):
    from fusion_vo.cli.main import main

    rec = shutil.copytree(drives[0], tmp_path / "rec")
    shutil.rmtree(rec / "state_groundtruth_estimate0")
    assert main(["calibrate", "camera-noise", str(rec)]) == 2
    assert "needs ground truth" in capsys.readouterr().err
