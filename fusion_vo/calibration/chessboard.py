"""Chessboard targets: the board's geometry and corner detection in images.

A board is described by its number of *inner* corners ``cols x rows`` (as OpenCV counts them: a board
of 10 x 7 squares has 9 x 6 inner corners) and the side of one square in metres. Its corners lie in the
board frame F at::

    X_F(i, j) = (i * square, j * square, 0),   i = 0..cols-1 (fast index), j = 0..rows-1

which is the order in which :func:`detect_corners` returns the image corners. A detection can start
at either end of the board (the pattern is symmetric under a half turn, and a square board also under
quarter turns, and a detector may number it in either handedness); :func:`board_orderings` lists the
equivalent orderings so that a caller with prior knowledge of the view can pick the right one.
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from fusion_vo.errors import InputError, check_file
from fusion_vo.recording.reader import decode_image

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class Board:
    """A planar chessboard.

    Attributes
    ----------
    cols, rows : int
        Inner corners along the board's x and y axes.
    square : float
        Side of one square [m].
    """

    cols: int
    rows: int
    square: float

    def __post_init__(self) -> None:
        if self.cols < 2 or self.rows < 2:
            raise InputError(f"a board needs at least 2 x 2 inner corners, got {self.cols} x {self.rows}")
        if not (self.square > 0 and np.isfinite(self.square)):
            raise InputError(f"the square size must be a positive length in metres, got {self.square}")

    @classmethod
    def parse(cls, spec: str, square: float) -> "Board":
        """Board from a ``"COLSxROWS"`` string of inner corners and the square size [m]."""
        m = re.fullmatch(r"\s*(\d+)\s*[xX*]\s*(\d+)\s*", spec)
        if not m:
            raise InputError(f"board '{spec}' is not COLSxROWS (inner corners, e.g. 9x6)")
        return cls(int(m.group(1)), int(m.group(2)), float(square))

    @property
    def pattern_size(self) -> tuple[int, int]:
        return (self.cols, self.rows)

    @property
    def n_corners(self) -> int:
        return self.cols * self.rows

    def object_points(self) -> np.ndarray:
        """Corner positions in the board frame, shape ``(cols*rows, 3)`` [m]."""
        i, j = np.meshgrid(np.arange(self.cols), np.arange(self.rows))
        pts = np.zeros((self.n_corners, 3))
        pts[:, 0] = i.ravel() * self.square
        pts[:, 1] = j.ravel() * self.square
        return pts


def board_orderings(board: Board, mirrored: bool = False) -> list[np.ndarray]:
    """Index permutations of a detection that describe the same physical board.

    ``corners[perm]`` is an equally valid detection of the board: the identity, the half turn, and for a
    square board the two quarter turns. With ``mirrored`` the reflections are added too (a detector may
    number the corners of a board seen from above in either handedness; only the orderings whose pose
    puts the camera in front of the board are physical).
    """
    idx = np.arange(board.n_corners).reshape(board.rows, board.cols)
    grids = [idx, idx[::-1, ::-1]]
    if board.cols == board.rows:
        grids += [np.rot90(idx, 1), np.rot90(idx, -1)]
    if mirrored:
        grids += [g[:, ::-1] for g in grids]
    return [g.ravel() for g in grids]


def to_grey(image: np.ndarray) -> np.ndarray:
    """8-bit grey version of a grey or colour, 8- or 16-bit image."""
    img = np.asarray(image)
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY)
    if img.dtype != np.uint8:
        img = cv2.normalize(img.astype(np.float32), None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    return img


def detect_corners(image: np.ndarray, board: Board) -> np.ndarray | None:
    """Inner corners of ``board`` in ``image`` with sub-pixel accuracy.

    Tries OpenCV's sector-based detector (``findChessboardCornersSB``) first and falls back to the
    classic detector refined by ``cornerSubPix``.

    Returns
    -------
    ndarray, shape (cols*rows, 2), or None when the board is not found.
    """
    grey = to_grey(image)
    flags = cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
    found, corners = cv2.findChessboardCornersSB(grey, board.pattern_size, flags=flags)
    if found:
        return corners.reshape(-1, 2).astype(np.float64)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    found, corners = cv2.findChessboardCorners(grey, board.pattern_size, flags=flags)
    if not found:
        return None
    # refinement window: a third of the smallest corner spacing, at least 2 px
    pts = corners.reshape(board.rows, board.cols, 2)
    spacing = min(np.linalg.norm(np.diff(pts, axis=0), axis=2).min(), np.linalg.norm(np.diff(pts, axis=1), axis=2).min())
    win = int(max(2, min(11, spacing / 3)))
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-3)
    corners = cv2.cornerSubPix(grey, corners.astype(np.float32), (win, win), (-1, -1), criteria)
    return corners.reshape(-1, 2).astype(np.float64)


def read_image(path: str | Path) -> np.ndarray:
    """Read an image file unchanged (grey or colour, 8 or 16 bit); :class:`InputError` if unreadable."""
    path = check_file(path)  # names a folder, a broken link ... as such
    try:  # decoded from bytes: cv2.imread fails on paths that are not valid UTF-8
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read image file ({exc.strerror})", path) from None
    img = decode_image(data)
    if img is None or img.size == 0:
        raise InputError("not a readable image", path)
    return img
