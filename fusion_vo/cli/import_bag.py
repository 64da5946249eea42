"""``fusion-vo import-bag``: convert a ROS 1 or ROS 2 bag into a recording folder.

Example::

    fusion-vo import-bag test1.bag husky_seq \\
        --static-tf "0 -0.3 0.52 -1.570796327 0 1.570796327 base_link imu_link"
"""

from __future__ import annotations

import argparse

from fusion_vo.cli.arguments import non_empty


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "import-bag",
        help="convert a ROS bag (ROS 1 .bag, ROS 2 folder or .mcap) into a recording folder",
        description="Write the recording layout (cam0, imu0, odom0, gps0) from a ROS 1 or ROS 2 bag. "
                    "A stream whose topic is not given takes the bag's only topic of that message type. "
                    "--imu-topic and --odom-topic may be given more than once: the first topic goes to imu0 "
                    "(odom0), the next to imu1 (odom1), and so on.",
    )
    parser.add_argument("bag", help="ROS 1 .bag file, ROS 2 bag folder, or .mcap/.db3 file")
    # an empty value is a usage error naming the option, not the default topic or the current folder
    parser.add_argument("out", nargs="?", type=non_empty("a recording folder"),
                        help="recording folder: new, empty, or a recording fusion-vo wrote (replaced)")
    topic = non_empty("a topic name")
    parser.add_argument("--image-topic", type=topic, help="sensor_msgs/Image or CompressedImage topic (cam0)")
    parser.add_argument("--imu-topic", type=topic, action="append",
                        help="sensor_msgs/Imu topic (imu0); repeated, the next ones go to imu1, imu2 ...")
    parser.add_argument("--odom-topic", type=topic, action="append",
                        help="nav_msgs/Odometry topic (odom0); repeated, the next ones go to odom1, odom2 ...")
    parser.add_argument("--gps-topic", type=topic, help="sensor_msgs/NavSatFix topic (gps0)")
    parser.add_argument("--camera-yaml", type=non_empty("a file name"),
                        help="cam0/sensor.yaml to use instead of the bag's CameraInfo")
    parser.add_argument("--static-tf", action="append", default=[], metavar="'X Y Z YAW PITCH ROLL PARENT CHILD'",
                        help="a fixed transform missing from the bag's /tf_static, in static_transform_publisher "
                             "order (repeatable)")
    parser.add_argument("--list", action="store_true", help="only list the bag's topics")
    parser.add_argument("--force", action="store_true",
                        help="replace a non-empty folder that is not a recording fusion-vo wrote")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from fusion_vo.recording.rosbag import import_bag, list_topics, parse_static_tf

    if args.list or args.out is None:
        if args.out is None and not args.list:
            from fusion_vo.errors import InputError

            raise InputError("give an output folder (or --list to only list the topics)")
        for t in list_topics(args.bag):
            print(f"{t.topic:40s} {t.msgtype:32s} {t.count:8d}")
        return 0
    summary = import_bag(
        args.bag, args.out,
        image_topic=args.image_topic, imu_topic=args.imu_topic, odom_topic=args.odom_topic,
        gps_topic=args.gps_topic, camera_yaml=args.camera_yaml,
        static_tfs=[parse_static_tf(s) for s in args.static_tf], overwrite=args.force,
    )
    print(f"{summary.out}: imported from {summary.bag}")
    print(f"  {'stream':6s} {'topic':36s} {'rows':>7s} {'rate Hz':>8s} {'span s':>8s} {'dup':>5s} {'dropped':>7s}")
    for s in summary.streams:
        rate = f"{s.rate_hz:.2f}" if s.rate_hz else "-"
        print(f"  {s.stream:6s} {s.topic:36s} {s.written:7d} {rate:>8s} {s.duration_s:8.2f} "
              f"{s.duplicates:5d} {s.dropped:7d}")
        if s.bag_time_stamps:
            print(f"         {s.bag_time_stamps} messages had no header stamp; their bag time was used")
    for note in summary.notes:
        print(f"  note: {note}")
    return 0
