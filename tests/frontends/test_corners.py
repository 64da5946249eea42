"""Corner settings that follow the image size and texture (frontends.corners) and their use by KLT."""

import cv2
import numpy as np
import pytest
from frontend_frames import canvas, pair, render, similarity_about, start_map

from frontends.corners import grid_shape, plan_corners, spread_corners
from frontends.direct import DenseFallback, DirectConfig
from frontends.base import IdentityMap
from frontends.klt import KltConfig, KltFrontend

REFERENCE = dict(min_distance=24.0, block_size=3, border=10, max_corners=60, replenish_below=40)


def test_settings_scale_with_the_diagonal_and_the_area():
    ref = plan_corners((360, 640), **REFERENCE)
    assert (ref.min_distance, ref.block_size, ref.border, ref.max_corners, ref.replenish_below) == (24.0, 3, 10, 60, 40)
    small = plan_corners((240, 320), **REFERENCE)
    assert small.min_distance == pytest.approx(24.0 * 400.0 / np.hypot(640, 360))
    assert small.max_corners == 60 and small.replenish_below == 40  # never fewer than at the reference size
    big = plan_corners((720, 1280), **REFERENCE)
    assert big.min_distance == pytest.approx(48.0) and big.block_size == 7 and big.border == 20
    assert big.max_corners == 240 and big.replenish_below == 160
    centre = plan_corners((360, 640), **REFERENCE, central_region=0.5)
    assert centre.region == (160, 90, 480, 270)
    assert centre.inside(np.array([[320.0, 180.0], [100.0, 180.0], [320.0, 300.0]])).tolist() == [True, False, False]


def _half_textured():
    """Gravel on the left half, the same gravel at a tenth of the contrast on the right half."""
    img = render(start_map()).astype(np.float32)
    img[:, 320:] = 128.0 + 0.1 * (img[:, 320:] - 128.0)
    return np.clip(img, 0, 255).astype(np.uint8)


def test_grid_gives_every_part_of_the_frame_a_corner():
    img = _half_textured()
    mask = np.full(img.shape, 255, np.uint8)
    plain = spread_corners(img, mask, 40, 0.02, 0.02, 12.0, 3, (1, 1), 20)
    assert len(plain) == 40 and np.all(plain[:, 0] < 320)  # the strongest corners all crowd on the left
    grid = grid_shape(img.shape, 160.0)
    assert grid == (2, 4)
    spread = spread_corners(img, mask, 40, 0.02, 0.02, 12.0, 3, grid, 20)
    assert len(spread) == 40
    right = spread[spread[:, 0] >= 320]
    assert len(right) == 4  # one per cell of the faint half
    assert {int(x // 160) for x in right[:, 0]} == {2, 3} and {int(y // 180) for y in right[:, 1]} == {0, 1}


def test_quality_is_lowered_only_when_too_few_corners_come_back():
    # four strong squares on a faint texture: four corners each at the first quality level
    img = (128 + 0.05 * (render(start_map()).astype(np.float32) - 128)).astype(np.uint8)
    for x, y in ((100, 80), (400, 80), (100, 220), (400, 220)):
        img[y : y + 60, x : x + 60] = 250
    mask = np.full(img.shape, 255, np.uint8)
    fixed = spread_corners(img, mask, 60, 0.02, 0.02, 12.0, 3, (1, 1), 20)
    assert 12 <= len(fixed) <= 16
    lowered = spread_corners(img, mask, 60, 0.02, 0.0005, 12.0, 3, (1, 1), 20)
    assert len(lowered) >= 20
    # the first level is kept when it gives enough
    rich = render(start_map())
    assert np.array_equal(spread_corners(rich, mask, 60, 0.02, 0.0005, 12.0, 3, (1, 1), 20),
                          spread_corners(rich, mask, 60, 0.02, 0.02, 12.0, 3, (1, 1), 20))


@pytest.mark.parametrize("size", [(320, 240), (1280, 720)])
def test_klt_measures_other_image_sizes(size):
    """The same motion seen at another resolution (scaled to it) is measured as accurately."""
    f = size[0] / 640.0
    truth = similarity_about(size[0] / 2, size[1] / 2, 7.0 * f, -5.0 * f, 1.2)
    a0 = np.diag([f, f]) @ start_map(700.3, 800.7)
    a1 = (np.vstack([truth, [0, 0, 1]]) @ np.vstack([a0, [0, 0, 1]]))[:2]
    f0, f1 = render(a0, size=size), render(a1, size=size)
    fe = KltFrontend(KltConfig())
    fe.process(f0, 0.0)
    m = fe.process(f1, 0.05)
    assert m.ok and m.info["path"] != "dense"
    assert m.n_inliers >= KltConfig().min_inliers
    corners = np.array([[0.0, 0.0], [size[0], 0.0], [0.0, size[1]], [size[0], size[1]]])
    err = np.abs(corners @ (m.matrix - truth)[:, :2].T + (m.matrix - truth)[:, 2]).max()
    assert err < 0.05 * f + 0.02, err


def test_central_region_keeps_corners_and_pixels_in_the_centre():
    f0, f1 = pair(similarity_about(320, 180, 5.0, 3.0, 0.5))
    fe = KltFrontend(KltConfig(central_region=0.5))
    fe.process(f0, 0.0)
    pts = fe._ref_pts
    assert len(pts) >= 20
    assert np.all((pts[:, 0] >= 160) & (pts[:, 0] < 480) & (pts[:, 1] >= 90) & (pts[:, 1] < 270))
    assert fe.process(f1, 0.05).ok
    with pytest.raises(ValueError, match="central_region"):
        KltConfig(central_region=0.05)
    with pytest.raises(ValueError, match="central_region"):
        DirectConfig(central_region=1.5)
    # the dense alignment of only the centre still finds the motion
    dense = DenseFallback(IdentityMap(), DirectConfig(central_region=0.4)).measure(f0, f1, None)
    assert np.abs(dense.matrix - similarity_about(320, 180, 5.0, 3.0, 0.5)).max() < 0.05
    assert canvas().shape == (2048, 2048)


def test_feature_detector_settings_follow_the_image_size_and_contrast():
    from frontends.corners import scale_detector
    from frontends.detectors import detect_corners
    from frontends.features import FeatureConfig

    shi = FeatureConfig().detector_settings()
    rich = render(start_map())
    assert scale_detector(shi, rich) is shi  # 640 x 360: unchanged
    small = scale_detector(shi, rich[:240, :320])
    assert (small.level, small.neighbourhood, small.block_size, small.max_corners) == (0, (9, 9), 3, 150)
    big = scale_detector(shi, cv2.resize(rich, (1280, 720)))
    assert (big.level, big.neighbourhood, big.max_corners) == (2, (9, 9), 600)
    fast = FeatureConfig(detector="fast").detector_settings()
    assert scale_detector(fast, rich).fast_threshold == fast.fast_threshold  # good contrast: unchanged
    dim = np.clip(128.0 + 0.3 * (rich.astype(np.float32) - 128.0), 0, 255).astype(np.uint8)
    lowered = scale_detector(fast, dim)
    assert 5 <= lowered.fast_threshold < 0.5 * fast.fast_threshold
    # the lowered threshold finds all the corners wanted on the dim floor, the fixed one half as many
    found, fixed = len(detect_corners(dim, lowered)), len(detect_corners(dim, fast))
    assert found == fast.max_corners and fixed < 0.6 * found, (found, fixed)


@pytest.mark.parametrize("detector", ["shi_tomasi", "fast", "harris"])
def test_features_measure_a_small_dim_frame(detector):
    """A 320 x 240 low-contrast view of a known motion: the scaled detector finds more corners (all of
    them where FAST's fixed threshold finds none, which fails the frame without raising)."""
    from frontends.features import FeatureConfig, FeatureFrontend

    size = (320, 240)
    f = 0.5
    truth = similarity_about(size[0] / 2, size[1] / 2, 7.0 * f, -5.0 * f, 1.2)
    a0 = np.diag([f, f]) @ start_map(700.3, 800.7)
    a1 = (np.vstack([truth, [0, 0, 1]]) @ np.vstack([a0, [0, 0, 1]]))[:2]
    dim = [np.clip(128.0 + 0.15 * (render(a, size=size).astype(np.float32) - 128.0), 0, 255).astype(np.uint8)
           for a in (a0, a1)]
    motions = []
    for adaptive in (True, False):
        fe = FeatureFrontend(FeatureConfig(detector=detector, dense_fallback=False, adaptive_detector=adaptive))
        fe.process(dim[0], 0.0)
        motions.append(fe.process(dim[1], 0.05))
    m, fixed = motions
    assert m.ok, m.info
    corners = np.array([[0.0, 0.0], [size[0], 0.0], [0.0, size[1]], [size[0], size[1]]])
    err = np.abs(corners @ (m.matrix - truth)[:, :2].T + (m.matrix - truth)[:, 2]).max()
    assert err < 0.1, err
    # measured: 102 / 71 / 121 inliers against 63 / 0 / 82 with the settings of a 640 x 360 frame
    assert m.n_inliers > 1.3 * fixed.n_inliers
    if detector == "fast":
        assert not fixed.ok and "corners" in fixed.info.get("reason", "")
