"""The renderer against the camera model: a bright dot on the floor appears where the geometry projects it."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from fusion_vo.geometry.camera import CameraModel
from fusion_vo.simulation.mount import body_pose, camera_mount
from fusion_vo.simulation.render import render_frame

DOT = np.array([1.3, -0.7])  # world position of the dot [m]
TEXEL = 0.0005  # [m]
BACKGROUND = 20.0


def dot_texture(half: int = 200, sigma: float = 2.5) -> np.ndarray:
    """A dark square texture with a Gaussian dot (``sigma`` texels) on its centre texel."""
    yy, xx = np.mgrid[-half:half + 1, -half:half + 1]
    return (BACKGROUND + 220.0 * np.exp(-0.5 * (xx**2 + yy**2) / sigma**2)).astype(np.float32)


def dot_centroid(image: np.ndarray, radius: int = 5) -> np.ndarray:
    v, u = np.unravel_index(np.argmax(image), image.shape)
    assert radius <= u < image.shape[1] - radius and radius <= v < image.shape[0] - radius
    patch = np.clip(image[v - radius:v + radius + 1, u - radius:u + radius + 1] - BACKGROUND, 0, None)
    dv, du = np.mgrid[-radius:radius + 1, -radius:radius + 1]
    return np.array([u + np.sum(du * patch) / patch.sum(), v + np.sum(dv * patch) / patch.sum()])


def pose_showing_dot_at(camera: CameraModel, pixel: np.ndarray, yaw: float) -> np.ndarray:
    """``T_WS`` of a robot with heading ``yaw`` whose camera sees the dot at ``pixel``."""
    ray = np.append(camera.normalize(pixel[None])[0], 1.0)
    T_WS0 = body_pose(0.0, 0.0, yaw) @ camera.T_BS  # body at the origin
    direction = T_WS0[:3, :3] @ ray
    floor_point = T_WS0[:3, 3] - T_WS0[2, 3] / direction[2] * direction
    body_xy = DOT - floor_point[:2]
    return body_pose(body_xy[0], body_xy[1], yaw) @ camera.T_BS


@pytest.mark.parametrize("supersample", [1, 2])
@pytest.mark.parametrize("lens, coefficients", [("radial-tangential", [-0.12, 0.03, 0.001, -0.0008]),
                                                ("equidistant", [0.05, -0.01, 0.002, 0.0])])
def test_dot_appears_where_the_camera_model_projects_it(supersample, lens, coefficients):
    # rendered without the lens distortion, the radial-tangential dot lands 1-3.5 px away
    camera = CameraModel(160, 120, 110.0, 112.0, 80.3, 58.7, lens, coefficients,
                         camera_mount(0.25, 0.1, tilt_x_deg=4.0, tilt_y_deg=-3.0))
    texture = dot_texture()
    origin = (DOT[0] - 200 * TEXEL, DOT[1] - 200 * TEXEL)
    rng = np.random.default_rng(5)
    errors = []
    for _ in range(6):
        target = rng.uniform([12, 12], [148, 108])
        T_WS = pose_showing_dot_at(camera, target, rng.uniform(-math.pi, math.pi))
        X_S = np.linalg.inv(T_WS) @ np.array([DOT[0], DOT[1], 0.0, 1.0])
        expected = camera.project(X_S[None, :3])[0]
        np.testing.assert_allclose(expected, target, atol=1e-6)  # the pose is right
        image = render_frame(texture, camera, T_WS, texel_size=TEXEL, origin=origin, border_value=BACKGROUND,
                             supersample=supersample)
        errors.append(np.linalg.norm(dot_centroid(image.astype(np.float64)) - expected))
    assert max(errors) < 0.05, errors


def test_featureless_stretch_gives_flat_frames(generate):
    root = generate("featureless", seed=6, duration=8.0, featureless_time=[3.0, 4.5])
    lines = (root / "cam0/data.csv").read_text().splitlines()[1:]
    t = np.array([int(line.split(",")[0]) for line in lines]) * 1e-9
    t -= t[0]
    spread = np.array([cv2.imread(str(Path(root, "cam0/data", line.split(",")[1])), cv2.IMREAD_GRAYSCALE).std()
                       for line in lines])
    inside = (t >= 3.0) & (t <= 4.5)
    assert inside.sum() == 31
    assert spread[inside].max() < 2.0  # sensor noise only (1 grey level)
    assert np.median(spread[~inside]) > 10.0
