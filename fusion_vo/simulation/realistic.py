"""An independent camera simulation: a lens, optics and sensor the estimator does not model.

The default renderer (:mod:`fusion_vo.simulation.render`) images the floor through the same
:class:`~fusion_vo.geometry.camera.CameraModel` that the estimator inverts, so its recordings only
check that the estimator is consistent with itself. This module renders through its own path and
shares nothing with :mod:`fusion_vo.geometry`:

lens
    ``polynomial``: a higher-order radial (barrel) model on the undistorted normalised radius,
    ``r_d = r (1 + k1 r² + k2 r⁴ + k3 r⁶ + k4 r⁸)`` (four radial terms: OpenCV's radial-tangential
    model the estimator uses stops at three, and the coefficients written to ``sensor.yaml`` are a
    least-squares fit of ``k1..k3`` over the image, as a calibration would find them);
    ``equisolid``: a true fisheye, ``r_d = 2 f sin(θ / 2)`` (θ the angle from the optical axis);
    ``sensor.yaml`` gets OpenCV's equidistant model ``θ_d = θ (1 + k1 θ² + ... + k4 θ⁸)`` fitted to it.
    With ``calibration: none`` the file has no intrinsics at all (an uncalibrated camera), with
    ``calibration: focal`` a focal length only (no distortion).
optics
    defocus (a Gaussian blur that grows as the camera leaves its focus height), motion blur (renders
    averaged over the exposure), vignetting ``cos⁴``-like;
sensor
    rolling shutter (each image row exposed ``readout / rows`` after the previous one), shot and read
    noise, 8-bit quantisation and clipping, and an auto-exposure loop that drives the mean grey towards
    a target with a one-frame lag;
floor
    a printed checkerboard (squares of ``checker_size`` metres, optionally over a faint ``grain`` of
    scikit-image's gravel photograph) or a photographed texture.

Rays are cast onto the floor ``z = 0`` from the camera pose of each row band and sub-exposure; the floor
is evaluated analytically (checkerboard) or sampled (photograph) at ``supersample²`` rays per pixel and
box-filtered down.
"""

from __future__ import annotations

import math
from typing import Annotated, Callable, Literal

import cv2
import numpy as np
from pydantic import Field, model_validator

from fusion_vo.config.base import INTEGER, NUMBER, Float, Fraction, Int, NonNegative, Positive, Section
from fusion_vo.simulation.floor import TEXTURES, load_texture, mirror_tile

LENSES = ("polynomial", "equisolid")
CALIBRATIONS = ("fitted", "focal", "none")


#: a lens coefficient or offset (of a normalised radius, or in pixels): beyond it no lens
_Coefficient = Annotated[float, Field(ge=-1e3, le=1e3), NUMBER]


class RealisticCamera(Section):
    """Options of the independent renderer (the ``realistic`` mapping of a simulation)."""

    lens: Literal[LENSES] = Field("polynomial", description=(
        "``polynomial`` (barrel, four radial terms) or ``equisolid`` (fisheye)."))
    focal: Positive = Field(420.0, description=(
        "Focal length [px] (both axes; the principal point is the image centre plus ``centre_offset``)."))
    centre_offset: tuple[_Coefficient, _Coefficient] = Field((1.5, -2.0), description=(
        "Principal point offset from the image centre [px]."))
    coefficients: tuple[_Coefficient, _Coefficient, _Coefficient, _Coefficient] = Field(
        (-0.28, 0.09, -0.02, 0.004), description="``k1..k4`` of the polynomial lens (ignored by the equisolid lens).")
    tangential: tuple[_Coefficient, _Coefficient] = Field((4e-4, -3e-4), description=(
        "Decentering ``(p1, p2)`` of a lens element slightly off axis, applied (Brown's form) to the *distorted* "
        "normalised coordinates of either lens: the estimator's models apply it before the radial term "
        "(radial-tangential) or not at all (equidistant)."))
    calibration: Literal[CALIBRATIONS] = Field("fitted", description=(
        "What ``cam0/sensor.yaml`` states: ``fitted`` (the estimator's closest model, fitted), ``focal`` (the "
        "focal length only, no distortion), ``none`` (no intrinsics)."))
    defocus: NonNegative = Field(0.8, description="Gaussian blur at the focus height [px].")
    defocus_per_metre: NonNegative = Field(10.0, description=(
        "Additional blur per metre of height away from ``focus_height`` [px / m]."))
    focus_height: Float = Field(0.1, gt=0, le=100, description="Height at which the lens is focused [m].")
    rolling_shutter: Float = Field(0.0, ge=0, le=1, description=(
        "Time from the first to the last image row [s] (0: global shutter)."))
    bands: Int = Field(12, ge=1, le=4096, description="Row bands rendered with their own pose under a rolling "
                                                      "shutter.")
    vignetting: Fraction = Field(0.25, description="Relative brightness loss at the image corners.")
    read_noise: Float = Field(1.5, ge=0, le=255, description="Read noise [grey levels].")
    shot_noise: Float = Field(0.25, ge=0, le=100, description=(
        "Shot noise: standard deviation ``shot_noise * sqrt(grey)`` [grey levels]."))
    auto_exposure: Fraction = Field(0.3, description=(
        "Fraction of the log-error to the target grey corrected per frame (0: fixed exposure)."))
    target_grey: Float = Field(110.0, gt=0, le=255, description="Auto-exposure target mean [grey levels].")
    brightness: Float = Field(170.0, gt=0, le=255, description="Grey level of a white floor at the initial "
                                                               "exposure.")
    checker_size: Float = Field(0.0, ge=0, le=100, description=(
        "Side of a checkerboard square [m] (0: the photographed ``texture`` instead)."))
    checker_contrast: Fraction = Field(0.7, description=(
        "Difference between white and black squares (fraction of white)."))
    grain: Float = Field(0.06, ge=0, le=10, description=(
        "Contrast of the gravel photograph under the checkerboard (0: clean print)."))
    checker_squares: list[Annotated[int, Field(ge=1, le=10_000), INTEGER]] = Field(default_factory=list, description=(
        "``[columns, rows]`` of a finite calibration board from the floor origin along x and y, white around it; "
        "empty (the default): the checkerboard covers the whole floor."))
    texture: Literal[TEXTURES] = Field("gravel", description=(
        "Photograph used as the floor or grain (scikit-image's ``gravel``, ``grass`` or ``brick``)."))
    texel_size: Float = Field(0.00025, gt=0, le=1, description="Size of one texel of the photograph on the floor "
                                                               "[m].")
    rocking_deg: Float = Field(0.0, ge=0, le=90, description=(
        "Amplitude of the camera's roll and pitch oscillation about its optical centre [deg]."))
    rocking_period: Positive = Field(1.3, description="Period of the roll oscillation [s] (pitch: 1.37 times as "
                                                      "long).")
    supersample: Int = Field(2, ge=1, le=16, description="Rays per pixel along each axis.")

    @model_validator(mode="after")
    def _board(self) -> RealisticCamera:
        if len(self.checker_squares) not in (0, 2):
            raise ValueError(f"checker_squares must be [columns, rows] or empty, not {self.checker_squares}")
        return self

    # ---------------------------------------------------------------- rocking
    def rocking(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Camera rotation ``R`` (camera frame, about its centre) at ``t`` and its angular rate [rad/s]."""
        a = math.radians(self.rocking_deg)
        w1, w2 = 2 * math.pi / self.rocking_period, 2 * math.pi / (1.37 * self.rocking_period)
        rx, ry = a * math.sin(w1 * t), a * math.sin(w2 * t + 0.7)
        drx, dry = a * w1 * math.cos(w1 * t), a * w2 * math.cos(w2 * t + 0.7)
        cx, sx, cy, sy = math.cos(rx), math.sin(rx), math.cos(ry), math.sin(ry)
        Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
        Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
        # body rate of R = Rx(rx) Ry(ry): w = drx e_x + Rx dry e_y (in the camera frame)
        w = np.array([drx, 0.0, 0.0]) + Rx @ np.array([0.0, dry, 0.0])
        return Rx @ Ry, w


class _Lens:
    """Pixel <-> ray mapping of the true lens."""

    def __init__(self, cam: RealisticCamera, width: int, height: int):
        self.cam = cam
        self.f = float(cam.focal)
        self.c = np.array([(width - 1) / 2.0 + cam.centre_offset[0], (height - 1) / 2.0 + cam.centre_offset[1]])
        self.k = np.asarray(cam.coefficients, dtype=np.float64)
        self.p = np.asarray(cam.tangential, dtype=np.float64)

    def _tangential(self, xy: np.ndarray) -> np.ndarray:
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        p1, p2 = self.p
        return np.column_stack([2 * p1 * x * y + p2 * (r2 + 2 * x * x), p1 * (r2 + 2 * y * y) + 2 * p2 * x * y])

    def _distort_radius(self, r: np.ndarray) -> np.ndarray:
        r2 = r * r
        k1, k2, k3, k4 = self.k
        return r * (1 + r2 * (k1 + r2 * (k2 + r2 * (k3 + r2 * k4))))

    def rays(self, pixels: np.ndarray) -> np.ndarray:
        """Unit camera-frame rays (N x 3) through raw pixel positions (N x 2)."""
        observed = (np.asarray(pixels, dtype=np.float64) - self.c) / self.f
        d = observed.copy()
        for _ in range(20):  # remove the decentering: observed = d + tangential(d)
            d = observed - self._tangential(d)
        rd = np.hypot(d[:, 0], d[:, 1])
        direction = d / np.maximum(rd, 1e-12)[:, None]
        if self.cam.lens == "equisolid":
            theta = 2.0 * np.arcsin(np.clip(rd / 2.0, 0.0, 1.0))
            return np.column_stack([direction * np.sin(theta)[:, None], np.cos(theta)])
        # invert r_d = r (1 + k1 r^2 + ...) by Newton from r = r_d
        r = rd.copy()
        for _ in range(30):
            h = 1e-7
            fr = self._distort_radius(r) - rd
            dfr = (self._distort_radius(r + h) - self._distort_radius(r - h)) / (2 * h)
            r = r - fr / np.where(np.abs(dfr) > 1e-9, dfr, 1.0)
        if np.any(self._distort_radius(r) - rd > 1e-6) or np.any(~np.isfinite(r)):
            raise ValueError("the polynomial lens folds over inside the image: reduce its coefficients")
        xy = direction * r[:, None]
        v = np.column_stack([xy, np.ones(len(xy))])
        return v / np.linalg.norm(v, axis=1, keepdims=True)

    def sensor_calibration(self, width: int, height: int) -> dict:
        """The ``cam0/sensor.yaml`` intrinsics and distortion of :attr:`RealisticCamera.calibration`."""
        cam = self.cam
        if cam.calibration == "none":
            return {}
        intr = [self.f, self.f, float(self.c[0]), float(self.c[1])]
        if cam.calibration == "focal":
            return {"intrinsics": [self.f, self.f, (width - 1) / 2.0, (height - 1) / 2.0],
                    "distortion_model": "none", "distortion_coefficients": [0.0, 0.0, 0.0, 0.0]}
        corners = np.array([[0, 0], [width - 1, 0], [0, height - 1], [width - 1, height - 1]], dtype=np.float64)
        rays = self.rays(corners)
        theta_max = float(np.max(np.arccos(np.clip(rays[:, 2], -1, 1))))
        if cam.lens == "equisolid":
            theta = np.linspace(1e-3, theta_max, 200)
            target = 2.0 * np.sin(theta / 2.0) / theta - 1.0  # theta_d / theta - 1 = k1 θ² + ... + k4 θ⁸
            A = np.column_stack([theta**2, theta**4, theta**6, theta**8])
            k = np.linalg.lstsq(A, target, rcond=None)[0]
            return {"intrinsics": intr, "distortion_model": "equidistant", "distortion_coefficients": [float(v) for v in k]}
        r = np.linspace(1e-3, math.tan(theta_max), 200)
        target = self._distort_radius(r) / r - 1.0
        A = np.column_stack([r**2, r**4, r**6])
        k = np.linalg.lstsq(A, target, rcond=None)[0]
        p1, p2 = (float(v) for v in self.p)
        return {"intrinsics": intr, "distortion_model": "radial-tangential",
                "distortion_coefficients": [float(k[0]), float(k[1]), p1, p2, float(k[2])]}


class RealisticRenderer:
    """Renders frames of the floor through :class:`RealisticCamera`.

    Parameters
    ----------
    cam : RealisticCamera
    width, height : int
        Image size [px].
    exposure_time : float
        Exposure [s] (motion blur).
    blur_samples : int
        Renders averaged over the exposure.
    """

    def __init__(self, cam: RealisticCamera, width: int, height: int, exposure_time: float = 0.0,
                 blur_samples: int = 3):
        self.cam = cam
        self.width, self.height = int(width), int(height)
        self.exposure_time = float(exposure_time)
        self.blur_samples = max(int(blur_samples), 1) if exposure_time > 0 else 1
        self.lens = _Lens(cam, self.width, self.height)
        s = int(cam.supersample)
        offsets = (np.arange(s) + 0.5) / s - 0.5
        us = (np.arange(self.width)[:, None] + offsets[None, :]).ravel()
        vs = (np.arange(self.height)[:, None] + offsets[None, :]).ravel()
        uu, vv = np.meshgrid(us, vs)
        rays = self.lens.rays(np.column_stack([uu.ravel(), vv.ravel()])).reshape(len(vs), len(us), 3)
        self._rays = np.ascontiguousarray(rays, dtype=np.float32)
        self._row_time = vv[:, 0] / max(self.height - 1, 1) - 0.5  # -0.5 .. 0.5 of the readout
        pu = (np.arange(self.width) - self.lens.c[0]) / self.lens.f
        pv = (np.arange(self.height) - self.lens.c[1]) / self.lens.f
        r2 = pu[None, :] ** 2 + pv[:, None] ** 2
        r2max = float(r2.max())
        self._vignette = (1.0 - cam.vignetting * r2 / r2max).astype(np.float32)
        self._gain = 1.0
        self._texture: np.ndarray | None = None
        if cam.checker_size == 0 or cam.grain > 0:
            self._texture = mirror_tile(load_texture(cam.texture)).astype(np.float32) / 255.0

    def sensor_calibration(self) -> dict:
        """Intrinsics and distortion for ``cam0/sensor.yaml`` (see :attr:`RealisticCamera.calibration`)."""
        return self.lens.sensor_calibration(self.width, self.height)

    # ---------------------------------------------------------------- floor
    def _floor(self, px: float, py: float, dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
        """Floor brightness at ``(px + dx, py + dy)`` [m] (``dx, dy`` float32 offsets from the camera).

        Whole periods of the checkerboard and the photograph are removed from ``(px, py)`` in float64,
        so float32 keeps sub-texel precision anywhere on the floor.
        """
        cam = self.cam
        out = None
        if self._texture is not None:
            th, tw = self._texture.shape
            ox = np.float32(px / cam.texel_size - tw * math.floor(px / cam.texel_size / tw))
            oy = np.float32(py / cam.texel_size - th * math.floor(py / cam.texel_size / th))
            k = np.float32(1.0 / cam.texel_size)
            u = dx * k + ox
            v = dy * k + oy
            tex = cv2.remap(self._texture, u, v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
            if cam.checker_size == 0:
                return tex
            out = 1.0 + np.float32(cam.grain) * (tex - np.float32(0.5))
        period = 2.0 * cam.checker_size
        k = np.float32(1.0 / cam.checker_size)
        cx = np.float32((px - period * math.floor(px / period)) / cam.checker_size)
        cy = np.float32((py - period * math.floor(py / period)) / cam.checker_size)
        ix, iy = np.floor(dx * k + cx), np.floor(dy * k + cy)
        parity = (ix + iy).astype(np.int32) & 1
        board = np.where(parity > 0, np.float32(1.0), np.float32(1.0 - cam.checker_contrast))
        if cam.checker_squares:  # a finite board: square indices counted from the floor origin
            cols, rows = cam.checker_squares
            gx = ix + np.float32(round((px - (px - period * math.floor(px / period))) / cam.checker_size))
            gy = iy + np.float32(round((py - (py - period * math.floor(py / period))) / cam.checker_size))
            outside = (gx < 0) | (gx >= cols) | (gy < 0) | (gy >= rows)
            board = np.where(outside, np.float32(1.0), board)
        return board if out is None else out * board

    def _radiance(self, pose_at: Callable[[float], np.ndarray], t: float) -> tuple[np.ndarray, float]:
        """Supersampled floor radiance at exposure centre ``t`` and the mean camera height."""
        cam = self.cam
        hs, ws = self._rays.shape[:2]
        out = np.zeros((hs, ws), np.float32)
        times = [t] if self.blur_samples == 1 else list(np.linspace(t - self.exposure_time / 2,
                                                                    t + self.exposure_time / 2, self.blur_samples))
        bands = cam.bands if cam.rolling_shutter > 0 else 1
        edges = np.linspace(0, hs, bands + 1).astype(int)
        heights = []
        for ts in times:
            for b in range(bands):
                r0, r1 = edges[b], edges[b + 1]
                tb = ts + cam.rolling_shutter * float(np.mean(self._row_time[r0:r1])) if bands > 1 else ts
                T = pose_at(tb)
                R, p = T[:3, :3].astype(np.float32), T[:3, 3]
                heights.append(p[2])
                # the rays' floor offsets from the camera: (-h q_x / q_z, -h q_y / q_z), q = R ray
                q = cv2.transform(self._rays[r0:r1], R)
                qx, qy, qz = cv2.split(q)
                if float(qz.max()) >= -1e-6:
                    raise ValueError("a ray of the camera misses the floor: the lens sees the horizon")
                lam = cv2.divide(np.float32(-p[2]), qz)
                out[r0:r1] += self._floor(float(p[0]), float(p[1]), cv2.multiply(lam, qx), cv2.multiply(lam, qy))
        out /= len(times)
        return out, float(np.mean(heights))

    def frame(self, pose_at: Callable[[float], np.ndarray], t: float, rng: np.random.Generator) -> np.ndarray:
        """The 8-bit frame exposed about ``t``; ``pose_at(t)`` gives the camera pose ``T_WS`` (4x4)."""
        cam = self.cam
        radiance, h = self._radiance(pose_at, t)
        sigma = cam.supersample * (cam.defocus + cam.defocus_per_metre * abs(h - cam.focus_height))
        if sigma > 0.1:
            radiance = cv2.GaussianBlur(radiance, (0, 0), sigma)
        img = cv2.resize(radiance, (self.width, self.height), interpolation=cv2.INTER_AREA)
        grey = img * self._vignette * (cam.brightness * self._gain)
        noise = np.sqrt(cam.read_noise**2 + cam.shot_noise**2 * np.maximum(grey, 0.0))
        grey = grey + noise * rng.standard_normal(grey.shape).astype(np.float32)
        out = np.clip(np.rint(grey), 0, 255).astype(np.uint8)
        if cam.auto_exposure > 0:
            mean = max(float(out.mean()), 1.0)
            self._gain *= math.exp(cam.auto_exposure * math.log(cam.target_grey / mean))
        return out


def board_views(cam: RealisticCamera, width: int, height: int, n_views: int, distance: tuple[float, float],
                shift: float, seed: int = 1, tilt: float = 0.2) -> list[np.ndarray]:
    """Views of the finite board of ``cam`` (``checker_squares``) from above, for intrinsic calibration.

    Each view looks down at the board's centre shifted by up to ``shift`` metres, from ``distance``
    (a range, metres along the optical axis), rotated at random about the vertical and tilted by up to
    ``tilt`` rad about both horizontal axes, as a person waving a printed board under the camera would
    (tilted views are what separate the focal length from the distance).

    Returns
    -------
    list of ndarray
        The 8-bit frames (the board may be cut off or not found in some of them).
    """
    from scipy.spatial.transform import Rotation

    if len(cam.checker_squares) != 2 or cam.checker_size <= 0:
        raise ValueError("board views need a finite board: checker_size and checker_squares [cols, rows]")
    r = RealisticRenderer(cam, width, height)
    rng = np.random.default_rng(seed)
    centre = np.array(cam.checker_squares, float) / 2.0 * cam.checker_size
    views = []
    for _ in range(n_views):
        turn = Rotation.from_rotvec([rng.uniform(-tilt, tilt), rng.uniform(-tilt, tilt), rng.uniform(-np.pi, np.pi)])
        R = turn.as_matrix() @ np.diag([1.0, -1.0, -1.0])  # looking down, then tilted
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = [*(centre + rng.uniform(-shift, shift, 2)), 0.0]
        T[:3, 3] -= R[:, 2] * rng.uniform(*distance)  # back off along the optical axis
        views.append(r.frame(lambda t, T=T: T, 0.0, rng))
    return views
