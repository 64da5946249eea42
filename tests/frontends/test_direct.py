"""The direct frontend's registration, its options, and the dense check of few sliding points."""

import dataclasses

import numpy as np
import pytest
from frontend_frames import HEIGHT, WIDTH, pair, similarity_about

from frontends import make_frontend
from frontends.base import FrameMotion, IdentityMap, MotionStatus
from frontends.direct import DenseFallback, DirectConfig
from fusion_vo.config import RunConfig, load_config
from fusion_vo.errors import InputError


def test_direct_is_a_run_option(tmp_path):
    path = tmp_path / "run.yaml"
    path.write_text("frontend: direct\ndirect: {iterations: 12, max_pixels: 5000}\n")
    cfg = load_config(path)
    odo = cfg.odometry_config()
    assert odo.frontend == "direct"
    assert odo.frontend_options["iterations"] == 12 and odo.frontend_options["max_pixels"] == 5000
    assert make_frontend("direct", odo.frontend_options).config.iterations == 12
    with pytest.raises(ValueError, match="iterations"):
        make_frontend("direct", {"iterations": 0})
    with pytest.raises(ValueError, match="frontend: expected one of"):
        RunConfig(frontend="dense")


def test_dense_check_replaces_a_wrong_point_estimate_and_keeps_a_right_one():
    truth = similarity_about(WIDTH / 2, HEIGHT / 2, 6.0, -4.0, 0.8)
    f0, f1 = pair(truth)
    fallback = DenseFallback(IdentityMap(), DirectConfig())
    right = FrameMotion(0.05, 0.0, matrix=truth.copy(), status=MotionStatus.OK)
    assert fallback.verify(f0, f1, right, tolerance=1.0) is None
    short = truth.copy()
    short[:, 2] *= 0.8  # a motion 20 % short, as points sliding along edges give
    fixed = fallback.verify(f0, f1, FrameMotion(0.05, 0.0, matrix=short, status=MotionStatus.OK), tolerance=1.0)
    assert fixed is not None and fixed.info["path"] == "dense"
    assert np.abs(fixed.matrix - truth).max() < 0.05



def test_dense_check_needs_a_confident_alignment_to_overrule_the_points():
    """The same disagreeing alignment replaces the points when it correlates at ``min_correlation`` or
    better, and not when it correlates less (a frame coming out of a featureless stretch: a wrong
    minimum at correlation 0.33 once replaced a right point estimate by a 4.8 degree turn)."""
    truth = similarity_about(WIDTH / 2, HEIGHT / 2, 6.0, -4.0, 0.8)
    f0, f1 = pair(truth)
    short = truth.copy()
    short[:, 2] *= 0.8
    points = FrameMotion(0.05, 0.0, matrix=short, status=MotionStatus.OK)
    fallback = DenseFallback(IdentityMap(), DirectConfig())
    measured = fallback.measure(f0, f1, short)
    limit = fallback.aligner.config.min_correlation
    assert measured.correlation >= limit
    for correlation, replaced in ((limit, True), (0.33, False), (float("nan"), False)):
        fallback.measure = lambda *_, c=correlation: dataclasses.replace(measured, correlation=c)
        checked = fallback.verify(f0, f1, points, tolerance=1.0)
        assert (checked is not None) == replaced, correlation

@pytest.mark.parametrize("finest", [0, 1])
def test_alignment_from_a_coarser_finest_level(finest):
    """``finest_level: 1`` aligns on the half-resolution image (fewer pixels): still accurate."""
    truth = similarity_about(WIDTH / 2, HEIGHT / 2, 9.0, -3.0, 1.5)
    f0, f1 = pair(truth)
    fe = make_frontend("direct", {"finest_level": finest})
    fe.process(f0, 0.0)
    m = fe.process(f1, 0.05)
    assert m.ok
    corners = np.array([[0.0, 0.0], [WIDTH, 0.0], [0.0, HEIGHT], [WIDTH, HEIGHT]])
    err = np.abs(corners @ (m.matrix - truth)[:, :2].T + (m.matrix - truth)[:, 2]).max()
    assert err < (0.03 if finest == 0 else 0.06), err


def test_grid_limit_keeps_the_rectified_image_no_larger_than_the_frame():
    """Through a barrel lens the rectified image is larger than the frame; ``grid_limit`` samples it more
    coarsely (fewer pixels to align) and still measures the similarity in rectified pixels."""
    import math

    from frontend_frames import as3, start_map
    from test_frontends import CENTRE, _Radial, _render_distorted, centre_error

    pm = _Radial()
    truth = similarity_about(*CENTRE, 20.0, 35.0, 2.0)
    a0 = start_map()
    frames = [_render_distorted(a0, pm), _render_distorted((as3(truth) @ as3(a0))[:2], pm)]
    shapes = []
    for limit in (False, True):
        fe = make_frontend("direct", {"grid_limit": limit}, point_map=pm)
        fe.process(frames[0], 0.0)
        m = fe.process(frames[1], 0.05)
        assert m.ok
        assert centre_error(m.matrix, truth) < 0.1
        assert abs(m.params[3]) < 3e-4 and abs(math.degrees(m.params[2]) - 2.0) < 0.01
        rect = fe.aligner._rectifier
        shapes.append(rect.shape)
        assert (rect.pitch > 1.0) == limit
    (h0, w0), (h1, w1) = shapes
    assert h0 * w0 > HEIGHT * WIDTH >= h1 * w1
