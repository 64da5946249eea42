"""False alarms of the consistency monitor: honest streams dropped on clean generated drives.

Every stream of :func:`fusion_vo.sensors.synthetic.synthetic_streams` is honest (its noise is the noise
the configuration states), so whatever the monitor drops there is a false alarm that throws information
away. The drives carry wheels, gyro and an AHRS heading of ``--ahrs-sigma`` (the Husky's set, with
encoders instead of a twist), with and without the camera, for each duration, gyro bias and seed. The
whole-recording check is run through the EKF (:func:`fusion_vo.backends.fuse`, default configuration;
the check is the same for every backend); the causal check (:mod:`fusion_vo.backends.live_monitor`)
through the streaming EKF, fed sample by sample, on the ``--stream-seeds`` first seeds of the longest
duration with the camera. It prints each run that dropped something and the count.

Usage::

    python benchmarks/monitor_false_alarms.py [--seeds 8] [--durations 60,120] [--biases 0,0.005,0.01]
        [--stream-seeds 4] [--ahrs-sigma 0.02]
"""

from __future__ import annotations

import argparse
import time

from fusion_vo.backends import FusionConfig, SensorStreams, fuse
from fusion_vo.backends.streaming import streaming_for, time_ordered_messages
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams


def streams_for(duration: float, bias: float, seed: int, camera: bool, ahrs_sigma: float) -> SensorStreams:
    """A clean generated drive with wheels, gyro and AHRS (and the camera's increments if ``camera``)."""
    s = synthetic_streams(SyntheticOptions(duration=duration, ahrs_sigma=ahrs_sigma, gyro_bias=bias), seed=seed)
    return SensorStreams(visual=s.visual if camera else None, camera_height=s.camera_height, wheel=s.wheel,
                         imu=s.imu)


def streamed(streams: SensorStreams) -> list[dict]:
    """The spans the causal check dropped when ``streams`` is fed to the streaming EKF sample by sample."""
    fusion = streaming_for(streams, "ekf", FusionConfig())
    for _, kind, message in time_ordered_messages(streams):
        getattr(fusion, f"add_{kind}")(message)
    return fusion.finish().inconsistent


def describe(episodes: list[dict]) -> str:
    return "; ".join(f"{e['component']} {e['start']:.1f}-{e['end']:.1f} s NIS {e['max_nis']:.0f}" for e in episodes)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--durations", default="60,120", help="drive lengths [s], comma-separated")
    parser.add_argument("--biases", default="0,0.005,0.01", help="true gyro biases [rad/s], comma-separated")
    parser.add_argument("--stream-seeds", type=int, default=4, help="seeds also streamed (0: none)")
    parser.add_argument("--ahrs-sigma", type=float, default=0.02, help="AHRS heading noise [rad], white")
    args = parser.parse_args(argv)
    durations = [float(v) for v in args.durations.split(",")]
    biases = [float(v) for v in args.biases.split(",")]
    t0 = time.process_time()
    runs = alarms = 0
    print(f"whole-recording check (EKF), wheels + gyro + AHRS (sigma {args.ahrs_sigma:g} rad) [+ camera]")
    for duration in durations:
        for bias in biases:
            for seed in range(args.seeds):
                for camera in (False, True):
                    episodes = fuse(streams_for(duration, bias, seed, camera, args.ahrs_sigma), "ekf",
                                    FusionConfig()).inconsistent
                    runs += 1
                    if episodes:
                        alarms += 1
                        print(f"  {duration:g} s, bias {bias:g}, seed {seed}, {'camera' if camera else 'no camera'}: "
                              f"{describe(episodes)}")
    print(f"runs with a drop: {alarms} of {runs}")
    if args.stream_seeds:
        runs = alarms = 0
        print(f"causal check (streaming EKF), {max(durations):g} s, bias {biases[-1]:g}, with camera")
        for seed in range(args.stream_seeds):
            episodes = streamed(streams_for(max(durations), biases[-1], seed, True, args.ahrs_sigma))
            runs += 1
            if episodes:
                alarms += 1
                print(f"  seed {seed}: {describe(episodes)}")
        print(f"runs with a drop: {alarms} of {runs}")
    print(f"CPU {time.process_time() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
