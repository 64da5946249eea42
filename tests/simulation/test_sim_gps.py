"""The simulator's GPS option: gps0/ with noise, lever arm, outages and jumps, in ENU at the datum."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from fusion_vo.recording import Recording
from fusion_vo.sensors import gps as gps_model
from fusion_vo.sensors.gps import has_fixes, read_fixes
from fusion_vo.simulation import SimulationOptions
from fusion_vo.simulation.standard import STANDARD

OPTIONS = {"duration": 30.0, "gps": True, "gps_rate": 5.0, "gps_noise": 0.05, "gps_lever_arm": [-0.3, 0.2, 0.5],
           "gps_outages": [[10.0, 15.0]], "gps_jumps": [[20.0, 20.8, 12.0, 16.0]], "gps_heading_deg": 40.0,
           "gps_origin": [5.0, -3.0], "camera_rate": 2.0}


@pytest.fixture(scope="module")
def rec(generate):
    return Recording(generate("gps", "random", 21, **OPTIONS))


def test_fixes_are_the_antenna_in_enu_with_the_stated_noise(rec):
    gps = read_fixes(rec)
    gt = rec.groundtruth()
    np.testing.assert_allclose(gps.lever_arm, [-0.3, 0.2, 0.5])
    assert gps.horizontal_sigma == 0.05 and gps.skipped == {}
    np.testing.assert_allclose(gps.covariance[0], np.eye(2) * 0.05**2)
    truth = gps_model.Alignment(math.radians(40.0), np.array([5.0, -3.0]), 0.0, 0).apply(gt.xyyaw)
    expected = gps_model.predict(gps_model.interpolate_poses(gt.t, truth, gps.t), gps.lever_arm)
    err = gps.enu[:, :2] - expected
    t = gps.t - 1.6e9
    clean = ~((t > 19.9) & (t < 20.9))
    assert np.std(err[clean], axis=0) == pytest.approx([0.05, 0.05], rel=0.2)
    assert np.all(np.abs(np.mean(err[clean], axis=0)) < 0.015)
    np.testing.assert_allclose(np.mean(err[~clean], axis=0), [12.0, 16.0], atol=0.1)
    assert np.count_nonzero(~clean) == 5


def test_outage_leaves_no_fix_and_the_rate_holds_elsewhere(rec):
    t = read_fixes(rec).t - 1.6e9
    assert not np.any((t >= 10.0) & (t <= 15.0))
    gaps = np.diff(t)
    assert np.max(gaps) == pytest.approx(5.4, abs=1e-5)  # 9.8 s -> 15.2 s: both ends are inside
    assert np.median(gaps) == pytest.approx(0.2, abs=1e-5)


def test_alignment_helper_recovers_the_world_heading_from_the_fixes(rec):
    gps = read_fixes(rec)
    gt = rec.groundtruth()
    fit = gps_model.align_to_fixes(gt.t, gt.xyyaw, gps, t_end=gt.t[0] + 19.0)  # before the jump
    assert fit is not None and fit.n == 70
    assert math.degrees(fit.yaw_sigma) < 1.0
    assert abs(fit.yaw - math.radians(40.0)) < 3 * fit.yaw_sigma
    np.testing.assert_allclose(fit.offset, [5.0, -3.0], atol=0.1)
    assert fit.n_outliers == 0 and fit.rms == pytest.approx(0.05 * math.sqrt(2), rel=0.25)
    # over the whole drive the 5 jumped fixes are discarded and the heading still holds
    full = gps_model.align_to_fixes(gt.t, gt.xyyaw, gps)
    assert full.n_outliers == 5 and abs(full.yaw - math.radians(40.0)) < 3 * full.yaw_sigma
    assert full.rms == pytest.approx(0.05 * math.sqrt(2), rel=0.25)


def test_truth_and_sensor_yaml(rec):
    sim = yaml.safe_load((rec.path / "simulation.yaml").read_text())
    assert sim["truth"]["gps_world_heading_deg"] == 40.0 and sim["truth"]["gps_jumped_fixes"] == 5
    meta = yaml.safe_load((rec.path / "gps0" / "sensor.yaml").read_text())
    assert meta["datum"]["latitude"] == pytest.approx(47.3977)


def test_without_the_option_no_gps_is_written(generate):
    assert not has_fixes(Recording(generate("short", "random", 0, duration=2.0)))


@pytest.mark.parametrize("options", [{"gps_outages": [[5.0]]}, {"gps_jumps": [[3.0, 2.0, 1.0, 1.0]]},
                                     {"gps_noise": 0.0}, {"gps_datum": [95.0, 0.0, 0.0]}])
def test_bad_gps_options_are_refused(options):
    with pytest.raises(ValueError, match="gps_"):
        SimulationOptions(**options)


def test_standard_recording_has_a_10_s_outage_and_a_20_m_jump():
    profile, _, options, _ = STANDARD["gps_outage"]
    (t0, t1), = options["gps_outages"]
    (_, _, de, dn), = options["gps_jumps"]
    assert profile == "random" and t1 - t0 == 10.0 and math.hypot(de, dn) == 20.0
    SimulationOptions(**options)
