"""Benchmark: the input rate the ROS 2 node sustains and the age of the pose it publishes.

    python benchmarks/ros2_node.py [--seconds 20] [--camera-hz 60] [--imu-hz 200] [--odom-hz 50]

Inputs, made here: a 640x360 mono8 camera looking at a random texture that slides 2 px per frame (the
KLT frontend tracks it), an IMU and wheel odometry, all stamped with the wall clock and published at
their rates in real time by this process. The node (``fusion-vo ros2``, EKF, default settings, camera on
its own thread) runs in a subprocess; both run in a loopback-only network namespace (the script re-runs
itself under ``unshare -n``). Printed, for the node over DDS:

* the rate of messages the node took (its diagnostics' ``received``) beside the rate offered, the camera
  frames its frontend processed per second and those it dropped from its queue;
* the age of each published pose when it arrived (arrival wall time minus its stamp: the pose is
  predicted to the node's clock at publication), median and p99;
* how far that pose was predicted beyond the processed state (``predicted_s`` of the diagnostics).

Baseline, in the same run: the same StreamingFusion and live visual odometry fed directly in-process
(a camera thread, the other samples from the main thread, paced alike), ``current_estimate(now)`` read at
50 Hz: frames processed per second, the call's duration (the age of its pose) and the prediction.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import cv2
import common
import numpy as np

from fusion_vo.measurements import ImuSample, TwistSample
from fusion_vo.ros2.camera import CameraPipeline
from fusion_vo.ros2.intake import Intake
from fusion_vo.ros2.sensors import sensor_setup, streaming_fusion, visual_odometry
from fusion_vo.ros2.settings import load_settings

CAM0 = """sensor_type: camera
rate_hz: {hz}
resolution: [640, 360]
camera_model: pinhole
intrinsics: [420.0, 420.0, 319.5, 179.5]
distortion_model: radial-tangential
distortion_coefficients: [0.0, 0.0, 0.0, 0.0]
T_BS: {{cols: 4, rows: 4, data: [0.0, -1.0, 0.0, 0.25, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.1, 0.0, 0.0, 0.0, 1.0]}}
"""
IMU0 = """T_BS: {cols: 4, rows: 4, data: [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]}
gyroscope_noise_density: 0.00017
accelerometer_noise_density: 0.002
"""
SHIFT_PX = 2  # texture motion per frame
SPEED = SHIFT_PX * 0.1 / 420.0  # [m per frame] at the camera's 0.1 m height and 420 px focal length


def texture(size=(1200, 4000), seed=1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    noise = rng.normal(128, 60, size).astype(np.float32)
    return np.clip(cv2.GaussianBlur(noise, (0, 0), 2.0), 0, 255).astype(np.uint8)


def frame(tex: np.ndarray, k: int) -> np.ndarray:
    x = (SHIFT_PX * k) % (tex.shape[1] - 700)
    return np.ascontiguousarray(tex[400:760, x:x + 640])


def schedule(args) -> list[tuple[float, str, int]]:
    """``(offset [s], kind, index)`` of every message in time order."""
    out = []
    for kind, hz in (("image", args.camera_hz), ("imu", args.imu_hz), ("odom", args.odom_hz)):
        out += [(k / hz, kind, k) for k in range(int(args.seconds * hz))]
    return sorted(out)


def percentiles(values) -> str:
    v = np.asarray(values, dtype=np.float64)
    return "n/a" if not len(v) else f"{np.median(v) * 1e3:.2f} / {np.percentile(v, 99) * 1e3:.2f} ms"


# ------------------------------------------------------------------------------------ the node over DDS
def run_node(args, calib: Path) -> dict:
    import rclpy  # the ros2 extra (only inside the namespace)
    from diagnostic_msgs.msg import DiagnosticArray
    from nav_msgs.msg import Odometry
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import Image, Imu

    node_cmd = [sys.executable, "-m", "fusion_vo.cli.main", "ros2", "--ros-args", "-p", f"calibration:={calib}",
                "-p", "sensors:=[camera,imu,odom]", "-p", "diagnostics_period:=0.25"]
    proc = subprocess.Popen(node_cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    for line in proc.stdout:
        if "running" in line:
            break
    rclpy.init()
    peer = rclpy.create_node("ros2_node")
    poses, diags = [], []
    reliable = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    peer.create_subscription(Odometry, "/odometry/filtered", lambda m: poses.append(
        (time.time(), m.header.stamp.sec + m.header.stamp.nanosec * 1e-9)), reliable)
    peer.create_subscription(DiagnosticArray, "/diagnostics", lambda m: diags.append(
        {s.name: {kv.key: kv.value for kv in s.values} for s in m.status}), reliable)
    pubs = {"image": peer.create_publisher(Image, "/image", QoSProfile(depth=5)),
            "imu": peer.create_publisher(Imu, "/imu/data", QoSProfile(depth=100)),
            "odom": peer.create_publisher(Odometry, "/odom", QoSProfile(depth=100))}
    executor = SingleThreadedExecutor()
    executor.add_node(peer)
    threading.Thread(target=executor.spin, daemon=True).start()
    while min(p.get_subscription_count() for p in pubs.values()) == 0:
        time.sleep(0.05)
    time.sleep(1.0)
    tex = texture()

    def message(kind, k, t):
        stamp = lambda m: (setattr(m.header.stamp, "sec", int(t)),  # noqa: E731
                           setattr(m.header.stamp, "nanosec", int((t - int(t)) * 1e9)))
        if kind == "image":
            m = Image(height=360, width=640, encoding="mono8", step=640)
            m.header.frame_id = "camera"
            m.data = frame(tex, k).tobytes()
        elif kind == "imu":
            m = Imu()
            m.header.frame_id = "imu"
            m.linear_acceleration.z = 9.81
            m.orientation_covariance[0] = -1.0
        else:
            m = Odometry()
            m.child_frame_id = "base_link"
            m.twist.twist.linear.x = SPEED * args.camera_hz
        stamp(m)
        return m

    plan = schedule(args)
    start = time.time() + 0.2
    t_first_pose = len(poses)
    for offset, kind, k in plan:
        delay = start + offset - time.time()
        if delay > 0:
            time.sleep(delay)
        pubs[kind].publish(message(kind, k, time.time()))
    published_s = time.time() - start
    n_poses = len(poses)
    time.sleep(1.5)
    proc.send_signal(2)
    proc.wait(timeout=10)
    last = diags[-1]
    received = sum(int(s.get("received", 0)) for s in last.values())
    cam = last["fusion_vo: camera"]
    predicted = [float(d["fusion_vo: estimate"]["predicted_s"]) for d in diags
                 if d["fusion_vo: estimate"]["predicted_s"] != "nan"]
    ages = [r - s for r, s in poses[t_first_pose:n_poses]]
    result = {"offered": len(plan) / args.seconds, "taken": received / published_s,
                     "frames": int(cam["frames"]) / published_s, "dropped": int(cam["dropped"]),
                     "unusable": sum(int(s.get("unusable", 0)) for s in last.values()),
                     "age": percentiles(ages), "predicted": percentiles(predicted), "poses": len(ages)}
    return result


# ------------------------------------------------------------------------------------ in-process baseline
def run_in_process(args, calib: Path) -> dict:
    settings = load_settings(None, {"calibration": str(calib), "sensors": ["camera", "imu", "odom"]})
    setup = sensor_setup(settings)
    fusion = streaming_fusion(settings, setup)
    camera = CameraPipeline(visual_odometry(settings, setup), fusion, settings.node.image_queue)
    intake = Intake(fusion)
    tex = texture()
    ages, predicted = [], []
    stop = threading.Event()

    def reader():
        while not stop.wait(0.02):
            t = time.time()
            est = fusion.current_estimate(t) if fusion.current_estimate() is not None else None
            if est is not None:
                ages.append(time.time() - t)
                predicted.append(est.predicted)

    threading.Thread(target=reader, daemon=True).start()
    plan = schedule(args)
    start = time.time() + 0.2
    for offset, kind, k in plan:
        delay = start + offset - time.time()
        if delay > 0:
            time.sleep(delay)
        t = time.time()
        if kind == "image":
            camera.put(t, frame(tex, k).copy())
        elif kind == "imu":
            intake.put(t, "imu", ImuSample(t, np.zeros(3), np.array([0.0, 0.0, 9.81])))
        else:
            intake.put(t, "odom", TwistSample(t, SPEED * args.camera_hz, 0.0, 0.0))
    elapsed = time.time() - start
    time.sleep(1.5)
    stop.set()
    camera.stop()
    intake.stop()
    return {"offered": len(plan) / args.seconds, "taken": len(plan) / elapsed, "frames": camera.frames / elapsed,
            "dropped": camera.dropped, "unusable": 0, "age": percentiles(ages), "predicted": percentiles(predicted),
            "poses": len(ages)}


def main() -> None:
    p = common.parser(__doc__)
    p.add_argument("--seconds", type=float, default=20.0)
    p.add_argument("--camera-hz", type=float, default=60.0)
    p.add_argument("--imu-hz", type=float, default=200.0)
    p.add_argument("--odom-hz", type=float, default=50.0)
    args = p.parse_args()
    if os.environ.get("FUSION_VO_BENCH_NAMESPACE") != "1":  # DDS only inside a loopback-only namespace
        inner = [sys.executable, *sys.argv]
        sys.exit(subprocess.call(["unshare", "-n", "sh", "-c", "ip link set lo up && export "
                                  "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST FUSION_VO_BENCH_NAMESPACE=1 && exec "
                                  + shlex.join(inner)]))
    with tempfile.TemporaryDirectory() as tmp:
        calib = Path(tmp)
        (calib / "cam0").mkdir()
        (calib / "cam0" / "sensor.yaml").write_text(CAM0.format(hz=args.camera_hz))
        (calib / "imu0").mkdir()
        (calib / "imu0" / "sensor.yaml").write_text(IMU0)
        load = os.getloadavg()[0]
        base = run_in_process(args, calib)
        node = run_node(args, calib)
    print(f"ros2_node: {args.seconds:g} s of a 640x360 camera at {args.camera_hz:g} Hz, IMU {args.imu_hz:g} Hz, "
          f"odometry {args.odom_hz:g} Hz on {os.cpu_count()} cores (load average {load:.1f} before, "
          f"{os.getloadavg()[0]:.1f} after)")
    print("| fed | messages/s offered / taken | camera frames/s processed (dropped) | pose age p50 / p99 "
          "| predicted beyond the processed state p50 / p99 |")
    print("|---|---|---|---|---|")
    for name, r in (("StreamingFusion in-process (baseline)", base), ("fusion-vo ros2 over DDS", node)):
        print(f"| {name} | {r['offered']:.0f} / {r['taken']:.0f} | {r['frames']:.1f} ({r['dropped']}) | {r['age']} "
              f"| {r['predicted']} |")
    print(json.dumps({"baseline": base, "node": node}))
    sys.stdout.flush()
    os._exit(0)  # (rclpy's teardown with a spinning thread is not what is measured)


if __name__ == "__main__":
    main()
