"""Running the node in a process: ROS arguments, the executor, signals and a clean shutdown.

``rclpy`` parses the ``--ros-args`` (remaps ``-r``, parameters ``-p``, ``--params-file``, ``--log-level``);
SIGINT and SIGTERM stop the executor (it is polled every 0.1 s), then the camera thread, the node and the
ROS context are shut down and a summary of each input is printed: the process ends with status 0 within
a fraction of a second. A bad argument, parameter or configuration is an
:class:`~fusion_vo.errors.InputError` raised before any subscription (the command prints one line and exits
with status 2).

After start-up the objects made so far leave the garbage collector's scans (:func:`gc.freeze`): CPython's
full collections would otherwise scan the hundred thousand objects of the imported libraries and stall
whichever callback they fall in by some 40 ms (``benchmarks/backend_speed.py latency`` with and without
``--gc-freeze``; docs/decisions/0029-live-work-on-the-callers-thread.md).
"""

from __future__ import annotations

import gc
import signal
import sys
import threading

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions

from fusion_vo.errors import InputError
from fusion_vo.ros2.node import FusionNode

def ros_context(ros_args: list[str], name: str):
    """``rclpy.init`` with the ROS arguments and without rclpy's own signal handlers (InputError when rclpy
    rejects the arguments)."""
    args = [name] + list(ros_args)
    if ros_args and ros_args[0] != "--ros-args":
        raise InputError(f"unexpected argument '{ros_args[0]}' (ROS arguments follow --ros-args)")
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as exc:  # rclpy's RCLError and friends for malformed --ros-args
        raise InputError(f"--ros-args: {' '.join(str(exc).split())}") from None


def stop_on_signals(stop: threading.Event) -> dict:
    """SIGINT and SIGTERM set ``stop``; returns the handlers replaced."""
    previous = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        previous[sig] = signal.signal(sig, lambda signum, frame: stop.set())
    return previous


def run_node(config, ros_args: list[str]) -> int:
    """Start the ``fusion_vo`` node and spin it until SIGINT or SIGTERM; 0 after a clean shutdown."""
    stop = threading.Event()
    previous = stop_on_signals(stop)
    ros_context(ros_args, "fusion-vo-ros2")
    node = executor = None
    try:
        node = FusionNode(config)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        gc.collect()
        gc.freeze()
        topics = ", ".join(s.topic for s in node.stats.values())
        print(f"fusion-vo ros2: node {node.get_fully_qualified_name()} running (backend {node.settings.backend}; "
              f"inputs {topics}; output {node.pub.topic_name})", flush=True)
        while not stop.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    finally:
        lines = node.close() if node is not None else []
        if executor is not None:
            executor.shutdown(timeout_sec=1.0)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    for line in lines:
        print(f"fusion-vo ros2: {line}", flush=True)
    print("fusion-vo ros2: stopped", file=sys.stderr, flush=True)
    return 0
