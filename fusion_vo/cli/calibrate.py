"""``fusion-vo calibrate``: camera intrinsics, the camera over the floor, the lever arm and the wheels.

Each calibration prints its values with their standard deviations and writes the ``sensor.yaml`` file of
the recording layout it determines (``cam0/sensor.yaml`` or ``wheel0/sensor.yaml``).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from fusion_vo.errors import InputError


def register(sub) -> None:
    p = sub.add_parser("calibrate", help="calibrate the camera (intrinsics, height, tilt, lever arm) and the wheels",
                       description="Calibrations that write the sensor.yaml files of a recording.")
    kinds = p.add_subparsers(dest="kind", metavar="KIND")
    kinds.required = True

    q = kinds.add_parser("intrinsics", help="focal length, principal point and distortion from chessboard images")
    q.add_argument("images", nargs="+", metavar="IMAGE", help="images of a chessboard in varied poses")
    _board_options(q)
    q.add_argument("--model", choices=["pinhole", "fisheye"], default="pinhole",
                   help="pinhole with radial-tangential distortion, or fisheye (equidistant)")
    q.add_argument("--out", required=True, metavar="FILE",
                   help="cam0/sensor.yaml to write (its T_BS and rate are kept if it exists)")
    q.set_defaults(func=run_intrinsics)

    q = kinds.add_parser("floor", help="camera height, tilt and lever arm from one image of a chessboard on the floor")
    q.add_argument("image", metavar="IMAGE")
    q.add_argument("--intrinsics", required=True, metavar="YAML", help="cam0/sensor.yaml with the intrinsics")
    _board_options(q)
    q.add_argument("--board-origin", default="0,0", metavar="X,Y",
                   help="body-frame position of the board's first inner corner [m] (default 0,0)")
    q.add_argument("--board-yaw", type=float, default=0.0, metavar="DEG",
                   help="direction of the board's rows from body x [deg] (default 0)")
    q.add_argument("--out", required=True, metavar="FILE", help="cam0/sensor.yaml to write with the measured T_BS")
    q.set_defaults(func=run_floor)

    p.set_defaults(func=lambda args: p.print_help() or 2)


def _board_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--board", required=True, metavar="COLSxROWS", help="inner corners of the chessboard, e.g. 9x6")
    p.add_argument("--square", required=True, type=float, metavar="METRES", help="side of one square [m]")


def _pair(text: str, name: str) -> tuple[float, float]:
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise InputError(f"{name} needs X,Y in metres, got '{text}'") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise InputError(f"{name} must be finite, got '{text}'")
    return x, y


def run_intrinsics(args: argparse.Namespace) -> int:
    from fusion_vo.calibration.chessboard import Board
    from fusion_vo.calibration.intrinsics import calibrate_images
    from fusion_vo.geometry.camera import CameraModel

    board = Board.parse(args.board, args.square)
    result = calibrate_images(args.images, board, args.model)
    out = Path(args.out)
    base = CameraModel.from_yaml(out) if out.is_file() else None
    print(result.summary())
    result.to_camera(base).write_yaml(out)
    print(f"-> {out}" + (" (T_BS and rate kept)" if base is not None else ""))
    return 0


def run_floor(args: argparse.Namespace) -> int:
    from fusion_vo.calibration.chessboard import Board, detect_corners, read_image
    from fusion_vo.calibration.floor import floor_pose
    from fusion_vo.geometry.camera import CameraModel

    board = Board.parse(args.board, args.square)
    camera = CameraModel.from_yaml(args.intrinsics)
    img = read_image(args.image)
    if (img.shape[1], img.shape[0]) != (camera.width, camera.height):
        raise InputError(f"image is {img.shape[1]}x{img.shape[0]} but {args.intrinsics} is for "
                         f"{camera.width}x{camera.height}", args.image)
    corners = detect_corners(img, board)
    if corners is None:
        raise InputError(f"no {board.cols}x{board.rows} chessboard (inner corners) found", args.image)
    result = floor_pose(corners, camera, board, _pair(args.board_origin, "--board-origin"), args.board_yaw)
    print(result.summary())
    camera.T_BS = result.T_BS
    camera.write_yaml(args.out)
    print(f"-> {args.out}")
    return 0
