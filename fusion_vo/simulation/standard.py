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
}


def make_standard(name: str, out_dir: str | Path) -> Path:
    """Generate the standard recording ``name`` into ``out_dir``."""
    if name not in STANDARD:
        raise ValueError(f"unknown standard recording '{name}' (choose one of {', '.join(STANDARD)})")
    profile, seed, options, _ = STANDARD[name]
    return simulate(out_dir, profile=profile, seed=seed, **options)
