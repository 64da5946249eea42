"""show-matches: corners of two frames matched like the frontends do, drawn on the current frame."""

import cv2
import numpy as np
import pytest

from fusion_vo.cli.main import main
from fusion_vo.evaluation.matches import find_matches

SHIFT = (6.0, -4.0)  # image content motion between the frames [px]


def texture(shape=(240, 320), seed=3):
    rng = np.random.default_rng(seed)
    noise = cv2.GaussianBlur(rng.uniform(0, 255, (shape[0] + 40, shape[1] + 40)).astype(np.float32), (0, 0), 2.0)
    return cv2.normalize(noise, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)


def two_frames():
    big = texture()
    m = np.float32([[1, 0, SHIFT[0]], [0, 1, SHIFT[1]]])
    moved = cv2.warpAffine(big, m, (big.shape[1], big.shape[0]), flags=cv2.INTER_LINEAR)
    return big[20:-20, 20:-20].copy(), moved[20:-20, 20:-20].copy()


@pytest.mark.parametrize("frontend", ["features", "klt"])
def test_inliers_move_by_the_image_shift(frontend):
    prev, cur = two_frames()
    matches = find_matches(prev, cur, frontend)
    assert matches.status == "ok"
    assert matches.n_inliers >= 20
    motion = matches.current[matches.inliers] - matches.previous[matches.inliers]
    np.testing.assert_allclose(np.median(motion, axis=0), SHIFT, atol=0.3)
    np.testing.assert_allclose(matches.matrix[:, 2], SHIFT, atol=0.3)


def test_klt_matches_a_motion_too_large_to_track_from_where_the_points_were():
    """The KLT frontend finds a large motion from the frames' shift by phase correlation when tracking from
    the points' own positions fails; the drawing does the same (it showed 5 matches, 0 inliers, at 30 px)."""
    big = texture((300, 380))
    m = np.float32([[1, 0, 30.0], [0, 1, -24.0]])
    moved = cv2.warpAffine(big, m, (big.shape[1], big.shape[0]), flags=cv2.INTER_LINEAR)
    prev, cur = big[30:-30, 30:-30].copy(), moved[30:-30, 30:-30].copy()
    matches = find_matches(prev, cur, "klt")
    assert matches.status == "ok" and matches.n_inliers >= 20
    np.testing.assert_allclose(matches.matrix[:, 2], (30.0, -24.0), atol=0.3)


def write_sequence(root):
    (root / "cam0" / "data").mkdir(parents=True)
    rows = ["#timestamp [ns],filename"]
    for i, img in enumerate(two_frames()):
        cv2.imwrite(str(root / "cam0" / "data" / f"{i}.png"), img)
        rows.append(f"{1_000_000_000 + i * 50_000_000},{i}.png")
    (root / "cam0" / "data.csv").write_text("\n".join(rows) + "\n")
    (root / "cam0" / "sensor.yaml").write_text(
        "sensor_type: camera\nrate_hz: 20\nresolution: [320, 240]\ncamera_model: pinhole\n"
        "intrinsics: [300, 300, 160, 120]\ndistortion_model: radial-tangential\n"
        "distortion_coefficients: [0, 0, 0, 0]\n"
        "T_BS:\n  cols: 4\n  rows: 4\n  data: [0, -1, 0, 0.25, -1, 0, 0, 0.0, 0, 0, -1, 0.095, 0, 0, 0, 1]\n")
    return root


def test_show_matches_command(tmp_path, capsys):
    seq = write_sequence(tmp_path / "seq")
    out = tmp_path / "m.png"
    assert main(["show-matches", str(seq), "--frame", "1", "--frontend", "klt", "--out", str(out)]) == 0
    assert "inliers" in capsys.readouterr().out
    png = cv2.imread(str(out))
    assert png is not None and png.shape[0] > 300
    assert main(["show-matches", str(seq), "--frame", "2"]) == 2
    assert "--frame must lie between 1 and 1" in capsys.readouterr().err
