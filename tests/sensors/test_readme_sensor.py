"""The compass of docs/adding-a-sensor.md runs as written and its offset is estimated."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from fusion_vo.geometry import se2
from fusion_vo.sensors import registry
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams

PAGE = Path(__file__).resolve().parents[2] / "docs" / "adding-a-sensor.md"


def page_example() -> str:
    """The first Python block of the page's "A compass, complete" section."""
    text = PAGE.read_text()
    section = text[text.index("## A compass, complete"):]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def test_the_documented_sensor_example_runs_and_estimates_its_offset(capsys):
    s = synthetic_streams(SyntheticOptions(duration=20.0), seed=4)
    rng = np.random.default_rng(3)
    t = np.arange(s.truth.t[0], s.truth.t[-1], 0.1)
    yaw = se2.wrap_angle(np.interp(t, s.truth.t, np.unwrap(s.truth.xyyaw[:, 2])) + 0.2 + rng.normal(0, 0.02, len(t)))
    code = page_example()
    assert "register(Sensor(" in code and "State(" in code
    space = {"wheels": s.wheel, "imu": s.imu, "t": t, "yaw": yaw}
    try:
        exec(compile(code, str(PAGE), "exec", dont_inherit=True), space)  # (as a script: no __future__ of this module)
    finally:
        registry.unregister("compass")
    printed = float(capsys.readouterr().out.strip())
    result = space["result"]
    for name in ("ekf", "ekf_smoothed", "gtsam", "gtsam_online"):
        # measured: 0.1943 (EKF, σ 0.0032) to 0.1949 (GTSAM batch) against the true 0.2
        assert abs(result.calibration[name]["compass_offset"] - 0.2) < 0.01, (name, result.calibration[name])
        assert result.counts[name]["compass"].used >= 300, (name, result.counts[name])
    assert printed == result.calibration["gtsam"]["compass_offset"]
    assert "compass" not in registry.names()
