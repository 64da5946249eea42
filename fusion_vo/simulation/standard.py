"""The standard generated recordings used by the tests, the examples and the benchmarks.

Each name fixes a profile, options and a seed (``datasets/generated.md`` lists them), so a recording
can be regenerated bit for bit anywhere: ``fusion-vo simulate OUT --standard NAME``.
"""

from __future__ import annotations

from pathlib import Path

from fusion_vo.simulation.generate import simulate

#: name -> (profile, seed, options, description)
STANDARD: dict[str, tuple[str, int, dict, str]] = {
    "square": ("square", 1, {}, "the 0.9 m square of thesis table 5.2 (turns in place at the corners)"),
    "circle": ("circle", 2, {}, "one full circle of radius 0.4 m, camera tangent to the path (thesis 5.2.1)"),
    "random60": ("random", 3, {"duration": 60.0},
                 "60 s random drive with stops, up to 0.3 m/s and 0.9 rad/s, camera 0.1 m high, 0.25 m ahead"),
    "standstill": ("standstill", 4, {"duration": 5.0}, "5 s without motion (thesis figures 3.3-3.5)"),
    "hard": ("random", 5, {"duration": 40.0, "highlight_radius": 22.0, "dropped_frames": 0.05,
                           "exposure_time": 0.004, "blur_samples": 3, "featureless_time": [20.0, 23.0],
                           "exposure_drift": 0.1,
                           "vignetting": 0.3, "wheel_start_count": 2**31 - 20000, "slip": 0.002},
             "40 s random drive with wheel calibration errors, slip, a fixed specular highlight, 5 % dropped "
             "frames, motion blur, exposure drift, vignetting and 3 s of featureless floor"),
    "height_error": ("random", 6, {"duration": 30.0, "height_error": 0.02},
                     "30 s random drive whose cam0/sensor.yaml height is 2 % too large (self-calibration)"),
    "tilted": ("random", 7, {"duration": 20.0, "tilt_x_deg": 3.0, "tilt_y_deg": -2.0, "height_vibration": 0.001,
                             "range_finder": True},
               "20 s random drive with a tilted camera, 1 mm height vibration and a range finder"),
    "turn_in_place": ("turn_in_place", 8, {}, "one full turn about the axle (lever-arm calibration)"),
    "straight": ("straight", 9, {"length": 1.0}, "a 1 m straight drive (height calibration)"),
    "umbmark_cw": ("umbmark_cw", 10, {"side": 2.0}, "UMBmark 2 m square, clockwise (wheel calibration)"),
    "umbmark_ccw": ("umbmark_ccw", 11, {"side": 2.0}, "UMBmark 2 m square, counter-clockwise"),
    "short": ("random", 12, {"duration": 5.0}, "5 s random drive for quick checks"),
    "gps_outage": ("random", 13, {"duration": 60.0, "gps": True, "gps_outages": [[20.0, 30.0]],
                                  "gps_jumps": [[40.0, 41.0, 12.0, 16.0]]},
                   "60 s random drive with GPS at 5 Hz (5 cm noise, antenna 0.1 m behind the axle, 0.4 m up), "
                   "a 10 s outage from 20 s and a 20 m multipath jump from 40 to 41 s"),
    # rendered through fusion_vo.simulation.realistic: a lens, optics and sensor the estimator does not model
    "real_fisheye_checker": (
        "random", 21,
        {"duration": 15.0, "width": 320, "height": 240, "camera_rate": 60.0, "camera_height": 0.25,
         "height_vibration": 0.1, "vibration_frequency": 0.05, "exposure_time": 0.008, "blur_samples": 3,
         "range_finder": True,
         "realistic": {"lens": "equisolid", "focal": 170.0, "checker_size": 0.08, "rocking_deg": 3.0,
                       "rolling_shutter": 0.012, "defocus": 0.8, "focus_height": 0.25, "defocus_per_metre": 8.0}},
        "15 s at 60 Hz, 320x240, equisolid fisheye (calibration: fitted equidistant model), coarse 8 cm "
        "checkerboard, camera 0.15-0.35 m high, 3 deg rocking, rolling shutter, motion blur, defocus"),
    "real_barrel_coarse": (
        "random", 22,
        {"duration": 30.0, "exposure_time": 0.004, "blur_samples": 3,
         "realistic": {"lens": "polynomial", "checker_size": 0.04, "defocus": 1.2}},
        "30 s at 20 Hz, 640x360, four-term barrel lens (calibration: fitted three-term model), checkerboard "
        "squares a quarter of the image wide, defocus, motion blur, auto-exposure"),
    "real_barrel_fine": (
        "random", 23,
        {"duration": 30.0, "exposure_time": 0.004, "blur_samples": 3,
         "realistic": {"lens": "polynomial", "checker_size": 0.01, "defocus": 1.2}},
        "as real_barrel_coarse over a 1 cm checkerboard"),
    "real_gravel_focal_only": (
        "random", 24,
        {"duration": 20.0, "camera_rate": 30.0, "height_vibration": 0.01, "vibration_frequency": 0.2,
         "range_finder": True, "exposure_time": 0.004, "blur_samples": 3,
         "realistic": {"lens": "polynomial", "calibration": "focal", "checker_size": 0.0, "defocus": 1.0}},
        "20 s at 30 Hz, 640x360, barrel lens over the gravel photograph, sensor.yaml states the focal length "
        "only (no distortion), camera 0.09-0.11 m high"),
}

#: the recordings of the independent renderer (``python benchmarks/visual.py independent``)
REALISTIC = [name for name in STANDARD if name.startswith("real_")]


def make_standard(name: str, out_dir: str | Path) -> Path:
    """Generate the standard recording ``name`` into ``out_dir``."""
    if name not in STANDARD:
        raise ValueError(f"unknown standard recording '{name}' (choose one of {', '.join(STANDARD)})")
    profile, seed, options, _ = STANDARD[name]
    return simulate(out_dir, profile=profile, seed=seed, **options)
