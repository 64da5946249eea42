"""Exact ray casting of the floor plane into a distorted camera image.

For every (sub-)pixel the normalised ray ``r = (x, y, 1)`` of the *distorted* pixel is computed once
(:meth:`CameraModel.pixel_rays`, an iterative undistortion). For a camera pose ``T_WS = (R, t)`` the
ray leaves the camera centre along ``q = R r`` and meets the floor ``z = 0`` at::

    X = t_x - t_z q_x / q_z,    Y = t_y - t_z q_y / q_z

which is a homography of ``r``::

    [X, Y, 1]^T ~ H r,   H = [t_x R_2 - t_z R_0;  t_y R_2 - t_z R_1;  R_2]     (R_i: row i of R)

Composed with the floor-to-texture scaling (:mod:`fusion_vo.simulation.floor`), one transform of the
precomputed rays gives the texture coordinates of every pixel and one ``cv2.remap`` (bilinear) samples
the texture. The transform is affine in every frame: for a level camera ``H``'s last row is
``(0, 0, h22)``; a tilted camera only turns about the vertical as the robot drives, so its rays are
turned by the tilt and divided by their z once, after which the map is affine again
(:meth:`Renderer._texture_maps`). Supersampling renders ``s x s`` rays per pixel and
averages them (box filter), which removes aliasing and the phase-dependent blur of bilinear sampling.
Motion blur averages renders at poses spread over the exposure time.

A repeating texture is sampled from a copy padded with its own wrap-around, wide enough to hold the
whole footprint of the image once whole periods are removed: the same values as ``BORDER_WRAP``, but on
``remap``'s fast path for every pixel.

The texture coordinates are float32; the integer number of texture periods under the camera is
removed in float64 first, so precision does not degrade far from the origin.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence

import cv2
import numpy as np

from fusion_vo.geometry.camera import CameraModel
from fusion_vo.simulation.floor import Floor, Rectangle

logger = logging.getLogger(__name__)


def floor_homography(T_WS: np.ndarray) -> np.ndarray:
    """The homography from normalised rays ``(x, y, 1)`` to floor points ``(X, Y, 1)`` for pose ``T_WS``."""
    R = np.asarray(T_WS, dtype=np.float64)[:3, :3]
    t = np.asarray(T_WS, dtype=np.float64)[:3, 3]
    return np.vstack([t[0] * R[2] - t[2] * R[0], t[1] * R[2] - t[2] * R[1], R[2]])


class Renderer:
    """Renders a :class:`Floor` seen by a :class:`CameraModel` from arbitrary camera poses.

    Parameters
    ----------
    camera : CameraModel
    floor : Floor
    supersample : int
        Rays per pixel along each axis (1 = one ray through the pixel centre).
    """

    def __init__(self, camera: CameraModel, floor: Floor, supersample: int = 2):
        if supersample < 1:
            raise ValueError("supersample must be >= 1")
        self.camera = camera
        self.floor = floor
        self.supersample = int(supersample)
        rays = camera.pixel_rays(self.supersample)
        self._rays = np.ascontiguousarray(rays, dtype=np.float32)
        h, w = rays.shape[:2]
        # homogeneous rays of the image border: their sign tells whether all rays meet the floor, and
        # their floor points bound the floor seen by the whole image
        border = np.concatenate([rays[0, :], rays[-1, :], rays[:, 0], rays[:, -1]])
        self._border_rays = np.column_stack([border, np.ones(len(border))])
        self._padded: np.ndarray | None = None
        self._pad = 0
        self._turned_rays: tuple[np.ndarray, np.ndarray] | None = None  # (M, p) of a tilted camera
        logger.debug("renderer ready: %dx%d rays", w, h)

    def _world_to_texture(self, centre: np.ndarray) -> np.ndarray:
        """The affine map floor metres -> texture coordinates, removing whole periods under ``centre``."""
        fl = self.floor
        s = fl.texel_size
        shift = np.zeros(2)
        if fl.wrap:
            th, tw = fl.texture.shape
            shift[0] = math.floor((centre[0] - fl.origin[0]) / s / tw) * tw
            shift[1] = math.floor((centre[1] - fl.origin[1]) / s / th) * th
        return np.array([[1.0 / s, 0.0, -fl.origin[0] / s - shift[0]],
                         [0.0, 1.0 / s, -fl.origin[1] / s - shift[1]],
                         [0.0, 0.0, 1.0]])

    def _padded_texture(self, H_tex: np.ndarray) -> tuple[np.ndarray, int] | None:
        """The repeating texture extended by whole-texel wrap-around margins that hold every sample.

        ``remap`` with ``BORDER_WRAP`` takes a slow per-pixel path for every sample near or beyond the
        texture edge, which after removing whole periods is a large part of the image. Sampling a
        texture padded with its own wrap-around gives the same values on the fast path. Returns
        ``(texture, pad)`` or None when the margin needed exceeds half the texture size (the caller
        then wraps).
        """
        th, tw = self.floor.texture.shape
        outline = self._border_rays @ H_tex.T
        outline = outline[:, :2] / outline[:, 2:3]
        lo = outline.min(axis=0)
        hi = outline.max(axis=0)
        need = max(-lo[0], -lo[1], hi[0] - (tw - 1), hi[1] - (th - 1), 0.0) + 2.0
        if need > max(tw, th) // 2:
            return None
        if need > self._pad:
            self._pad = min(int(math.ceil(need * 1.25 / 32.0)) * 32, max(tw, th) // 2)
            self._padded = cv2.copyMakeBorder(self.floor.texture, self._pad, self._pad, self._pad, self._pad,
                                              cv2.BORDER_WRAP)
            logger.debug("texture padded by %d texels", self._pad)
        return self._padded, self._pad

    def _transform_rays(self, H: np.ndarray) -> np.ndarray:
        """``H`` applied to every ray (float32, shape of the ray grid)."""
        if H[2, 0] == 0.0 and H[2, 1] == 0.0:  # a level camera: the map is affine, no division needed
            return cv2.transform(self._rays, H[:2] / H[2, 2])
        return cv2.perspectiveTransform(self._rays, H)

    def _texture_maps(self, T_WS: np.ndarray, to_tex: np.ndarray) -> np.ndarray:
        """Texture coordinates of every ray for camera pose ``T_WS`` (float32, shape of the ray grid).

        A robot turns its camera about the vertical only: ``R_WS = R_z(psi) M`` with ``M`` the camera
        rotation of the first pose rendered, whenever the last rows of ``R_WS`` and ``M`` agree. With
        the rays turned by ``M`` and divided by their z once, ``p = (M r)_xy / (M r)_z``, the floor
        point of every ray is affine in ``p``::

            X_xy = t_xy - t_z R_z(psi)_2x2 p

        so one affine ``cv2.transform`` replaces the perspective division in every frame.
        """
        R = T_WS[:3, :3]
        t = T_WS[:3, 3]
        if R[2, 0] == 0.0 and R[2, 1] == 0.0:  # a level camera: the map is affine in the rays themselves
            return self._transform_rays(to_tex @ floor_homography(T_WS))
        if self._turned_rays is None:
            rays = np.concatenate([self._rays.astype(np.float64), np.ones(self._rays.shape[:2] + (1,))], axis=2)
            m = rays @ R.T
            self._turned_rays = (R.copy(), np.ascontiguousarray(m[..., :2] / m[..., 2:3], dtype=np.float32))
        M, p = self._turned_rays
        if not np.array_equal(R[2], M[2]):  # another tilt than the one prepared
            return self._transform_rays(to_tex @ floor_homography(T_WS))
        turn = (R @ M.T)[:2, :2]
        A = to_tex[:2, :2] @ (-t[2] * turn)
        b = to_tex[:2, :2] @ t[:2] + to_tex[:2, 2]
        return cv2.transform(p, np.column_stack([A, b]))

    def radiance(self, T_WS: np.ndarray) -> np.ndarray:
        """The floor intensity seen through every pixel from pose ``T_WS`` (float32, no photometric effects).

        Parameters
        ----------
        T_WS : ndarray, shape (4, 4)
            Camera pose in the world (camera-to-world).

        Returns
        -------
        ndarray, shape (height, width), float32
            Pixels whose ray misses the floor are ``floor.border_value``.
        """
        T_WS = np.asarray(T_WS, dtype=np.float64)
        fl = self.floor
        H = floor_homography(T_WS)
        sees_horizon = bool(np.any(self._border_rays @ T_WS[2, :3] > -1e-6))
        covered, rects = self._featureless_in_view(H, sees_horizon)
        if covered:  # the whole view is flat grey floor
            return np.full((self.camera.height, self.camera.width), fl.featureless_value, dtype=np.float32)
        to_tex = self._world_to_texture(T_WS[:2, 3])
        padded = self._padded_texture(to_tex @ H) if fl.wrap and not sees_horizon else None
        if padded is not None:
            texture, pad = padded
            to_tex[:2, 2] += pad
            maps = self._texture_maps(T_WS, to_tex)
            img = cv2.remap(texture, maps, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        else:
            maps = self._texture_maps(T_WS, to_tex) if not sees_horizon else self._transform_rays(to_tex @ H)
            # remap needs coordinates well inside the int16 range of its fixed-point maps
            img = cv2.remap(fl.texture, np.clip(maps, -30000.0, 30000.0), None, cv2.INTER_LINEAR,
                            borderMode=cv2.BORDER_WRAP if fl.wrap else cv2.BORDER_CONSTANT,
                            borderValue=float(fl.border_value))
        for rect in rects:
            self._paint_featureless(img, maps, to_tex, rect)
        if sees_horizon:  # some rays miss the floor: mask them
            miss = (self._rays.reshape(-1, 2) @ T_WS[2, :2].astype(np.float32) + np.float32(T_WS[2, 2])) > -1e-6
            img.reshape(-1)[miss] = fl.border_value
        if self.supersample > 1:
            img = cv2.resize(img, (self.camera.width, self.camera.height), interpolation=cv2.INTER_AREA)
        return img

    def _featureless_in_view(self, H: np.ndarray, sees_horizon: bool) -> tuple[bool, list[Rectangle]]:
        """Whether one featureless rectangle fills the whole view, and those that reach into it.

        The floor points of the border rays bound the floor seen by the whole image: the view is the
        image of the (sub-)pixel grid's outline, so its bounding box is that of its border.
        """
        fl = self.floor
        if not fl.featureless or sees_horizon:  # no bound on a view that reaches the horizon
            return False, list(fl.featureless)
        corners = self._border_rays @ H.T
        corners = corners[:, :2] / corners[:, 2:3]
        lo = corners.min(axis=0)
        hi = corners.max(axis=0)
        near = []
        for rect in fl.featureless:
            if (rect.x_min + fl.edge / 2 <= lo[0] and hi[0] <= rect.x_max - fl.edge / 2
                    and rect.y_min + fl.edge / 2 <= lo[1] and hi[1] <= rect.y_max - fl.edge / 2):
                return True, [rect]  # every ray is at least edge / 2 inside: fully flat
            if not (rect.x_min > hi[0] + fl.edge or rect.x_max < lo[0] - fl.edge
                    or rect.y_min > hi[1] + fl.edge or rect.y_max < lo[1] - fl.edge):
                near.append(rect)
        return False, near

    def _paint_featureless(self, img: np.ndarray, maps: np.ndarray, to_tex: np.ndarray, rect: Rectangle) -> None:
        """Blend the flat grey of ``rect`` into ``img`` (at full ray resolution).

        ``alpha = clip(d / edge + 1/2, 0, 1)`` with ``d`` the signed distance inside the rectangle
        (its smallest distance to a side), computed from the texture coordinates ``maps`` of the rays,
        which ``to_tex`` (a scaling and shift) relates to the floor.
        """
        fl = self.floor
        k = to_tex[0, 0]  # texels per metre
        u, v = cv2.split(maps)
        inside = u - np.float32(k * rect.x_min + to_tex[0, 2])
        np.minimum(inside, np.float32(k * rect.x_max + to_tex[0, 2]) - u, out=inside)
        np.minimum(inside, v - np.float32(k * rect.y_min + to_tex[1, 2]), out=inside)
        np.minimum(inside, np.float32(k * rect.y_max + to_tex[1, 2]) - v, out=inside)
        inside *= np.float32(1.0 / (k * max(fl.edge, 1e-9)))
        inside += np.float32(0.5)
        np.clip(inside, 0.0, 1.0, out=inside)
        flat = np.float32(fl.featureless_value) - img
        flat *= inside
        img += flat

    def radiance_blurred(self, poses: Sequence[np.ndarray]) -> np.ndarray:
        """The mean of :meth:`radiance` over several poses (motion blur over an exposure)."""
        acc = self.radiance(poses[0])
        for T in poses[1:]:
            acc += self.radiance(T)
        if len(poses) > 1:
            acc *= np.float32(1.0 / len(poses))
        return acc


def render_frame(texture: np.ndarray | Floor, camera: CameraModel, T_WS: np.ndarray, *,
                 texel_size: float | None = None, origin: tuple[float, float] = (0.0, 0.0),
                 wrap: bool = False, border_value: float = 0.0, supersample: int = 2) -> np.ndarray:
    """Render one ``uint8`` image of a textured floor (no noise or other photometric effects).

    Convenient for single images (a chessboard lying on the floor, a test pattern); for many frames
    build a :class:`Renderer` once, which precomputes the pixel rays.

    Parameters
    ----------
    texture : ndarray or Floor
        A grey image laid on the floor (texel ``(0, 0)`` centred at ``origin``), or a ready Floor.
    camera : CameraModel
    T_WS : ndarray, shape (4, 4)
        Camera pose in the world; the floor is the plane ``z = 0``.
    texel_size : float
        Floor size of one texture pixel [m] (required unless ``texture`` is a Floor).
    origin : tuple of float
        World position of the centre of texel ``(0, 0)``.
    wrap : bool
        Repeat the texture (it should be seamless) or show ``border_value`` around it.
    border_value : float
        Intensity where there is no texture.
    supersample : int
        Rays per pixel along each axis.

    Returns
    -------
    ndarray, shape (camera.height, camera.width), uint8
    """
    if isinstance(texture, Floor):
        floor = texture
    else:
        if texel_size is None:
            raise ValueError("texel_size is required with a texture image")
        floor = Floor.from_image(texture, texel_size, seamless=False, origin=origin, border_value=border_value)
        floor.wrap = wrap
    img = Renderer(camera, floor, supersample).radiance(T_WS)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)
