"""The fusion runs of ``test_sensor_instances.py``: generated drives with ``odom1`` (another base's twist) and ``imu1``
(a second gyro mounted upside down) fused by every backend, batch and streamed.

``python tests/sensors/instances_job.py OUT`` makes them all and writes ``OUT/runs.pkl`` (each run's trajectories,
counts and calibration, and the drives' ground truth). The session's second process runs it ahead
(tests/background.py); a test run without that process calls :func:`make` itself. Seeds are fixed: the runs are the
same in either process.
"""

from __future__ import annotations

import pickle
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fusion_vo.backends import SensorStreams, fuse
from fusion_vo.backends.streaming import streaming_for, time_ordered_messages
from fusion_vo.measurements import ImuData, TwistData
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams

#: a gyro mounted upside down: its z axis is the body's -z (a half turn about x)
UPSIDE_DOWN = np.diag([1.0, -1.0, -1.0, 1.0])
IMU1_BIAS = 0.02  # [rad/s] in the body frame
#: a component of odom1's twist corrupted (test_a_masked_component_has_no_influence)
CORRUPT = {
    "yaw_rate": lambda tw: TwistData(tw.t, tw.vx, tw.vy, tw.wz + 0.3),
    "vx": lambda tw: TwistData(tw.t, 1.5 * tw.vx, tw.vy, tw.wz),
    "vy": lambda tw: TwistData(tw.t, tw.vx, tw.vy + 0.2, tw.wz),
}
#: odom1's masks of test_a_masked_odometry_chains_between_keyframes
CHAIN_MASKS = (("vx", "yaw_rate"), ("vx", "vy"))
NO_LAG = {"graph": {"fixed_lag": 0.0}}


@dataclass
class Run:
    """What the tests read of a :class:`~fusion_vo.backends.result.FusionResult`."""

    trajectories: dict
    counts: dict
    calibration: dict


def _truth_rates(truth, t):
    """Forward speed and yaw rate of the ground truth at times ``t``."""
    dt = np.gradient(truth.t)
    v = np.hypot(np.gradient(truth.xyyaw[:, 0]), np.gradient(truth.xyyaw[:, 1])) / dt
    w = np.gradient(np.unwrap(truth.xyyaw[:, 2])) / dt
    return np.interp(t, truth.t, v), np.interp(t, truth.t, w)


def twist(truth, seed: int, hz: float = 50.0) -> TwistData:
    """Another base's odometry twist: the truth's speed and yaw rate with 1 cm/s and 0.01 rad/s of noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(truth.t[0], truth.t[-1], 1.0 / hz)
    v, w = _truth_rates(truth, t)
    return TwistData(t, v + rng.normal(0.0, 0.01, len(t)), np.zeros(len(t)), w + rng.normal(0.0, 0.01, len(t)))


def upside_down_gyro(truth, seed: int, T_BS=UPSIDE_DOWN) -> ImuData:
    """A second gyro at 100 Hz mounted upside down, with a body-frame bias of ``IMU1_BIAS`` and 2e-3 rad/s/√Hz of
    noise: its own z reads minus the body's yaw rate."""
    rng = np.random.default_rng(seed)
    t = np.arange(truth.t[0], truth.t[-1], 0.01)
    _, w = _truth_rates(truth, t)
    body = w + IMU1_BIAS + rng.normal(0.0, 2e-3 * np.sqrt(100.0), len(t))
    gyro = np.column_stack([rng.normal(0, 1e-3, len(t)), rng.normal(0, 1e-3, len(t)), -body])
    accel = np.tile([0.0, 0.0, -9.81], (len(t), 1))
    return ImuData(t, gyro, accel, None, np.asarray(T_BS, dtype=np.float64), 100.0, {})


def _kept(result) -> Run:
    return Run(result.trajectories, result.counts, result.calibration)


def _fused(streams: SensorStreams, sensors: list[str], backend: str = "all", config=None) -> Run:
    return _kept(fuse(streams.select(sensors), backend, config))


def _streamed(streams: SensorStreams, backend: str, config=None) -> Run:
    """Every sample through the streaming fusion as ``fusion-vo replay`` feeds it."""
    fusion = streaming_for(streams, backend, config)
    fusion.feed(time_ordered_messages(streams))
    return _kept(fusion.finish())


def runs() -> dict:
    """Every run the tests read, by name, and the two drives' ground truth (``truth/drive``, ``truth/skewed``)."""
    out: dict = {}
    # 40 s of wheels and gyro (its bias 0.01 rad/s), and the same drive's twist as another odometer would give
    s = synthetic_streams(SyntheticOptions(duration=40.0), seed=11)
    tw, other = twist(s.truth, seed=6), twist(s.truth, seed=7)
    out["truth/drive"] = s.truth
    alone = {"graph": {"fixed_lag": 0.0}, "sync_odometry": False}
    for others in ([], ["imu"]):
        key = "+".join(others) or "alone"
        out[f"odom0/{key}"] = _fused(SensorStreams(imu=s.imu, odom=tw), others + ["odom"], config=alone)
        out[f"odom1/{key}"] = _fused(SensorStreams(imu=s.imu, extra={"odom1": tw}), others + ["odom1"], config=alone)
        out[f"both/{key}"] = _fused(SensorStreams(imu=s.imu, odom=tw, extra={"odom1": other}),
                                    others + ["odom", "odom1"], config=alone)
    for backend in ("ekf", "gtsam"):
        out[f"stream/{backend}/odom0"] = _streamed(SensorStreams(odom=tw), backend, {"sync_odometry": False})
        out[f"stream/{backend}/odom1"] = _streamed(SensorStreams(extra={"odom1": tw}), backend, {"sync_odometry": False})
    for component, corrupt in CORRUPT.items():
        masked = {**NO_LAG, "odom1": {"mask": [c for c in ("vx", "vy", "yaw_rate") if c != component]}}
        for name, data, config in (("clean", tw, masked), ("corrupted", corrupt(tw), masked),
                                   ("kept", corrupt(tw), NO_LAG)):
            out[f"mask/{component}/{name}"] = _fused(SensorStreams(wheel=s.wheel, imu=s.imu, extra={"odom1": data}),
                                                     ["wheel", "imu", "odom1"], config=config)
    for mask in CHAIN_MASKS:
        for every in (1, 3):
            config = {"graph": {"keyframe_every": every, "fixed_lag": 0.0, "online": False}, "odom1": {"mask": list(mask)}}
            out[f"chain/{'+'.join(mask)}/{every}"] = _fused(SensorStreams(imu=s.imu, extra={"odom1": tw}),
                                                            ["imu", "odom1"], "gtsam", config)
    own = {**NO_LAG, "odom1": {"yaw_scale": 0.0, "k_yaw": 1e-3}}
    for name, config in (("own", own), ("plain", NO_LAG)):
        out[f"section/odom1/{name}"] = _fused(SensorStreams(imu=s.imu, extra={"odom1": tw}), ["imu", "odom1"],
                                              config=config)
        out[f"section/odom0/{name}"] = _fused(SensorStreams(imu=s.imu, odom=tw), ["imu", "odom"], config=config)
    # 30 s of wheels whose base is 5 % larger than configured (their heading drifts), the built-in gyro, and a
    # second gyro mounted upside down with its own bias
    s = synthetic_streams(SyntheticOptions(duration=30.0, wheel_base_factor=1.05), seed=12)
    gyro1 = upside_down_gyro(s.truth, seed=3)
    flat = ImuData(gyro1.t, gyro1.gyro, gyro1.accel, None, np.eye(4), 100.0, {})
    out["truth/skewed"] = s.truth
    out["imu1/wheels"] = _fused(SensorStreams(wheel=s.wheel), ["wheel"], config=NO_LAG)
    out["imu1/imu0"] = _fused(SensorStreams(wheel=s.wheel, imu=s.imu), ["wheel", "imu"], config=NO_LAG)
    out["imu1/imu1"] = _fused(SensorStreams(wheel=s.wheel, extra={"imu1": gyro1}), ["wheel", "imu1"], config=NO_LAG)
    out["imu1/flat"] = _fused(SensorStreams(wheel=s.wheel, extra={"imu1": flat}), ["wheel", "imu1"], config=NO_LAG)
    for backend in ("ekf", "gtsam"):
        out[f"stream/{backend}/wheels"] = _streamed(SensorStreams(wheel=s.wheel), backend)
        out[f"stream/{backend}/imu1"] = _streamed(SensorStreams(wheel=s.wheel, extra={"imu1": gyro1}), backend)
    return out


def make(out) -> Path:
    """:func:`runs` written to ``out/runs.pkl``; returns ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "runs.pkl").write_bytes(pickle.dumps(runs()))
    return out


if __name__ == "__main__":
    import instances_job  # (the runs pickled as this module's, which the tests import, not as __main__'s)

    instances_job.make(sys.argv[1])
