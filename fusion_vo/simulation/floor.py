"""The floor: a photographed texture laid on the plane z = 0 of the world.

A floor point ``(x, y)`` [m] has texture coordinates (pixel centres at integers, OpenCV's convention)::

    u = (x - x0) / texel_size,    v = (y - y0) / texel_size

where ``(x0, y0)`` is the world position of the centre of texel ``(0, 0)``. A seamless texture repeats
with period ``texture.shape * texel_size``; a non-repeating one (a chessboard for calibration) shows a
constant ``border_value`` outside.

The photographs are scikit-image's ``gravel``, ``grass`` and ``brick`` (512 x 512 grey, public domain,
CC0). They are made seamless by mirror tiling: the image and its left-right, up-down and both-way
mirrors form a 2 x 2 block whose opposite edges match, so wrapping around shows no seam.

Featureless stretches are world-space rectangles painted a flat grey, blended over ``edge`` metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

TEXTURES = ("gravel", "grass", "brick")


def load_texture(name: str) -> np.ndarray:
    """One of scikit-image's photographed textures as a 2-D ``uint8`` array.

    Parameters
    ----------
    name : {"gravel", "grass", "brick"}
    """
    if name not in TEXTURES:
        raise ValueError(f"unknown texture {name!r}; choose one of {', '.join(TEXTURES)}")
    import skimage.data

    image = getattr(skimage.data, name)()
    if image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    return np.ascontiguousarray(image)


def mirror_tile(image: np.ndarray) -> np.ndarray:
    """A seamless 2x2 mirror tiling of ``image`` (twice its size in each direction)."""
    top = np.hstack([image, image[:, ::-1]])
    return np.ascontiguousarray(np.vstack([top, top[::-1, :]]))


@dataclass(frozen=True)
class Rectangle:
    """An axis-aligned rectangle of the floor in world metres."""

    x_min: float
    y_min: float
    x_max: float
    y_max: float

    def __post_init__(self) -> None:
        if not (self.x_max > self.x_min and self.y_max > self.y_min):
            raise ValueError(f"empty rectangle {self}")


@dataclass
class Floor:
    """A textured floor plane.

    Parameters
    ----------
    texture : ndarray
        2-D ``float32`` intensities (0..255).
    texel_size : float
        Size of one texel on the floor [m].
    origin : tuple of float
        World position ``(x0, y0)`` of the centre of texel ``(0, 0)`` [m].
    wrap : bool
        Repeat the texture (seamless textures) or show ``border_value`` outside it.
    border_value : float
        Intensity outside a non-repeating texture.
    featureless : list of Rectangle
        Stretches of flat grey floor.
    featureless_value : float
        Their intensity (default: the texture mean).
    edge : float
        Width of the blend from texture to flat grey [m].
    """

    texture: np.ndarray
    texel_size: float
    origin: tuple[float, float] = (0.0, 0.0)
    wrap: bool = True
    border_value: float = 0.0
    featureless: list[Rectangle] = field(default_factory=list)
    featureless_value: float | None = None
    edge: float = 0.002

    def __post_init__(self) -> None:
        self.texture = np.ascontiguousarray(self.texture, dtype=np.float32)
        if self.texture.ndim != 2:
            raise ValueError("texture must be a 2-D grey image")
        if not self.texel_size > 0:
            raise ValueError("texel_size must be positive")
        if self.featureless_value is None:
            self.featureless_value = float(self.texture.mean())

    @classmethod
    def from_image(cls, image: np.ndarray, texel_size: float, *, seamless: bool = True, upsample: int = 1,
                   **kwargs) -> "Floor":
        """A floor from any grey image.

        Parameters
        ----------
        image : ndarray
            Grey (or colour, converted to grey) image.
        texel_size : float
            Floor size of one pixel of ``image`` [m].
        seamless : bool
            Mirror-tile the image so it repeats without seams (``wrap=True``); otherwise the image is
            shown once and ``border_value`` around it.
        upsample : int
            Resample the texture ``upsample`` times finer with bicubic interpolation, so that bilinear
            sampling at render time adds less blur.
        **kwargs
            Further :class:`Floor` fields (``origin``, ``featureless`` ...).
        """
        img = np.asarray(image)
        if img.ndim == 3:
            img = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY if img.shape[2] == 3 else cv2.COLOR_RGBA2GRAY)
        unit_range = img.dtype.kind == "f" and float(img.max()) <= 1.0
        img = img.astype(np.float32) * (255.0 if unit_range else 1.0)
        if seamless:
            img = mirror_tile(img)
        size = float(texel_size)
        if upsample > 1:
            h, w = img.shape
            if seamless:  # resample with wrap-around so the seam stays invisible
                pad = 4
                padded = cv2.copyMakeBorder(img, pad, pad, pad, pad, cv2.BORDER_WRAP)
                big = cv2.resize(padded, None, fx=upsample, fy=upsample, interpolation=cv2.INTER_CUBIC)
                img = big[pad * upsample:(pad + h) * upsample, pad * upsample:(pad + w) * upsample]
            else:
                img = cv2.resize(img, None, fx=upsample, fy=upsample, interpolation=cv2.INTER_CUBIC)
            # new texel j sits at old texel coordinate (j + 0.5) / upsample - 0.5
            origin = kwargs.pop("origin", (0.0, 0.0))
            shift = 0.5 * size - 0.5 * size / upsample
            kwargs["origin"] = (origin[0] - shift, origin[1] - shift)
            size /= upsample
        return cls(texture=img, texel_size=size, wrap=seamless, **kwargs)

    @classmethod
    def photographed(cls, name: str = "gravel", texel_size: float = 0.00025, upsample: int = 2,
                     **kwargs) -> "Floor":
        """A seamless floor from one of scikit-image's photographs (see :func:`load_texture`)."""
        return cls.from_image(load_texture(name), texel_size, seamless=True, upsample=upsample, **kwargs)

    @property
    def period(self) -> tuple[float, float]:
        """Repeat period ``(px, py)`` of the texture on the floor [m]."""
        h, w = self.texture.shape
        return w * self.texel_size, h * self.texel_size
