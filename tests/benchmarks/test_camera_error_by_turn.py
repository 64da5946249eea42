"""``benchmarks/camera_error_by_turn.py``: the heading errors' statistics per band of turn."""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from camera_error_by_turn import parse_options, turn_bands  # noqa: E402


def test_turn_bands_separate_frame_errors_from_a_bias_that_persists():
    """Straight: pure frame errors (lag 1 -0.5, RMS √2 σ). Turning by ±0.02 rad: a bias of 3 units along the
    turn that changes sign with it, plus white noise, so its lag 1 is positive (same turn direction
    for runs of 50 increments)."""
    rng = np.random.default_rng(1)
    n = 20000
    straight = np.arange(n) < n // 2
    sign = np.where((np.arange(n) // 50) % 2 == 0, 1.0, -1.0)
    turns = np.where(straight, 0.0, 0.02 * sign)
    frame = rng.normal(size=n + 1)
    errors = np.where(straight, frame[1:] - frame[:-1], 3.0 * sign + rng.normal(size=n))
    chained = np.ones(n, bool)
    chained[0] = False
    rows = {(lo, hi): (count, rms, mean, lag) for lo, hi, count, rms, mean, lag in turn_bands(errors, turns, chained)}
    count, rms, mean, lag = rows[(0.0, 0.002)]
    assert count == n // 2 and abs(rms - np.sqrt(2.0)) < 0.05 and abs(mean) < 0.05 and abs(lag + 0.5) < 0.03
    count, rms, mean, lag = rows[(0.015, 0.03)]
    assert count == n // 2 and abs(mean - 3.0) < 0.05 and abs(rms - np.sqrt(10.0)) < 0.05 and lag > 0.8
    assert rows[(0.002, 0.008)][0] == 0 and np.isnan(rows[(0.002, 0.008)][3])  # an empty band says so


def test_parse_options():
    assert parse_options("warp_tolerance=0.005,border=12") == {"warp_tolerance": 0.005, "border": 12}
    assert parse_options(None) == {}
