"""``fusion-vo calibrate``: camera intrinsics, the camera over the floor, the lever arm, the camera's heading noise
and the wheels.

Each calibration prints its values with their standard deviations. ``intrinsics`` and ``floor`` always
write the ``cam0/sensor.yaml`` named by ``--out``; ``height``, ``lever-arm``, ``camera-noise`` and ``wheels``
write a ``sensor.yaml`` (``cam0/`` or ``wheel0/``) only when ``--out`` names one, so a recording is never changed
unless asked. Files are replaced atomically and follow the umask.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from fusion_vo.cli.arguments import finite_number, non_negative_number, positive_number
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
    q.add_argument("--radial-terms", type=int, choices=[2, 3], default=2,
                   help="radial distortion terms of the pinhole model: 2 (k3 fixed at 0) or 3, for strong "
                        "barrel lenses with views reaching the image corners")
    q.add_argument("--out", required=True, metavar="FILE",
                   help="cam0/sensor.yaml to write (its T_BS and rate are kept if it exists)")
    q.set_defaults(func=run_intrinsics)

    q = kinds.add_parser("floor", help="camera height, tilt and lever arm from one image of a chessboard on the floor")
    q.add_argument("image", metavar="IMAGE")
    q.add_argument("--intrinsics", required=True, metavar="YAML", help="cam0/sensor.yaml with the intrinsics")
    _board_options(q)
    q.add_argument("--board-origin", default="0,0", metavar="X,Y",
                   help="body-frame position of the board's first inner corner [m] (default 0,0)")
    q.add_argument("--board-yaw", type=finite_number, default=0.0, metavar="DEG",
                   help="direction of the board's rows from body x [deg] (default 0)")
    q.add_argument("--out", required=True, metavar="FILE", help="cam0/sensor.yaml to write with the measured T_BS")
    q.set_defaults(func=run_floor)

    q = kinds.add_parser("height", help="camera height from a straight drive of known length (thesis method)")
    q.add_argument("seq", metavar="SEQ", help="recording of a straight drive")
    q.add_argument("--distance", required=True, type=positive_number, metavar="M", help="driven distance [m]")
    q.add_argument("--distance-std", type=non_negative_number, default=0.001, metavar="M",
                   help="standard deviation of the measured distance [m] (default 0.001)")
    q.add_argument("--allow-failed", action="store_true", help="accept frames the frontend failed on")
    q.add_argument("--out", metavar="FILE", help="cam0/sensor.yaml to write with the measured height")
    q.set_defaults(func=run_height)

    q = kinds.add_parser("lever-arm", help="camera offset from the rotation centre from a turn in place")
    q.add_argument("seq", metavar="SEQ", help="recording of a turn in place about the axle")
    q.add_argument("--height-std", type=non_negative_number, default=0.0, metavar="M",
                   help="standard deviation of the camera height [m], propagated into the result")
    q.add_argument("--out", metavar="FILE", help="cam0/sensor.yaml to write with the measured lever arm")
    q.set_defaults(func=run_lever_arm)

    q = kinds.add_parser("wheels", help="wheel radii and wheel base (ground truth or UMBmark)")
    q.add_argument("seq", metavar="SEQ", help="recording with wheel0 and ground truth (the clockwise square for UMBmark)")
    q.add_argument("--method", choices=["groundtruth", "umbmark"], default="groundtruth")
    q.add_argument("--ccw", metavar="SEQ2", help="the counter-clockwise square (UMBmark)")
    q.add_argument("--out", metavar="FILE", help="wheel0/sensor.yaml to write")
    q.set_defaults(func=run_wheels)

    q = kinds.add_parser("camera-noise",
                         help="the camera's heading noise by turn and each frame's own error, against ground truth",
                         description="Run visual odometry on drives with ground truth and measure how its heading "
                                     "errors grow with the turn between two frames and how much of them is each "
                                     "frame's own (fusion_vo.calibration.camera_noise). With --out the model is "
                                     "written under camera_noise in that cam0/sensor.yaml (its other keys kept); "
                                     "runs of the same frontend then use it.")
    q.add_argument("seqs", nargs="+", metavar="SEQ", help="recordings of the camera with ground truth")
    q.add_argument("--frontend", choices=("klt", "features", "direct"), default=None,
                   help="frontend to measure (default: that of --config, else klt)")
    q.add_argument("--config", metavar="YAML", help="run configuration (its odometry and frontend sections are used)")
    q.add_argument("--out", metavar="FILE", help="cam0/sensor.yaml to write the model into")
    q.set_defaults(func=run_camera_noise)

    p.set_defaults(func=lambda args: p.print_help() or 2)


def _board_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--board", required=True, metavar="COLSxROWS", help="inner corners of the chessboard, e.g. 9x6")
    p.add_argument("--square", required=True, type=positive_number, metavar="METRES", help="side of one square [m]")


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
    from fusion_vo.config.sensor_files import read_camera

    board = Board.parse(args.board, args.square)
    result = calibrate_images(args.images, board, args.model, radial_terms=args.radial_terms)
    out = Path(args.out)
    base = read_camera(out) if out.is_file() else None
    print(result.summary())
    result.to_camera(base).write_yaml(out)
    print(f"-> {out}" + (" (T_BS and rate kept)" if base is not None else ""))
    return 0


def run_floor(args: argparse.Namespace) -> int:
    from fusion_vo.calibration.chessboard import Board, detect_corners, read_image
    from fusion_vo.calibration.floor import floor_pose
    from fusion_vo.config.sensor_files import read_camera

    board = Board.parse(args.board, args.square)
    camera = read_camera(args.intrinsics)
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


def _camera_out(recording, out: str | None, change) -> None:
    if not out:
        print("(not written: give --out cam0/sensor.yaml to write it)")
        return
    camera = recording.camera
    change(camera)
    camera.write_yaml(out)
    print(f"-> {out}")


def run_height(args: argparse.Namespace) -> int:
    from fusion_vo.calibration.height import height_from_drive
    from fusion_vo.calibration.motion import frame_motions
    from fusion_vo.recording import Recording

    rec = Recording(args.seq)
    motions, geometry = frame_motions(rec)
    r = height_from_drive(motions, geometry.rectifier.f, geometry.rectifier.c, args.distance, args.distance_std,
                          args.allow_failed)
    print(r.summary())

    def set_height(cam):
        cam.T_BS[2, 3] = r.height

    _camera_out(rec, args.out, set_height)
    return 0


def run_lever_arm(args: argparse.Namespace) -> int:
    from fusion_vo.calibration.lever_arm import lever_arm_from_turn
    from fusion_vo.calibration.motion import frame_motions
    from fusion_vo.recording import Recording

    rec = Recording(args.seq)
    _check_turn_in_place(rec)
    motions, geometry = frame_motions(rec)
    r = lever_arm_from_turn([m.matrix for m in motions if m.ok], geometry, args.height_std)
    print(r.summary())

    def set_lever(cam):
        cam.T_BS[:2, 3] = r.lever_arm

    _camera_out(rec, args.out, set_lever)
    return 0


def _check_turn_in_place(rec) -> None:
    """With wheels, refuse a drive: the frames' fixed point is then the centre of the arc driven, not the
    axle, and the lever arm would come out wrong with a tiny standard deviation."""
    if not rec.has("wheel0"):
        return
    import numpy as np

    from fusion_vo.sensors.wheel import read_ticks, ticks_to_travel

    travel = ticks_to_travel(read_ticks(rec))
    dl, dr = np.diff(travel.left), np.diff(travel.right)
    axle = float(np.sum(np.abs(dl + dr))) / 2.0  # distance the axle centre moved
    arcs = float(np.sum(np.abs(dr - dl))) / 2.0  # distance each wheel moved about it
    if axle > 0.01 and axle > 0.25 * arcs:
        turned = math.degrees(2.0 * arcs / travel.wheel_base)
        raise InputError(f"not a turn in place: the wheels moved the axle {axle:.3f} m while turning {turned:.0f} "
                         "deg; record a turn in place about the axle", rec.path / "wheel0" / "data.csv")


def run_camera_noise(args: argparse.Namespace) -> int:
    from fusion_vo.calibration.camera_noise_drive import calibrate
    from fusion_vo.config import load_config
    from fusion_vo.config.files import load_yaml, write_yaml_atomic
    from fusion_vo.recording import Recording

    config = load_config(args.config)
    if args.frontend:
        config = config.model_copy(update={"frontend": args.frontend})  # (one of argparse's choices)
    try:
        odometry = config.odometry_config()
    except ValueError as exc:
        raise InputError(str(exc), args.config) from None
    recordings = [Recording(seq) for seq in args.seqs]
    noise = calibrate(recordings, odometry)  # (it checks every drive's ground truth before any work)
    print(f"{noise.frontend} frontend, {noise.increments} increments of {len(recordings)} drive(s):")
    for lo, hi, sigma in zip(noise.edges, noise.edges[1:] + (math.inf,), noise.heading_sigma):
        print(f"  turn {lo:g}-{hi:g} rad between frames: heading error {1e6 * sigma:.1f} µrad (RMS)")
    print(f"  each frame's own heading error: {1e6 * noise.frame_sigma:.1f} µrad")
    if not args.out:
        print("(not written: give --out cam0/sensor.yaml to write it)")
        return 0
    data = load_yaml(args.out) if Path(args.out).is_file() else {}
    data["camera_noise"] = noise.to_dict()
    write_yaml_atomic(args.out, data)
    print(f"-> {args.out}")
    return 0


def run_wheels(args: argparse.Namespace) -> int:
    from fusion_vo.calibration.wheels import umbmark, wheels_from_groundtruth
    from fusion_vo.config.files import write_yaml_atomic
    from fusion_vo.recording import Recording
    from fusion_vo.sensors.wheel import read_ticks

    rec = Recording(args.seq)
    if args.method == "umbmark":
        if not args.ccw:
            raise InputError("UMBmark needs the counter-clockwise square too (--ccw SEQ2)")
        other = Recording(args.ccw)
        if other.path.resolve() == rec.path.resolve():
            raise InputError("--ccw: the same recording as SEQ (UMBmark needs a clockwise and a counter-clockwise "
                             "square)", args.ccw)
        r = umbmark((read_ticks(rec), rec.groundtruth()), (read_ticks(other), other.groundtruth()),
                    sources=(rec.path, other.path))
    elif args.ccw:
        raise InputError("--ccw is used only with --method umbmark")
    else:
        r = wheels_from_groundtruth(read_ticks(rec), rec.groundtruth())
    print(r.summary())
    if args.out:
        write_yaml_atomic(args.out, r.to_dict())
        print(f"-> {args.out}")
    else:
        print("(not written: give --out wheel0/sensor.yaml to write it)")
    return 0
