"""Fused tracks against the best single sensor on the standard 'short' recording (5 s random drive).

Each fused track's ATE is at most visual odometry's (the better single sensor there), and the fused leg
lengths follow visual odometry's within 0.02 percentage points. Before the generated gyro stopped leading
the heading by 0.5 ms, the smoothed EKF scored 0.0305 mm against visual odometry's 0.0303.
"""

import json

import pytest

from fusion_vo.config import RunConfig
from fusion_vo.pipeline import run_pipeline

FUSED = ("ekf", "ekf_smoothed", "gtsam", "gtsam_online")
#: the recording and the run both tests read, made ahead in the background (tests/background.py)
BACKGROUND_COMMANDS = {"short_all": ["-q", "run", "{standard:short}", "--out", "{out}", "--backend", "all"]}
BACKGROUND_JOBS = {"*": ["standard:short", "fusion-vo:short_all"]}


@pytest.fixture(scope="module")
def short_metrics(standard_recording, ahead, tmp_path_factory):
    """``fusion-vo run short --backend all``: its metrics.json."""

    def here():
        out = tmp_path_factory.mktemp("short_run") / "run"
        run_pipeline(standard_recording("short"), out, RunConfig(backend="all"))
        return out

    return json.loads((ahead("fusion-vo:short_all", here) / "metrics.json").read_text())


def test_every_fused_track_is_at_most_the_best_single_sensor(short_metrics):
    m = short_metrics
    best = min(m["vo"]["ate_m"], m["wheel"]["ate_m"])
    assert best == m["vo"]["ate_m"]
    for name in FUSED:
        assert m[name]["ate_m"] <= best, (name, m[name]["ate_m"], best)


def test_fused_legs_follow_visual_odometry(short_metrics):
    vo = [leg["error_pct"] for leg in short_metrics["vo"]["legs"]]
    assert vo
    for name in FUSED:
        legs = [leg["error_pct"] for leg in short_metrics[name]["legs"]]
        assert len(legs) == len(vo)
        assert max(abs(a - b) for a, b in zip(legs, vo)) <= 0.02, name
