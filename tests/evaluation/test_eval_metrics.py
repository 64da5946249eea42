"""Figures of fusion_vo.evaluation.metrics on trajectories with known errors."""

import copy
import math

import numpy as np
import pytest

from fusion_vo.errors import InputError
from fusion_vo.evaluation import metrics as m

from eval_synthetic import circle_path, distorted, square_path


def trajectory(t, x, y, yaw, name="est"):
    return m.planar_trajectory(np.asarray(t) + 1.0, x, y, yaw, name=name)


@pytest.fixture(scope="module")
def square():
    return square_path()


def test_rigidly_moved_copy_has_zero_aligned_error_but_anchoring_keeps_nothing_back(square):
    t, x, y, yaw = square
    gt = trajectory(t, x, y, yaw, "gt")
    c, s = math.cos(0.3), math.sin(0.3)
    est = trajectory(t, c * x - s * y + 2.0, s * x + c * y - 1.0, yaw + 0.3)
    figures = m.evaluate_trajectory(gt, est).figures
    assert figures["ate_m"] == pytest.approx(0.0, abs=1e-9)
    assert figures["ate_anchored_m"] == pytest.approx(0.0, abs=1e-9)
    assert figures["end_m"] == pytest.approx(0.0, abs=1e-9)
    assert figures["heading_deg"] == pytest.approx(0.0, abs=1e-6)
    assert figures["rpe_1m_pct"] == pytest.approx(0.0, abs=1e-6)
    assert figures["vx_rmse_m_s"] == pytest.approx(0.0, abs=1e-9)


def test_scale_error_shows_in_legs_rpe_and_velocity(square):
    t, x, y, yaw = square
    gt = trajectory(t, x, y, yaw, "gt")
    result = m.evaluate_trajectory(gt, trajectory(*distorted(t, x, y, yaw, scale=1.05, step=2)),
                                   m.detect_legs(gt))
    figures = result.figures
    assert len(figures["legs"]) == 4
    for leg in figures["legs"]:
        assert leg["actual_m"] == pytest.approx(0.9, abs=1e-6)
        assert leg["estimated_m"] == pytest.approx(0.945, abs=1e-6)
        assert leg["error_pct"] == pytest.approx(5.0, abs=1e-4)
    # the square closes, so does the scaled square: the end point is right, the figures in between not
    assert figures["end_m"] == pytest.approx(0.0, abs=1e-6)
    assert figures["ate_anchored_m"] > 0.02
    # over straight 1 m stretches the error is 5 cm; stretches across a corner see less
    assert 2.5 < figures["rpe_1m_pct"] <= 5.0 + 1e-6
    assert figures["path_length_m"] == pytest.approx(3.6, abs=0.01)
    # forward speed 0.2 m/s is 5 % too fast while driving, right while turning in place
    assert 0.002 < figures["vx_rmse_m_s"] < 0.01
    assert figures["yaw_rate_rmse_deg_s"] == pytest.approx(0.0, abs=1e-6)
    assert [d["length_m"] for d in figures["drift"]] == [0.5, 1.0, 2.0]
    assert figures["revolutions"] == pytest.approx(1.0, abs=1e-6)


def test_heading_error_per_revolution_on_a_circle():
    t, x, y, yaw = circle_path()
    gt = trajectory(t, x, y, yaw, "gt")
    bias = math.radians(3.6) / t[-1]  # 3.6 deg after the one revolution
    figures = m.evaluate_trajectory(gt, trajectory(*distorted(t, x, y, yaw, yaw_rate_bias=bias))).figures
    assert figures["revolutions"] == pytest.approx(1.0, abs=1e-3)
    assert figures["heading_deg"] == pytest.approx(3.6, abs=1e-6)
    assert figures["heading_per_rev_pct"] == pytest.approx(1.0, abs=2e-3)
    assert figures["yaw_rate_rmse_deg_s"] == pytest.approx(3.6 / t[-1], rel=1e-6)
    assert figures["legs"] == []


def test_legs_follow_the_turns_of_the_square(square):
    t, x, y, yaw = square
    legs = m.detect_legs(trajectory(t, x, y, yaw))
    assert [tuple(np.round(leg.end_xy, 6)) for leg in legs] == [(0.9, 0.0), (0.9, 0.9), (0.0, 0.9), (0.0, 0.0)]
    assert all(leg.length_m == pytest.approx(0.9) for leg in legs)
    t_circle, *rest = circle_path()
    assert m.detect_legs(trajectory(t_circle, *rest)) == []


def test_body_velocities_are_in_the_body_frame():
    t = np.arange(0.0, 1.0, 0.1)
    traj = m.planar_trajectory(t, 0.5 * t * math.cos(1.0), 0.5 * t * math.sin(1.0), np.full(t.shape, 1.0 + np.pi / 2))
    vel = m.body_velocities(traj)
    np.testing.assert_allclose(vel.vx, 0.0, atol=1e-12)
    np.testing.assert_allclose(vel.vy, -0.5, atol=1e-12)  # moving to the robot's right
    np.testing.assert_allclose(vel.t, t[1:])


def test_estimate_outside_the_ground_truth_time_is_an_input_error(square):
    t, x, y, yaw = square
    gt = trajectory(t, x, y, yaw, "gt")
    with pytest.raises(InputError, match="match the ground truth in time"):
        m.evaluate_trajectory(gt, trajectory(t + 1000.0, x, y, yaw))


def test_planar_relative_yaw_equals_evo_rotation_rpe(square):
    t, x, y, yaw = square
    gt = trajectory(t[::4], x[::4], y[::4], yaw[::4], "gt")
    est = trajectory(*distorted(t, x, y, yaw, scale=1.02, yaw_rate_bias=0.02, step=4))
    for delta, unit in ((1.0, m.Unit.meters), (1, m.Unit.frames)):
        fast = m.relative_yaw_errors(gt, est, delta, unit)
        slow = m.rpe_errors(gt, est, delta, unit, m.PoseRelation.rotation_angle_deg)
        assert fast.size > 20
        np.testing.assert_allclose(fast, slow, atol=1e-6)


def test_vectorised_rpe_translation_equals_evos_rpe(square):
    """The translation errors are computed for all pairs at once; evo's RPE takes three SE(3) inversions per
    pair. Same pairs, same numbers (a drive that also turns, so the frames of the pairs differ)."""
    t, x, y, yaw = square
    gt = trajectory(t[::4], x[::4], y[::4], yaw[::4], "gt")
    est = trajectory(*distorted(t, x, y, yaw, scale=1.02, yaw_rate_bias=0.02, step=4))
    for delta, unit in ((0.5, m.Unit.meters), (1.0, m.Unit.meters), (1, m.Unit.frames), (7, m.Unit.frames)):
        rpe = m.RPE(m.PoseRelation.translation_part, delta=delta, delta_unit=unit, rel_delta_tol=m.REL_DELTA_TOL,
                    all_pairs=unit == m.Unit.meters, pairs_from_reference=True)
        rpe.process_data((gt, est))
        fast = m.rpe_errors(gt, est, delta, unit)
        assert fast.size > 20 and np.max(rpe.error) > 1e-4
        np.testing.assert_allclose(fast, rpe.error, rtol=1e-12, atol=1e-14)
    assert m.rpe_errors(gt, est, 1e3, m.Unit.meters).size == 0  # longer than the path: no pair


def test_planar_anchor_and_alignment_equal_evos_se3_transforms(square):
    t, x, y, yaw = square
    gt = trajectory(t[::4], x[::4], y[::4], yaw[::4], "gt")
    est = trajectory(*distorted(t, x, y, yaw, scale=1.02, yaw_rate_bias=0.02, step=4))
    moved = copy.deepcopy(est)
    moved.align_origin(gt)
    anchored = m.anchor(gt, est)
    np.testing.assert_allclose(anchored.positions_xyz, moved.positions_xyz, atol=1e-12)
    np.testing.assert_allclose(anchored.orientations_quat_wxyz * np.sign(anchored.orientations_quat_wxyz[:, :1]),
                               moved.orientations_quat_wxyz * np.sign(moved.orientations_quat_wxyz[:, :1]),
                               atol=1e-12)
    c, s = math.cos(0.3), math.sin(0.3)
    matrix = np.eye(4)
    matrix[:2, :2], matrix[:2, 3] = [[c, -s], [s, c]], [1.5, -2.0]
    moved = copy.deepcopy(est)
    moved.transform(matrix)
    shifted = m.transform_2d(est, matrix[:2, :2], matrix[:2, 3])
    np.testing.assert_allclose(shifted.positions_xyz, moved.positions_xyz, atol=1e-12)
    np.testing.assert_allclose(m.yaw_of(shifted), m.yaw_of(moved), atol=1e-12)


def test_standing_still_gives_figures_without_distance():
    t = np.arange(0.0, 5.0, 0.05)
    gt = trajectory(t, np.zeros_like(t), np.zeros_like(t), np.zeros_like(t), "gt")
    est = trajectory(t, 0.001 * t, np.zeros_like(t), np.zeros_like(t))
    figures = m.evaluate_trajectory(gt, est).figures
    assert figures["path_length_m"] == 0.0
    assert figures["end_m"] == pytest.approx(0.001 * t[-1])
    assert math.isnan(figures["end_pct"]) and math.isnan(figures["rpe_1m_pct"])
    assert figures["drift"] == [] and figures["legs"] == []


def test_height_and_tilt_of_the_ground_truth_are_ignored(square):
    t, x, y, yaw = square
    flat = trajectory(t, x, y, yaw, "gt")
    lifted = m.planar_trajectory(t + 1.0, x, y, yaw, name="gt")
    tilt = np.array([math.cos(0.05), math.sin(0.05), 0.0, 0.0])  # 5.7 deg roll about x, then yaw
    w, xq, yq, zq = lifted.orientations_quat_wxyz.T
    rolled = np.column_stack([w * tilt[0] - xq * tilt[1], w * tilt[1] + xq * tilt[0],
                              yq * tilt[0] + zq * tilt[1], zq * tilt[0] - yq * tilt[1]])
    lifted = m.PoseTrajectory3D(lifted.positions_xyz + [0, 0, 0.4], rolled, lifted.timestamps)
    est = trajectory(*distorted(t, x, y, yaw, scale=1.02, step=2))
    a = m.evaluate_trajectory(flat, est).figures
    b = m.evaluate_trajectory(lifted, est).figures
    for key in ("ate_m", "ate_anchored_m", "end_m", "heading_deg", "rpe_1m_m", "vx_rmse_m_s"):
        assert b[key] == pytest.approx(a[key], abs=1e-9), key
