"""``fusion-vo export RUN --to rosbag2|mcap OUT``: a run's trajectories as ROS 2 odometry and /tf."""

from __future__ import annotations

import argparse

from fusion_vo.cli.arguments import frame_id
from fusion_vo.errors import InputError


def register(sub) -> None:
    p = sub.add_parser(
        "export", help="write a run's trajectories as ROS 2 nav_msgs/Odometry and /tf (rosbag2 or MCAP)",
        description="Write every trajectory of RUN (NAME.tum, with its covariance from NAME.cov.csv when present) "
                    "as nav_msgs/msg/Odometry on /fusion_vo/NAME/odometry plus /tf, stamped on the recording's "
                    "clock, to a rosbag2 folder or an MCAP file (open either in Foxglove; play the rosbag2 folder "
                    "with 'ros2 bag play' for RViz). With the recording's ground truth (run.yaml's sequence) it is "
                    "exported too, as 'groundtruth'.")
    p.add_argument("run_dir", metavar="RUN", help="folder written by 'fusion-vo run'")
    p.add_argument("out", metavar="OUT", help="rosbag2 folder or .mcap file to create (must not exist)")
    p.add_argument("--to", dest="fmt", choices=["rosbag2", "mcap"], required=True, help="output format")
    p.add_argument("--trajectories", help="comma-separated names to export, 'groundtruth' among them for the "
                                          "recording's (default: every *.tum of RUN and the ground truth)")
    p.add_argument("--frame-id", type=frame_id, default="odom", help="fixed frame of the poses (default: odom)")
    p.add_argument("--no-groundtruth", action="store_true", help="leave the recording's ground truth out")
    p.set_defaults(func=run)


def _check_outside_inputs(run_dir: str, out: str) -> None:
    """The bag may not go into the run folder (a later ``fusion-vo run`` into it replaces the folder as a
    whole, the bag with it) nor into the recording the run names."""
    from pathlib import Path

    from fusion_vo.evaluation.io import read_run_config
    from fusion_vo.outputs import check_outside

    inputs = [run_dir]
    if (Path(run_dir) / "run.yaml").is_file():
        named = read_run_config(run_dir).get("sequence")
        if named and Path(str(named)).is_dir():
            inputs.append(str(named))
    check_outside(out, inputs, "output bag")


def run(args: argparse.Namespace) -> int:
    from fusion_vo.export.ros import export_trajectories, groundtruth_of_run, load_run_trajectories

    names = None
    if args.trajectories is not None:
        names = [n.strip() for n in args.trajectories.split(",") if n.strip()]
        if not names:
            raise InputError(f"--trajectories {args.trajectories!r}: no trajectory named (give e.g. ekf,groundtruth)")
    _check_outside_inputs(args.run_dir, args.out)
    want_gt = not args.no_groundtruth and (names is None or "groundtruth" in names)
    run_names = [n for n in names if n != "groundtruth"] if names else None
    trajectories = load_run_trajectories(args.run_dir, run_names) if run_names or names is None else []
    if want_gt:
        gt = groundtruth_of_run(args.run_dir)
        if gt is not None:
            trajectories.append(gt)
        elif names is None:  # by default the ground truth goes with the run: say when it cannot, and why
            print(f"note: no ground truth exported: {_why_no_groundtruth(args.run_dir)}; "
                  "--no-groundtruth leaves it out without this note")
        elif names:
            raise InputError("no ground truth: run.yaml names no recording with state_groundtruth_estimate0/",
                             args.run_dir)
    out = export_trajectories(trajectories, args.out, args.fmt, args.frame_id)
    for traj in trajectories:
        cov = "with covariance" if traj.covariance is not None else "covariance unknown"
        print(f"{traj.topic}: {len(traj.stamp_ns)} poses ({cov})")
    for traj in trajectories:
        if traj.ros_name != traj.name:
            print(f"note: trajectory '{traj.name}' exported as {traj.topic} and frame {traj.ros_name}/base_link "
                  "(ROS 2 names hold letters, digits and underscores only)")
    print(f"wrote {args.fmt} -> {out}")
    return 0


def _why_no_groundtruth(run_dir) -> str:
    """Why a run has no ground truth to export: its recording has none, or is not where run.yaml says."""
    from pathlib import Path

    from fusion_vo.evaluation.io import read_run_config

    named = read_run_config(run_dir).get("sequence") if (Path(run_dir) / "run.yaml").is_file() else None
    if named and Path(str(named)).is_dir():
        return f"its recording {named} has none (no state_groundtruth_estimate0/)"
    if named:
        return f"its recording {named}, named by run.yaml, is not there (moved or deleted?)"
    return "run.yaml names no recording"
