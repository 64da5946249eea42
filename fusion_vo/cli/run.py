"""``fusion-vo run SEQ --out DIR``: visual odometry, fusion and evaluation on one recording."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from fusion_vo.cli.arguments import MAX_THREADS, non_empty, positive_number, thread_count
from fusion_vo.cli.progress import progress_bar
from fusion_vo.config import BACKENDS, SENSORS
from fusion_vo.errors import InputError


def register(sub) -> None:
    p = sub.add_parser("run", help="run visual odometry (and fusion) on a recording",
                       description="Run visual odometry on a recording folder, fuse it with the wheels and the IMU, "
                                   "write a report (report.html) and evaluate against ground truth when the recording "
                                   "has it.")
    p.add_argument("sequence", nargs="?", help="recording folder (EuRoC layout plus wheel0/, see datasets/README.md)")
    p.add_argument("--out", "-o", help="output folder: new, empty, or an earlier run's (replaced as a whole)")
    p.add_argument("--force", action="store_true",
                   help="replace an output folder that is not empty and was not written by fusion-vo run")
    p.add_argument("--frontend", choices=["klt", "features", "direct"], help="visual frontend (default: klt)")
    p.add_argument("--config", "-c", type=non_empty("a configuration file"),
                   help="YAML configuration file (see --print-config)")
    p.add_argument("--backend", choices=BACKENDS, help="fusion backend (default: all)")
    p.add_argument("--sensors", help=f"comma-separated sensors to use, of {','.join(SENSORS)} or any sensor a package registers (entry point "
                        "fusion_vo.sensors) (default: the camera, wheels and IMU the recording has; gps is fused only when listed)")
    p.add_argument("--threads", type=thread_count, metavar="N",
                   help=f"threads for decoding frames ahead of the tracker and for OpenCV, at most {MAX_THREADS} (default: "
                        "the cores available); the results do not depend on it")
    p.add_argument("--no-evaluate", action="store_true", help="skip the evaluation against ground truth")
    p.add_argument("--uncalibrated", action="store_true",
                   help="the camera has no calibration: ignore the intrinsics' distortion (pinhole of the given or "
                        "stated focal length, lens distortion estimated from the frames)")
    p.add_argument("--focal-length", type=positive_number, help="approximate focal length [px] for --uncalibrated")
    p.add_argument("--print-config", action="store_true",
                   help="print the configuration (every option, its default and description; with --config, the "
                        "file's values) as YAML and exit")
    p.add_argument("--print-schema", action="store_true",
                   help="print the JSON schema of the configuration file (for editors) and exit")
    p.add_argument("--print-reference", action="store_true",
                   help="print every option of the configuration file as a Markdown reference and exit")
    p.set_defaults(func=run)


def _sensor_list(text: str) -> list[str]:
    names = [s.strip() for s in text.split(",") if s.strip()]
    if not names:
        raise InputError(f"--sensors {text!r}: no sensor named (give e.g. camera,wheel,imu)")
    return names


def apply_overrides(cfg, args):
    """The command-line options over the configuration file's values (``run``, ``replay``, ``batch``,
    ``sweep``): each is checked by the configuration's own model, and a value it rejects is an error
    naming the option rather than the configuration key."""
    overrides = []  # (option as typed, the values it sets)
    if getattr(args, "frontend", None):
        overrides.append((f"--frontend {args.frontend}", {"frontend": args.frontend}))
    if getattr(args, "backend", None):
        overrides.append((f"--backend {args.backend}", {"backend": args.backend}))
    if getattr(args, "sensors", None) is not None:
        overrides.append((f"--sensors {args.sensors}", {"sensors": _sensor_list(args.sensors)}))
    if getattr(args, "threads", None) is not None:
        overrides.append((f"--threads {args.threads}", {"odometry": {"threads": args.threads}}))
    if getattr(args, "no_evaluate", False):
        overrides.append(("--no-evaluate", {"evaluate": False}))
    if getattr(args, "uncalibrated", False):
        overrides.append(("--uncalibrated", {"odometry": {"uncalibrated": True}}))
    if getattr(args, "focal_length", None) is not None:
        overrides.append((f"--focal-length {args.focal_length:g}", {"odometry": {"focal_length": args.focal_length}}))
    for option, values in overrides:
        try:
            cfg = cfg.merged(values)
        except ValueError as exc:
            raise InputError(f"{option}: {str(exc).removeprefix('RunConfig: ')}") from None
    if getattr(args, "focal_length", None) is not None and not cfg.odometry.uncalibrated:
        raise InputError("--focal-length is used only with --uncalibrated (a calibrated camera keeps the focal "
                         "length of cam0/sensor.yaml)")
    return cfg


def run(args: argparse.Namespace) -> int:
    from fusion_vo.config.run import default_config_text, load_config, reference_text, schema_text

    if args.print_schema:
        sys.stdout.write(schema_text())
        return 0
    if args.print_reference:
        sys.stdout.write(reference_text())
        return 0
    if args.print_config:
        sys.stdout.write(default_config_text(load_config(args.config) if args.config else None))
        return 0
    if not args.sequence or not args.out:
        raise InputError("run needs a recording folder and --out DIR (see fusion-vo run --help)")
    from fusion_vo.pipeline import run_pipeline

    cfg = apply_overrides(load_config(args.config), args)
    with progress_bar("visual odometry") as update:
        summary = run_pipeline(args.sequence, args.out, cfg, progress=update, force=args.force,
                               config_path=args.config)
    for note in summary.notes:
        print(f"note: {note}")
    from fusion_vo.cli.evaluate import show_metrics, show_verdict

    if summary.metrics:
        show_metrics(summary.metrics, Path(args.out).resolve().name)
    if summary.report:
        show_verdict(summary.report["verdict"], summary.report["accuracy"])
    print(summary.line())
    if summary.report:
        print(f"report: {Path(args.out) / summary.report['path']}")
    return 0
