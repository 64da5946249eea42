"""The shared SE(2) / quaternion / geodetic helpers against their definitions."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fusion_vo.geometry import se2
from fusion_vo.recording.rosbag.transforms import quat_to_matrix, ypr_to_matrix
from fusion_vo.simulation.robot import integrate

angles = st.floats(-3.14, 3.14, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(th=st.one_of(angles, st.floats(-1e-3, 1e-3), st.just(1e-3), st.just(0.0), st.just(5e-324)))
def test_sinc_terms_match_their_definition(th):
    a, b = se2.sinc_terms(th)
    # the array path (numpy's sinc) and the scalar path (math) agree
    arr_a, arr_b = se2.sinc_terms(np.array([th, th]))
    assert arr_a[1] == pytest.approx(a, rel=1e-14, abs=1e-300) and arr_b[1] == pytest.approx(b, rel=1e-14, abs=1e-300)
    if abs(th) > 1e-3:
        assert a == pytest.approx(math.sin(th) / th, rel=1e-12)
        assert b == pytest.approx((1.0 - math.cos(th)) / th, rel=1e-9)
    else:  # the series, which the formula must reproduce without a cut-off
        assert a == pytest.approx(1.0 - th**2 / 6.0 + th**4 / 120.0, rel=1e-15, abs=1e-300)
        assert b == pytest.approx(th / 2.0 - th**3 / 24.0 + th**5 / 720.0, rel=1e-12, abs=1e-300)


@settings(max_examples=200, deadline=None)
@given(x=st.floats(-5, 5), y=st.floats(-5, 5), th=st.one_of(angles, st.floats(-1e-7, 1e-7)))
def test_exp_log_round_trip(x, y, th):
    p = np.array([x, y, th])
    assert se2.exp(se2.log(p)) == pytest.approx(p, abs=1e-9)


@settings(max_examples=100, deadline=None)
@given(yaw=angles, roll=st.floats(-0.3, 0.3), pitch=st.floats(-0.3, 0.3))
def test_quaternion_helpers_agree(yaw, roll, pitch):
    q = se2.quaternion_of_yaw([yaw])[0]
    assert se2.yaw_of_quaternion(q)[0] == pytest.approx(yaw, abs=1e-12)
    R = quat_to_matrix(*q)
    assert R == pytest.approx(ypr_to_matrix(yaw, 0.0, 0.0), abs=1e-12)
    # yaw of a tilted attitude is the ZYX yaw
    from scipy.spatial.transform import Rotation
    xyzw = Rotation.from_matrix(ypr_to_matrix(yaw, pitch, roll)).as_quat()
    assert se2.yaw_of_quaternion(xyzw[[3, 0, 1, 2]])[0] == pytest.approx(yaw, abs=1e-9)
    assert quat_to_matrix(*(3.0 * xyzw[[3, 0, 1, 2]])) == pytest.approx(ypr_to_matrix(yaw, pitch, roll), abs=1e-12)
    with pytest.raises(ValueError):
        quat_to_matrix(0.0, 0.0, 0.0, 0.0)


def test_arc_integration_is_a_circle():
    dt, v, w = 1e-3, 0.2, 0.5
    n = int(round(2 * math.pi / w / dt)) + 1
    poses = integrate(np.full(n, v), np.full(n, w), dt)
    radius = v / w
    centre = np.array([0.0, radius])
    assert np.linalg.norm(poses[:, :2] - centre, axis=1) == pytest.approx(np.full(n, radius), abs=1e-12)
    straight = integrate(np.full(11, 0.3), np.zeros(11), 0.1, start=(1.0, 2.0, 0.5))
    assert straight[-1, :2] == pytest.approx([1.0 + 0.3 * math.cos(0.5), 2.0 + 0.3 * math.sin(0.5)], abs=1e-12)

