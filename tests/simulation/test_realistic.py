"""The independent renderer: its own lens, a calibration the estimator can only approximate, and
frontends that measure every frame the plain OpenCV script measures on its coarse checkerboards."""

from __future__ import annotations

import ast
import tempfile
from pathlib import Path

import numpy as np
import pytest

from fusion_vo.config.sensor_files import camera_model
import fusion_vo.simulation.realistic as realistic
from fusion_vo import baseline
from fusion_vo.errors import InputError
from fusion_vo.geometry.camera import CameraModel
from fusion_vo.odometry import OdometryConfig, run_visual_odometry
from fusion_vo.recording import Recording
from fusion_vo.simulation import simulate
from fusion_vo.simulation.realistic import RealisticCamera, RealisticRenderer

from ahead_job import ahead_jobs


def test_renderer_shares_nothing_with_the_estimators_geometry():
    tree = ast.parse(Path(realistic.__file__).read_text())
    imported = [n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)]
    imported += [a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names]
    assert not [m for m in imported if m and (m.startswith("fusion_vo.geometry") or m.startswith("frontends"))]


@pytest.mark.parametrize("lens, size, focal, worst_px", [
    ("polynomial", (640, 360), 420.0, 0.5),
    ("equisolid", (320, 240), 170.0, 0.5),
])
def test_fitted_calibration_approximates_the_true_lens(lens, size, focal, worst_px):
    """The estimator's model (OpenCV radial-tangential, or the equidistant fisheye) with the fitted
    coefficients reprojects the true lens's rays to within ``worst_px``, but not exactly."""
    cam = RealisticCamera(lens=lens, focal=focal)
    r = RealisticRenderer(cam, *size)
    calib = r.sensor_calibration()
    model = camera_model({"resolution": list(size), **calib})
    gu, gv = np.meshgrid(np.linspace(0, size[0] - 1, 17), np.linspace(0, size[1] - 1, 13))
    pix = np.column_stack([gu.ravel(), gv.ravel()])
    rays = r.lens.rays(pix)
    err = np.linalg.norm(model.project(rays) - pix, axis=1)
    assert err.max() < worst_px
    assert err.max() > 1e-3  # an independent lens: the estimator's model does not reproduce it exactly
    # without the distortion (focal length only) the error at the corners is tens of pixels
    plain = CameraModel(size[0], size[1], *calib["intrinsics"])
    assert np.linalg.norm(plain.project(rays) - pix, axis=1).max() > 10.0


def _short(tmp_path, name, **realistic_options):
    options = {"width": 640, "height": 360, "exposure_time": 0.004, "blur_samples": 2}
    return simulate(tmp_path / name, profile="straight", seed=5, length=0.25, realistic=realistic_options,
                    **options)


#: the frontends' modes on the coarse drive: calibrated, then uncalibrated with the lens estimated from the frames
#: (True) and on the image's centre without it (False)
MODES = ("calibrated", True, False)


def _coarse_runs() -> dict:
    """A 0.25 m straight drive over checkerboard squares a quarter of the image wide (barrel lens), rendered into a
    temporary folder and measured by the plain script and by every frontend in every mode of :data:`MODES`: the
    frames the script measures and of all, the distance travelled, and per ``(mode, frontend)`` the distortion
    model the recording ended with, the frames measured, the distance travelled and the failures."""
    with tempfile.TemporaryDirectory() as tmp:
        coarse = _short(Path(tmp), "coarse", lens="polynomial", checker_size=0.04, defocus=1.2, supersample=1)
        results, _ = baseline.run(coarse)
        gt = Recording(coarse).groundtruth()
        out = {"plain": sum(m is not None for _, _, m in results), "frames": len(results),
               "truth": float(np.linalg.norm(gt.xyyaw[-1, :2] - gt.xyyaw[0, :2]))}
        for mode in MODES:
            for fe in ("klt", "features", "direct"):
                recording = Recording(coarse)
                config = (OdometryConfig(frontend=fe) if mode == "calibrated" else
                          OdometryConfig(frontend=fe, uncalibrated=True, lens_from_motion=mode))
                vo = run_visual_odometry(recording, config)
                out[mode, fe] = (recording.camera.distortion_model, sum(s == "ok" for s in vo.status),
                                 float(np.linalg.norm(vo.track.xyyaw[-1, :2] - vo.track.xyyaw[0, :2])), vo.failures)
    return out


def test_every_frontend_measures_what_the_plain_script_measures(made_ahead):
    coarse = made_ahead("coarse")
    plain, truth = coarse["plain"], coarse["truth"]
    assert plain >= coarse["frames"] - 2
    for fe in ("klt", "features", "direct"):
        _, measured, travelled, failures = coarse["calibrated", fe]
        assert measured >= plain, (fe, failures)
        assert abs(travelled - truth) < 0.01 * truth, fe


@pytest.mark.parametrize("lens_from_motion, tolerance", [(True, 0.015), (False, 0.04)])
def test_uncalibrated_frontends_measure_what_the_plain_script_measures(made_ahead, lens_from_motion, tolerance):
    """Without the lens model (a pinhole of the right focal length, as the plain script assumes) every
    frontend still measures every frame the plain script measures: over the whole image with the lens
    estimated from the frames, or on the centre of the image without that estimate."""
    coarse = made_ahead("coarse")
    plain, truth = coarse["plain"], coarse["truth"]
    for fe in ("klt", "features", "direct"):
        distortion, measured, travelled, failures = coarse[lens_from_motion, fe]
        assert distortion == ("division" if lens_from_motion else "none")
        assert measured >= plain, (fe, failures)
        # measured: 0.9 % long for all three with the estimated lens (lambda -0.338); 2.6 % short on the
        # centre without it (the centre of a barrel lens is magnified relative to the pinhole of the
        # fitted focal length)
        assert abs(travelled - truth) < tolerance * truth, fe


def test_frame_rendering_is_deterministic_and_exposure_adapts():
    cam = RealisticCamera(checker_size=0.04, auto_exposure=0.5, brightness=240.0, supersample=1)
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])
    T[2, 3] = 0.1
    frames = []
    for _ in range(2):
        r = RealisticRenderer(cam, 320, 240)
        rng = np.random.default_rng(0)
        frames.append([r.frame(lambda t: T, 0.05 * k, rng) for k in range(8)])
    assert all(np.array_equal(a, b) for a, b in zip(*frames))
    means = [float(f.mean()) for f in frames[0]]
    assert abs(means[-1] - cam.target_grey) < 0.3 * abs(means[0] - cam.target_grey)


def test_missing_intrinsics_is_an_error_unless_uncalibrated(tmp_path, monkeypatch):
    seq = simulate(tmp_path / "uncal", profile="straight", seed=3, length=0.05, width=320, height=240,
                   realistic={"lens": "polynomial", "focal": 220.0, "calibration": "none", "supersample": 1})
    assert "intrinsics" not in (seq / "cam0" / "sensor.yaml").read_text()
    with pytest.raises(InputError, match="uncalibrated"):
        run_visual_odometry(Recording(seq), OdometryConfig(frontend="klt"))
    vo = run_visual_odometry(Recording(seq), OdometryConfig(frontend="klt", uncalibrated=True, focal_length=220.0))
    assert sum(s == "ok" for s in vo.status) == len(vo.status) - 1
    gt = Recording(seq).groundtruth()
    truth = float(np.linalg.norm(gt.xyyaw[-1, :2] - gt.xyyaw[0, :2]))
    travelled = float(np.linalg.norm(vo.track.xyyaw[-1, :2] - vo.track.xyyaw[0, :2]))
    # the barrel lens is ignored: distances come out a few percent off, not more
    assert abs(travelled - truth) < 0.1 * truth
    # without the lens estimate, the image centre is used also when a configuration file gives the
    # frontend's section (every key set to its default), and not when the file asks for the whole image
    import fusion_vo.odometry as odometry
    from frontends.klt import KltConfig

    seen = []
    real = odometry.make_frontend

    def spy(name, options, point_map=None):
        seen.append(options.get("central_region"))
        return real(name, options, point_map=point_map)

    monkeypatch.setattr(odometry, "make_frontend", spy)
    for region in (None, 1.0):
        options = {**KltConfig().to_dict(), "central_region": region}
        run_visual_odometry(Recording(seq), OdometryConfig(frontend="klt", frontend_options=options, uncalibrated=True,
                                                           focal_length=220.0, lens_from_motion=False))
    assert seen == [odometry.UNCALIBRATED_CENTRAL_REGION, 1.0]


def test_bad_realistic_options_are_refused(tmp_path):
    with pytest.raises(ValueError, match="lens"):
        simulate(tmp_path / "x", profile="straight", realistic={"lens": "spherical"})
    with pytest.raises(ValueError, match=r"realistic\.colour: unknown key \(known: lens, focal, "):
        simulate(tmp_path / "y", profile="straight", realistic={"colour": 1})
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()


def _board_views(tmp_path, cam: RealisticCamera, size, n_views: int = 30):
    """Views of a finite board (inner corners 8 x 5) from above, tilted up to 11 degrees, saved as PNG."""
    import cv2

    paths = []
    for k, img in enumerate(realistic.board_views(cam, *size, n_views, distance=(0.10, 0.14), shift=0.09)):
        paths.append(tmp_path / f"view{k:02d}.png")
        cv2.imwrite(str(paths[-1]), img)
    return RealisticRenderer(cam, *size), paths


def _fisheye_calibrated() -> dict:
    """``calibrate intrinsics --model fisheye`` on views through the independent fisheye, rendered into a temporary
    folder: the focal length found, and at a grid of pixels the reprojection errors of the model found and of the
    true focal length without a lens model."""
    from fusion_vo.calibration.chessboard import Board
    from fusion_vo.calibration.intrinsics import calibrate_images

    cam = RealisticCamera(lens="equisolid", focal=170.0, checker_size=0.02, checker_squares=[9, 6], grain=0.0,
                          defocus=0.5, focus_height=0.2, defocus_per_metre=0.0, auto_exposure=0.0, vignetting=0.1,
                          supersample=2)
    size = (320, 240)
    with tempfile.TemporaryDirectory() as tmp:
        r, paths = _board_views(Path(tmp), cam, size)
        result = calibrate_images(paths, Board(8, 5, 0.02), model="fisheye")
    model = CameraModel(size[0], size[1], result.K[0, 0], result.K[1, 1], result.K[0, 2], result.K[1, 2],
                        "equidistant", result.distortion)
    gu, gv = np.meshgrid(np.linspace(20, size[0] - 21, 9), np.linspace(20, size[1] - 21, 7))
    pix = np.column_stack([gu.ravel(), gv.ravel()])
    rays = r.lens.rays(pix)
    focal_only = CameraModel(size[0], size[1], 170.0, 170.0, 159.5, 119.5)
    return {"focal": float(result.K[0, 0]), "error": np.linalg.norm(model.project(rays) - pix, axis=1),
            "plain": np.linalg.norm(focal_only.project(rays) - pix, axis=1)}


def test_calibrating_the_fisheye_wins_back_its_lens(made_ahead):
    """``calibrate intrinsics --model fisheye`` on views through the independent fisheye recovers a model
    that reprojects the true lens to within a few pixels, where the focal length alone is 140 px off."""
    made = made_ahead("fisheye_calibrated")
    err, plain = made["error"], made["plain"]
    # measured: worst 3.8 px, median 1.9 px from the views in which the board was found (9 of 30),
    # against 140 px and 22 px for the true focal length without a lens model
    assert plain.max() > 100.0 and np.median(plain) > 15.0
    assert err.max() < 5.0 and np.median(err) < 2.5, (err.max(), np.median(err))
    assert abs(made["focal"] - 170.0) < 0.04 * 170.0


@pytest.fixture(scope="module")
def focal_only(tmp_path_factory):
    """A 0.25 m straight drive over gravel through the barrel lens; ``sensor.yaml`` states the focal length
    only (no distortion)."""
    return _short(tmp_path_factory.mktemp("real"), "focal", lens="polynomial", calibration="focal", checker_size=0.0,
                  defocus=1.0, supersample=1)


def test_a_lens_stated_without_distortion_is_checked_against_the_frames(focal_only, caplog):
    """The barrel lens read as a pinhole makes the track short; the frames contradict the file, so the
    run takes the lens they show (with a warning naming the file) unless told to keep the file's."""
    gt = Recording(focal_only).groundtruth()
    truth = float(np.linalg.norm(gt.xyyaw[-1, :2] - gt.xyyaw[0, :2]))
    errors = {}
    for check in (True, False):
        recording = Recording(focal_only)
        with caplog.at_level("WARNING"):
            vo = run_visual_odometry(recording, OdometryConfig(check_lens=check))
        travelled = float(np.linalg.norm(vo.track.xyyaw[-1, :2] - vo.track.xyyaw[0, :2]))
        errors[check] = abs(travelled - truth) / truth
        assert recording.camera.distortion_model == ("division" if check else "none")
        if check:  # the true lens: lambda -0.335 estimated on the 20 s recording of this lens
            assert -0.4 < recording.camera.distortion[0] < -0.25
    assert "cam0/sensor.yaml states no lens distortion" in caplog.text
    assert errors[True] < 0.015 < errors[False]  # measured: 0.57 % against 5.8 %


def _pinhole_lens() -> str:
    """The lens model a run ends with on a straight drive rendered through a pinhole without distortion."""
    with tempfile.TemporaryDirectory() as tmp:
        seq = simulate(Path(tmp) / "pinhole", profile="straight", seed=5, length=0.25, distortion_model="none",
                       distortion=[0.0, 0.0, 0.0, 0.0])
        recording = Recording(seq)
        run_visual_odometry(recording)
        return recording.camera.distortion_model


def test_a_true_pinhole_keeps_its_stated_lens(made_ahead):
    """Rendered through a pinhole without distortion, the frames agree with the file: nothing changes."""
    assert made_ahead("pinhole_lens") == "none"


#: the values made in the session's second process (tests/ahead_job.py)
AHEAD = {"coarse": _coarse_runs, "fisheye_calibrated": _fisheye_calibrated, "pinhole_lens": _pinhole_lens}
BACKGROUND_COMMANDS, BACKGROUND_JOBS = ahead_jobs(__file__)
