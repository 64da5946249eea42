"""Camera height and wheel radius both uncertain: their priors decide who owns the common scale."""

import dataclasses

import pytest
from backend_synth import streams_of

from fusion_vo.backends import fuse
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams
from fusion_vo.sensors.wheel import read_ticks


@pytest.fixture(scope="module")
def drive():
    return synthetic_streams(SyntheticOptions(duration=20.0), seed=21)


def _with_radius_error(s, error, radius_sigma, height_sigma):
    """Streams whose wheel0 calibration states radii ``1 + error`` times the true ones."""
    cfg = s.wheel.config
    cfg = dataclasses.replace(cfg, wheel_radius_left=cfg.wheel_radius_left * (1 + error),
                              wheel_radius_right=cfg.wheel_radius_right * (1 + error), radius_sigma=radius_sigma)
    streams = streams_of(s).select(["camera", "wheel", "imu"])
    streams.wheel = dataclasses.replace(streams.wheel, config=cfg)
    streams.camera_height_sigma = height_sigma
    return streams


def _scales(drive, backend, radius_sigma, height_sigma):
    """(visual scale, wheel scale) estimated with correct radii and with radii stated 0.5 % too large."""
    out = []
    for error in (0.0, 0.005):
        cal = fuse(_with_radius_error(drive, error, radius_sigma, height_sigma), backend).calibration[backend]
        out.append((cal["visual_scale"], cal["wheel_scale"]))
    return out


@pytest.mark.parametrize("backend", ["ekf", "gtsam"])
def test_well_known_height_lets_the_camera_set_the_scale(drive, backend):
    # height known to 0.1 mm (0.1 %), radii to 0.5 mm (1 %): the radius error goes to the wheels
    (kv0, kr0), (kv1, kr1) = _scales(drive, backend, 0.0005, 1e-4)
    assert kv1 == pytest.approx(1.0, abs=2e-4)
    assert kv1 - kv0 == pytest.approx(0.0, abs=2e-4)
    assert kr1 - kr0 == pytest.approx(0.005, abs=0.0015)


@pytest.mark.parametrize("backend", ["ekf", "gtsam"])
def test_well_known_radii_let_the_wheels_set_the_scale(drive, backend):
    # the same data with the priors the other way round: the camera takes the disagreement
    (kv0, kr0), (kv1, kr1) = _scales(drive, backend, 1e-6, 0.005)
    assert kr1 - kr0 == pytest.approx(0.0, abs=2e-4)
    assert kv1 - kv0 == pytest.approx(-0.005, abs=0.0015)


@pytest.mark.parametrize("backend", ["ekf", "gtsam"])
def test_default_priors_keep_the_camera_height(drive, backend):
    # nothing states either uncertainty: the camera height (a mounting dimension, prior 0.2 %) keeps its
    # scale and the wheels (prior 2 %) take a 0.5 % radius error; the former defaults (5 % and 1 %) moved
    # the camera's scale by 96 % of it (-0.0048)
    (kv0, kr0), (kv1, kr1) = _scales(drive, backend, None, None)
    assert kv1 - kv0 == pytest.approx(0.0, abs=2e-4)
    assert kr1 - kr0 == pytest.approx(0.005, abs=0.0015)


def test_bad_sigma_in_sensor_yaml_names_the_key(tmp_path):
    from fusion_vo.errors import InputError
    from fusion_vo.recording.reader import Recording

    (tmp_path / "wheel0").mkdir()
    (tmp_path / "wheel0" / "data.csv").write_text("#timestamp [ns],left,right\n0,0,0\n50000000,10,10\n")
    (tmp_path / "wheel0" / "sensor.yaml").write_text(
        "{ticks_per_revolution: 4096, wheel_radius_left: 0.05, wheel_radius_right: 0.05, wheel_base: 0.3,"
        " radius_sigma: -0.001}\n")
    with pytest.raises(InputError, match="radius_sigma"):
        read_ticks(Recording(tmp_path))



def test_camera_height_uncertainty_grows_only_by_its_small_walk(drive):
    # a rigidly mounted camera keeps its height: the visual scale's default random walk is a tenth of the
    # wheels' (the wheels measure only the ratio of the two scales, so nothing else holds the camera's);
    # its sigma grows with the configured walk
    import math

    from fusion_vo.backends import FusionConfig

    streams = _with_radius_error(drive, 0.0, 0.0005, 1e-4)
    prior = 1e-4 / streams.camera_height
    duration = drive.truth.t[-1] - drive.truth.t[0]
    default = FusionConfig().ekf.visual_scale_random_walk
    assert default <= 0.1 * FusionConfig().ekf.scale_random_walk
    sigmas = []
    for walk in (None, 1e-3):
        config = FusionConfig()
        if walk is not None:
            config = config.merged({"ekf": {"visual_scale_random_walk": walk}})
        sigmas.append(fuse(streams, "ekf", config).calibration["ekf"]["visual_scale_sigma"])
    assert sigmas[0] <= math.sqrt(prior**2 + default**2 * duration) * 1.0001
    assert sigmas[0] <= 1.001 * prior
    assert sigmas[1] > 2 * prior
    assert sigmas[1] <= math.sqrt(prior**2 + 1e-3**2 * duration) * 1.0001
