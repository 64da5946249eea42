"""The terminal tables keep sub-millimetre errors readable: a metre column switches to millimetres."""

import io

from rich.console import Console

from fusion_vo.evaluation.table import POSE_COLUMNS, VELOCITY_COLUMNS, metrics_table


def render(metrics, columns):
    out = io.StringIO()
    Console(file=out, width=200, color_system=None).print(metrics_table(metrics, "t", columns=columns))
    return out.getvalue()


def test_sub_centimetre_column_is_in_millimetres():
    metrics = {"vo": {"ate_m": 7.9e-5, "ate_anchored_m": 1.58e-4, "end_m": 1.94e-4, "heading_deg": 0.01},
               "wheel": {"ate_m": 0.035828, "ate_anchored_m": 0.076, "end_m": 0.128418, "heading_deg": 11.82}}
    text = render(metrics, POSE_COLUMNS)
    assert "ATE mm" in text and "ATE0 mm" in text and "end mm" in text
    assert "0.079" in text and "35.828" in text and "128.418" in text
    assert "0.0001" not in text
    assert "head. deg" in text and "11.82" in text  # angles untouched


def test_metre_scale_column_stays_in_metres():
    metrics = {"ekf": {"ate_m": 2.525, "ate_anchored_m": 3.1, "end_m": 4.0},
               "wheel": {"ate_m": 6.86, "ate_anchored_m": 9.0, "end_m": float("nan")}}
    text = render(metrics, POSE_COLUMNS)
    assert "ATE m " in text and "mm" not in text
    assert "2.5250" in text and "6.8600" in text and "\u2013" in text


def test_speed_column_in_millimetres_per_second():
    metrics = {"vo": {"vx_rmse_m_s": 8.1e-5, "vy_rmse_m_s": 1.02e-4, "yaw_rate_rmse_deg_s": 0.01}}
    text = render(metrics, VELOCITY_COLUMNS)
    assert "vx mm/s" in text and "0.081" in text and "0.102" in text
    assert "velocity errors are" in text
