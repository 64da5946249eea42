"""``fusion-vo ros2`` (the ``fusion_vo`` ROS 2 node) and ``fusion-vo ros2-play`` (a bag or recording published).

Both need the ``ros2`` extra (``pip install "fusion-vo[ros2]"``); without it they say so in one line (exit 2).
Arguments after ``--ros-args`` go to ROS (remaps ``-r``, parameters ``-p``, ``--params-file``). See
``docs/ros2.md``.
"""

from __future__ import annotations

import argparse
import signal
import threading
from pathlib import Path

from fusion_vo.cli.arguments import non_empty, non_negative_number, positive_number
from fusion_vo.errors import InputError


def register(sub) -> None:
    p = sub.add_parser("ros2", help="run the fusion_vo ROS 2 node (needs the ros2 extra)",
                       description="Run the fusion_vo ROS 2 node: sensor topics in, odometry/filtered and "
                                   "diagnostics out (docs/ros2.md).")
    p.add_argument("--config", "-c", type=non_empty("a configuration file"),
                   help="YAML configuration: a fusion-vo run configuration plus a 'ros2' section")
    p.add_argument("--ros-args", dest="ros_args", nargs=argparse.REMAINDER, default=None, metavar="ARG",
                   help="the rest of the command line goes to ROS: -r FROM:=TO remaps, -p NAME:=VALUE parameters, "
                        "--params-file FILE")
    p.set_defaults(func=run_node)

    q = sub.add_parser("ros2-play", help="publish a ROS bag or a recording folder with /clock (needs the ros2 extra)",
                       description="Publish a ROS bag's topics (or a recording folder's streams under the node's "
                                   "input names) with their own stamps, paced by their recording time, and /clock.")
    q.add_argument("source", help="ROS bag (.bag, ROS 2 folder, .mcap, .db3) or recording folder")
    q.add_argument("--speed", type=non_negative_number, default=1.0,
                   help="playback speed: 1 = real time, N = N times faster, 0 = as fast as possible (default 1)")
    q.add_argument("--wait", type=non_negative_number, default=3.0,
                   help="seconds to wait for every topic to have a subscriber before playing (default 3)")
    q.add_argument("--tail", type=non_negative_number, default=1.0,
                   help="seconds of /clock published after the last message (default 1)")
    q.add_argument("--clock-rate", type=positive_number, default=50.0,
                   help="rate [Hz, simulated time] of /clock (default 50)")
    q.add_argument("--no-clock", action="store_true", help="do not publish /clock")
    q.add_argument("--ros-args", dest="ros_args", nargs=argparse.REMAINDER, default=None, metavar="ARG",
                   help="the rest of the command line goes to ROS, e.g. -r /jackal_velocity_controller/odom:=/odom")
    q.set_defaults(func=run_play)


def _ros2():
    """The ROS-facing modules (rclpy and the message packages), or a one-line error without the extra."""
    try:
        from fusion_vo.ros2 import play, run
    except ImportError as exc:
        raise InputError(f"the ros2 commands need the ros2 extra: pip install \"fusion-vo[ros2]\" ({exc})") from None
    return play, run


def _ros_args(args: argparse.Namespace) -> list[str]:
    return [] if args.ros_args is None else ["--ros-args", *args.ros_args]


def run_node(args: argparse.Namespace) -> int:
    _, run = _ros2()
    return run.run_node(args.config, _ros_args(args))


def run_play(args: argparse.Namespace) -> int:
    play, run = _ros2()
    source = Path(args.source)
    summary = play.PlaySummary()
    topics = play.source_topics(source, summary)  # a bad source is an error before ROS starts
    messages = play.messages_of(source, topics)
    stop = threading.Event()
    previous = run.stop_on_signals(stop)
    run.ros_context(_ros_args(args), "fusion-vo-ros2-play")
    player = None
    try:
        player = play.Player(topics, clock=not args.no_clock)
        missing = player.wait_for_subscribers(args.wait, stop)
        if missing:
            print(f"fusion-vo ros2-play: no subscriber after {args.wait:g} s on {', '.join(missing)}; playing anyway",
                  flush=True)
        player.play(messages, args.speed, args.clock_rate, args.tail, stop, summary)
    finally:
        if player is not None:
            player.destroy_node()
        run.rclpy.try_shutdown()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    for topic, why in summary.left_out.items():
        print(f"fusion-vo ros2-play: {topic} left out: {why}")
    total = sum(summary.published.values())
    print(f"fusion-vo ros2-play: {total} messages on {len(summary.published)} topics, {summary.span_s:.1f} s of "
          f"recording in {summary.wall_s:.1f} s" + (" (stopped)" if stop.is_set() else ""), flush=True)
    return 0
