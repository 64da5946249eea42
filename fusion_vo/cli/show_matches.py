"""``fusion-vo show-matches SEQ --frame N``: the matched corners of frames N-1 and N as a picture."""

from __future__ import annotations

import argparse

from fusion_vo.cli.arguments import non_empty


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "show-matches",
        help="draw the corners matched between two frames (previous: blue stars, current: red circles)",
        description="Match the corners of frames N-1 and N of a recording the way a frontend does and draw "
                    "them on frame N: blue stars in frame N-1, red circles in frame N, yellow lines for "
                    "inliers of the estimated motion, grey lines for outliers.",
    )
    parser.add_argument("sequence", metavar="SEQ", help="recording folder")
    parser.add_argument("--frame", "-n", metavar="N", type=int, required=True,
                        help="index of the current frame (row of cam0/data.csv, from 0); N-1 is the previous")
    parser.add_argument("--frontend", choices=("features", "klt"), default="features",
                        help="whose matching to show (default: features)")
    parser.add_argument("--out", "-o", metavar="FILE.png", default=None, type=non_empty("an image file name"),
                        help="output image (default: matches_<N>.png in the current folder); an existing file is "
                             "replaced only if fusion-vo wrote it")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from fusion_vo.errors import InputError
    from fusion_vo.evaluation.matches import find_matches, to_grey8
    from fusion_vo.evaluation.plots import plot_matches
    from fusion_vo.geometry.ground import GroundRectifier
    from fusion_vo.outputs import check_outside, check_picture_target
    from fusion_vo.recording import Recording

    recording = Recording(args.sequence)
    out = Path(args.out or f"matches_{args.frame}.png")
    if out.suffix.lower() != ".png":
        raise InputError("the image is written as PNG: give a file name ending in .png", out)
    check_outside(out, [recording.path], "output image")
    check_picture_target(out)  # only a picture fusion-vo wrote is replaced
    count = len(recording)
    if not 1 <= args.frame < count:
        raise InputError(f"--frame must lie between 1 and {count - 1} (the recording has {count} frames)",
                         Path(args.sequence) / "cam0" / "data.csv")
    frames = list(recording.frames(args.frame - 1, args.frame + 1))
    for frame in frames:
        if frame.image is None:  # the reader's reason already names the file and its line of cam0/data.csv
            raise InputError(frame.error) if frame.error else InputError("frame cannot be read", frame.source)
    try:
        matches = find_matches(frames[0].image, frames[1].image, args.frontend,
                               point_map=GroundRectifier(recording.camera))
    except ValueError as exc:
        raise InputError(str(exc), frames[1].source) from None
    dt = frames[1].t - frames[0].t
    title = (f"{args.frontend}: frames {args.frame - 1} -> {args.frame} ({dt * 1e3:.0f} ms): "
             f"{len(matches.previous)} matches, {matches.n_inliers} inliers")
    plot_matches(to_grey8(frames[1].image), matches, out, title)
    print(f"{title}\nwrote {out}")
    return 0
