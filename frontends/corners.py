"""Corner detection that adapts to the image size and texture, spread over the frame.

Fixed pixel values tuned on one image size do not carry over: a 320 x 240 frame needs closer corners
than a 640 x 360 one to find as many, and a 1280 x 720 frame can hold more. :class:`CornerPlan` scales
the settings of the reference size (640 x 360, where they are used unchanged):

* the minimum distance between corners and the structure-tensor block in proportion to the image
  diagonal;
* the number of corners with the image area (never fewer than at the reference size);
* a quality level lowered step by step (down to ``min_quality``) when too few corners come back, as
  on a coarse checkerboard or a blurred frame, so that the tracker has points to try before it falls
  back to a dense alignment;
* optionally, detection over a grid of cells: every cell that the strongest corners overall leave
  empty gets its own strongest corner (its quality judged within the cell) in place of the weakest of
  them, so that the corners cover the frame instead of crowding into its most textured or brightest
  part (a spread set fixes rotation and scale better and survives a part of the view going dark or
  leaving it). On an even texture every cell is already covered and nothing changes.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import cv2
import numpy as np

from frontends.detectors import DetectorSettings

#: the image size the frontends' pixel settings were chosen for
REFERENCE_SIZE = (360, 640)


@dataclass(frozen=True)
class CornerPlan:
    """Corner settings in effect for one image size (see :func:`plan_corners`).

    Attributes
    ----------
    scale : float
        Image diagonal over the reference diagonal.
    min_distance : float
        Minimum distance between corners [px of the full image].
    block_size : int
        Structure-tensor block [px of the detection image], odd.
    border : int
        Margin kept free of corners [px of the full image].
    max_corners : int
        Corners wanted after a full replenish.
    replenish_below : int
        Fewer surviving tracks than this trigger a new detection.
    region : tuple of int
        ``(x0, y0, x1, y1)``: the part of the image where corners are detected [px of the full image].
    """

    scale: float
    min_distance: float
    block_size: int
    border: int
    max_corners: int
    replenish_below: int
    region: tuple[int, int, int, int]

    def inside(self, pts: np.ndarray) -> np.ndarray:
        """Mask of the points (N x 2, full-image px) inside :attr:`region`."""
        x0, y0, x1, y1 = self.region
        pts = np.asarray(pts).reshape(-1, 2)
        return (pts[:, 0] >= x0) & (pts[:, 0] < x1) & (pts[:, 1] >= y0) & (pts[:, 1] < y1)


def plan_corners(shape: tuple[int, int], min_distance: float, block_size: int, border: int, max_corners: int,
                 replenish_below: int, central_region: float = 1.0) -> CornerPlan:
    """Scale reference-size corner settings to an image of ``shape`` (rows, cols).

    Parameters
    ----------
    shape : tuple of int
    min_distance, block_size, border, max_corners, replenish_below
        The settings for a 640 x 360 image.
    central_region : float
        Fraction of the width and height, about the centre, where corners are detected (1: all).
    """
    h, w = shape
    scale = math.hypot(h, w) / math.hypot(*REFERENCE_SIZE)
    area = (h * w) / float(REFERENCE_SIZE[0] * REFERENCE_SIZE[1])
    count = max(1.0, area * central_region**2)
    block = max(3, int(round(block_size * scale)) | 1)
    bx = max(int(round(border * scale)), int(round(0.5 * (1.0 - central_region) * w)), 4)
    by = max(int(round(border * scale)), int(round(0.5 * (1.0 - central_region) * h)), 4)
    return CornerPlan(
        scale=scale,
        min_distance=max(min_distance * scale, 6.0),
        block_size=block,
        border=max(int(round(border * scale)), 4),
        max_corners=int(round(max_corners * count)),
        replenish_below=int(round(replenish_below * count)),
        region=(bx, by, w - bx, h - by),
    )


def grid_shape(shape: tuple[int, int], cell: float) -> tuple[int, int]:
    """Rows and columns of a grid of cells about ``cell`` px wide over an image of ``shape``."""
    h, w = shape
    return max(1, int(round(h / cell))), max(1, int(round(w / cell)))


def spread_corners(image: np.ndarray, mask: np.ndarray, wanted: int, quality: float, min_quality: float,
                   min_distance: float, block_size: int, grid: tuple[int, int], enough: int) -> np.ndarray:
    """Shi-Tomasi corners of ``image`` spread over a ``grid`` of cells, lowering the quality if needed.

    Parameters
    ----------
    image : ndarray
        ``uint8`` detection image.
    mask : ndarray
        Where corners may lie (``uint8``, non-zero allowed).
    wanted : int
        Corners to return at most.
    quality : float
        First quality level (minimum eigenvalue relative to the strongest corner).
    min_quality : float
        Lowest quality level tried; the level is divided by 4 while fewer than ``enough`` corners
        come back.
    min_distance : float
        Minimum distance between corners [px of ``image``].
    block_size : int
        Structure-tensor block [px].
    grid : tuple of int
        Rows and columns of cells; every cell with texture gets at least one corner (up to half of
        ``wanted`` are given to otherwise empty cells).
    enough : int
        Corner count below which a lower quality level is tried.

    Returns
    -------
    ndarray, shape (N, 2), float32
        Corner positions in ``image`` pixels.
    """
    if wanted <= 0:
        return np.zeros((0, 2), np.float32)
    level = quality
    while True:
        # the candidates come back strongest first; four times the count leaves every cell a choice
        found = cv2.goodFeaturesToTrack(image, maxCorners=4 * wanted, qualityLevel=level, minDistance=min_distance,
                                        mask=mask, blockSize=block_size)
        pts = np.zeros((0, 2), np.float32) if found is None else found.reshape(-1, 2).astype(np.float32)
        if len(pts) >= enough or level <= min_quality:
            break
        level = max(level / 4.0, min_quality)
    if grid == (1, 1):
        return pts[:wanted]
    h, w = image.shape
    rows, cols = grid
    chosen = pts[:wanted]
    cell = (np.minimum(chosen[:, 1] * rows // h, rows - 1) * cols
            + np.minimum(chosen[:, 0] * cols // w, cols - 1)).astype(int)
    covered = np.zeros(rows * cols, bool)
    covered[cell] = True
    # every cell the strongest corners leave empty gets its own strongest corner, its quality relative to
    # the cell (a dim or low-contrast part of the frame), in place of the weakest corners overall; on an
    # even texture every cell is covered and nothing changes
    extra = []
    for c in np.flatnonzero(~covered)[: max(wanted // 2, 1)]:
        r, k = divmod(int(c), cols)
        y0, y1, x0, x1 = r * h // rows, (r + 1) * h // rows, k * w // cols, (k + 1) * w // cols
        sub_mask = np.ascontiguousarray(mask[y0:y1, x0:x1])
        if min(y1 - y0, x1 - x0) <= 2 * block_size or not sub_mask.any():
            continue
        found = cv2.goodFeaturesToTrack(np.ascontiguousarray(image[y0:y1, x0:x1]), maxCorners=1, qualityLevel=0.5,
                                        minDistance=min_distance, mask=sub_mask, blockSize=block_size)
        if found is not None:
            extra.append(found.reshape(-1, 2)[0] + np.array([x0, y0], np.float32))
    if not extra:
        return chosen
    keep = max(min(len(chosen), wanted - len(extra)), 0)
    return np.vstack([chosen[:keep], np.array(extra, np.float32)])


def new_corners(image: np.ndarray, existing: np.ndarray, plan: CornerPlan, margin: int, quality: float,
                min_quality: float, min_count: int, grid_cell: float) -> np.ndarray:
    """New Shi-Tomasi corners of a full-resolution ``uint8`` ``image``, away from the ``existing`` points.

    Corners are detected on the half-resolution image (``cv2.pyrDown``) by :func:`spread_corners`, inside
    ``plan.region`` less ``margin`` half-resolution pixels, and not in the cells of a grid of side
    ``plan.min_distance / 2`` that hold an existing point or neighbour one that does; up to
    ``plan.max_corners`` points in all.

    Parameters
    ----------
    image : ndarray
    existing : ndarray, shape (n, 2)
        Points already tracked [px of the full image].
    plan : CornerPlan
        The corner settings for this image size (:func:`plan_corners`).
    margin : int
        Margin kept inside the region [px of the half-resolution image].
    quality, min_quality : float
        First and lowest quality level (:func:`spread_corners`).
    min_count : int
        The quality level is lowered while fewer corners than this (or than wanted) come back.
    grid_cell : float
        Side of the cells over which the corners are spread [px of the full image] (0: no grid).

    Returns
    -------
    ndarray, shape (k, 2), float32
        The new corners [px of the full image].
    """
    half = cv2.pyrDown(image)
    hh, hw = half.shape
    x0, y0, x1, y1 = plan.region
    mask = np.zeros((hh, hw), np.uint8)
    mask[y0 // 2 + margin : (y1 + 1) // 2 - margin, x0 // 2 + margin : (x1 + 1) // 2 - margin] = 255
    cell = max(int(plan.min_distance // 2), 1)
    if len(existing):
        # blank the grid cells (and their neighbours) holding an existing track
        gi = np.clip((existing[:, 1] / 2) // cell, 0, (hh - 1) // cell).astype(int)
        gj = np.clip((existing[:, 0] / 2) // cell, 0, (hw - 1) // cell).astype(int)
        occ = np.zeros(((hh - 1) // cell + 3, (hw - 1) // cell + 3), bool)
        for di in (0, 1, 2):
            for dj in (0, 1, 2):
                occ[gi + di, gj + dj] = True
        occ = occ[1:-1, 1:-1]
        big = np.repeat(np.repeat(occ, cell, axis=0), cell, axis=1)[:hh, :hw]
        mask[big] = 0
    wanted = plan.max_corners - len(existing)
    if wanted <= 0:
        return np.zeros((0, 2), np.float32)
    grid = grid_shape((hh, hw), grid_cell / 2) if grid_cell > 0 else (1, 1)
    corners = spread_corners(half, mask, wanted, quality, min_quality, plan.min_distance / 2, plan.block_size, grid,
                             min(wanted, min_count))
    return corners * 2.0


#: spread of grey levels (95th minus 5th percentile) of the frames the FAST threshold was chosen on
REFERENCE_CONTRAST = 120.0


def _odd(x: float, least: int = 3) -> int:
    return max(least, 2 * int(round((x - 1.0) / 2.0)) + 1)


def image_contrast(image: np.ndarray) -> float:
    """95th minus 5th percentile of the grey levels of ``image`` (every fourth pixel each way)."""
    sample = image[::4, ::4]
    lo, hi = np.percentile(sample, (5.0, 95.0))
    return float(hi - lo)


def scale_detector(settings: DetectorSettings, image: np.ndarray) -> DetectorSettings:
    """The feature frontend's detector settings, chosen for 640 x 360, scaled to ``image``.

    As :func:`plan_corners` does for KLT: the detection level, non-maximum-suppression neighbourhood
    and structure-tensor block follow the image diagonal (a 320 x 240 frame is searched at full
    resolution with about the same spacing in full-resolution pixels as a 640 x 360 frame at half
    resolution), and the number of corners the image area (never fewer than at the reference size).
    Harris and Shi-Tomasi thresholds are relative to the strongest response already; FAST's absolute
    intensity threshold is lowered in proportion to the image's contrast when it is below
    :data:`REFERENCE_CONTRAST` (never below a quarter, nor 5 grey levels). At 640 x 360 with good
    contrast the settings come back unchanged.
    """
    h, w = image.shape[:2]
    scale = math.hypot(h, w) / math.hypot(*REFERENCE_SIZE)
    area = max(1.0, (h * w) / float(REFERENCE_SIZE[0] * REFERENCE_SIZE[1]))
    changes: dict = {}
    if abs(scale - 1.0) > 0.02:
        level = int(np.clip(settings.level + round(math.log2(scale)), 0, settings.level + 2))
        factor = scale * (1 << settings.level) / (1 << level)  # old detection px -> new detection px
        changes.update(level=level, block_size=_odd(settings.block_size * factor),
                       neighbourhood=tuple(_odd(v * factor, 1) for v in settings.neighbourhood),
                       max_corners=int(round(settings.max_corners * area)))
    if settings.method == "fast":
        ratio = min(1.0, max(0.25, image_contrast(image) / REFERENCE_CONTRAST))
        threshold = int(round(settings.fast_threshold * ratio))
        changes["fast_threshold"] = max(5, min(int(settings.fast_threshold), threshold))
    return dataclasses.replace(settings, **changes) if changes else settings
