"""The sensor measurement models: Jacobians against finite differences, vectorised rows equal single ones."""

import numpy as np
import pytest

from fusion_vo.sensors.imu import AHRS, GYRO
from fusion_vo.sensors.model import ARGUMENT_SIZES, Gate
from fusion_vo.sensors import registry
from fusion_vo.sensors.range import RANGE
from fusion_vo.sensors.visual import VISUAL
from fusion_vo.sensors.wheel import CURVED_WHEEL, STANDSTILL, WHEEL

ARGS = {"motion": np.array([0.12, -0.03, 0.4]), "heading": np.array([2.9]), "gyro_bias": np.array([0.013]),
        "visual_scale": np.array([1.04]), "wheel_scale": np.array([0.97]), "wheel_base_factor": np.array([1.1]),
        "ahrs_offset": np.array([-0.2]), "wheel_curvature": np.array([0.035])}
SIZES = {**ARGUMENT_SIZES, **{state.name: 1 for state in registry.all_states()}}
CASES = [(VISUAL, {}), (WHEEL, {}), (STANDSTILL, {}), (GYRO, {"dt": 0.05}), (AHRS, {}), (RANGE, {"camera_height": 0.3}),
         (CURVED_WHEEL, {"wheel_base": 0.3})]


@pytest.mark.parametrize("model,params", CASES, ids=[type(m).__name__ for m, _ in CASES])
def test_jacobians_match_finite_differences(model, params):
    args = {n: ARGS[n] for n in model.args}
    h, jac = model.evaluate(**args, **params)
    assert h.shape == (model.dim,) and set(jac) == set(model.args)
    for name in model.args:
        num = np.zeros((model.dim, SIZES[name]))
        for i in range(SIZES[name]):
            up, down = dict(args), dict(args)
            step = np.zeros(SIZES[name])
            step[i] = 1e-7
            up[name], down[name] = args[name] + step, args[name] - step
            num[:, i] = (model.evaluate(**up, **params)[0] - model.evaluate(**down, **params)[0]) / 2e-7
        np.testing.assert_allclose(jac[name], num, atol=1e-7, err_msg=f"{model.name} d/d{name}")


@pytest.mark.parametrize("model,params", CASES, ids=[type(m).__name__ for m, _ in CASES])
def test_rows_evaluated_together_equal_one_at_a_time(model, params):
    rng = np.random.default_rng(3)
    rows = [{n: ARGS[n] + 0.1 * rng.standard_normal(SIZES[n]) for n in model.args} for _ in range(4)]
    stacked = {n: np.array([r[n] for r in rows]) for n in model.args}
    h, jac = model.evaluate(**stacked, **params)
    for i, r in enumerate(rows):
        hi, ji = model.evaluate(**r, **params)
        np.testing.assert_allclose(h[i], hi, rtol=1e-15)
        for n in model.args:
            np.testing.assert_allclose(jac[n][i], ji[n], rtol=1e-15)


def test_predictions_are_the_documented_ones():
    m, k = ARGS["motion"], 1.04
    np.testing.assert_allclose(VISUAL.evaluate(m, [k])[0], [k * m[0], k * m[1], m[2]])
    np.testing.assert_allclose(WHEEL.evaluate(m, [0.97], [1.1])[0], [0.97 * m[0], 0.97 * m[1], 1.1 * m[2]])
    np.testing.assert_allclose(GYRO.evaluate(m, [0.013], dt=0.05)[0], [m[2] + 0.013 * 0.05])
    np.testing.assert_allclose(AHRS.evaluate([2.9], [-0.2])[0], [2.7])
    np.testing.assert_allclose(RANGE.evaluate([1.04], camera_height=0.3)[0], [0.3 / 1.04])
    # the residual wraps a heading (AHRS) and a turn over an interval (gyro) across ±π
    r, _ = AHRS.residual([-3.1], heading=[3.1], ahrs_offset=[0.0])
    np.testing.assert_allclose(r, [6.2 - 2 * np.pi])
    r, _ = GYRO.residual([3.1], motion=[0, 0, -3.1], gyro_bias=[0.0], dt=0.1)
    np.testing.assert_allclose(r, [2 * np.pi - 6.2])


def test_range_scale_prior_has_the_models_information_at_its_solution():
    z, sigma, hc = 0.31, 0.003, 0.3
    k, sk = RANGE.scale_prior(z, sigma, hc)
    h, jac = RANGE.evaluate([k], camera_height=hc)
    assert np.isclose(h[0], z)
    assert np.isclose(1.0 / sk**2, jac["visual_scale"][0, 0] ** 2 / sigma**2)


def test_gate():
    gate = Gate(0.999, 25.0)
    t = gate.threshold(2)
    assert np.isclose(t, 13.815510557964274)
    assert gate.inflation(0.5 * t, 2) == 1.0
    assert np.isclose(gate.inflation(4.0 * t, 2), 4.0)
    assert gate.inflation(30.0 * t, 2) is None and gate.inflation(np.nan, 2) is None
    assert Gate(1.0).inflation(1e12, 3) == 1.0


def test_range_reading_sigma_from_the_readings():
    """The noise of a range finder's readings is measured from their second differences, not from the slow
    vibration of the height they follow; gated spikes do not count."""
    from fusion_vo.measurements import RangeData
    from fusion_vo.sensors.range import reading_sigma

    rng = np.random.default_rng(7)
    t = np.arange(0.0, 20.0, 1 / 40)
    height = 0.1 + 0.001 * np.sin(2 * np.pi * 3.0 * t)  # 1 mm at 3 Hz, sampled at 40 Hz
    for sigma in (2e-4, 5e-4, 2e-3):
        z = height + rng.normal(0.0, sigma, len(t))
        z[100] += 0.05  # a spike
        assert reading_sigma(RangeData(t, z)) == pytest.approx(sigma, rel=0.12)
    assert reading_sigma(RangeData(t[:5], height[:5])) is None
