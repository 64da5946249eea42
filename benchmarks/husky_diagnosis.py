"""Why the fused tracks of robot_localization's Husky log drift: the figures behind
benchmarks/findings/robot_logs.md "Real robots".

The recording is ``tests/data/robot_localization/test1.bag`` (BSD; 395 s, 359 m, odometry twist 10 Hz,
IMU 30 Hz, GPS 2.5 Hz), imported as :mod:`examples.husky_gps` does. GPS is never fused here: it is the
reference (after the least-squares SE(2) alignment of each track to the fixes). The script prints

1. time offsets between the streams (odometry twist vs gyro from their yaw rates, odometry speed vs
   GPS speed), the standstills the odometry reports and the gyro's median rate and scatter there
   (its bias and its real noise, beside the noise the recording claims);
2. the wheels' yaw rate against the gyro's: the skid-steer ratio in turns and on the long, gently
   curved legs, and the gyro bias the wheels imply on those legs;
3. the odometry's speed scale against the GPS path (per 40 s and overall) and the AHRS heading's
   largest departure from the gyro's integral (why the consistency monitor drops it);
4. baselines measured in the same run: wheel + gyro dead reckoning with a constant gyro bias (the
   whole-log standstill median, zero, the best constant in hindsight) and with the odometry's speed
   scaled (what a scale known from outside would give);
5. the EKF's gyro-bias estimate over time (filtered and smoothed) against the standstill median, for
   the default configuration and two ablations (wheel yaw rate not used; a 0.002 rad/s bias prior);
6. each track's error against GPS over time (50 s bins): dead reckoning, EKF, EKF+RTS, GTSAM batch, iSAM2;
7. three candidate models for the last metres, measured: how the smoothers depend on the last second
   the AHRS is kept (the monitor's span edge moved by hand, ``--edges``), a gyro scale factor (the
   slope of the AHRS heading against the gyro's integral where the AHRS is kept, and the fused tracks
   with the gyro scaled), and the accelerometer as a speed-scale observation (forward acceleration
   integrated over the start, the stop and the restart against the odometry's speed change);
8. the gyro's noise at rest as a fourth candidate: its white noise density measured at the standstill
   (:func:`fusion_vo.sensors.imu.rest_noise_density`) and given to the backends for the intervals at
   rest (``imu.gyro_rest_noise_density``), so that the zero-velocity update pins the bias, with and
   without the AHRS, beside the default; the same with a tighter zero-velocity update, and other
   settings of the odometry's error model (each one changed alone);
9. each sensor's model against what the log shows of it, each change beside the default in the same run:
   the IMU's mounting (gravity in the body frame, and the gyro read about the vertical instead of the body's
   z axis), the gyro's Allan deviation at rest and its bias random walk, the odometry twist's yaw-rate
   error against the gyro (size and correlation time), and the AHRS heading's departure from the gyro
   (delay, white part, slow part and its correlation time) with the AHRS offset modelled as a
   Gauss-Markov error of that size (EKF only);
10. the gyro bias random walk by maximum likelihood, without GPS: the one standstill's samples alone (a
   bias walk plus white noise), and the EKF's prediction-error log-likelihood ``L`` over the whole log
   (:mod:`noise_likelihood` beside this script, which checks the method on generated drives): ``L``
   profiled over the walk with and without the AHRS, its maximum found by a bounded search, ``L`` jointly
   with the AHRS's noise model (white sigma, offset random walk, Gauss-Markov offset), all four backends
   at the estimates beside the default and dead reckoning, and the same profile on robot_localization's
   Jackal log (``test2.bag``).

Usage::

    python benchmarks/husky_diagnosis.py [BAG] [--section9] [--section10]

Takes a few minutes (GTSAM batch and iSAM2 over the whole log, once per variant of sections 5-10);
``--section9`` prints section 9 alone (about 3 minutes), ``--section10`` section 10 alone.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "examples"))

from husky_gps import DEFAULT_BAG, HUSKY_IMU_TF, gps_errors, read_gps  # noqa: E402

from fusion_vo.backends import FusionConfig, SensorStreams, fuse  # noqa: E402
from fusion_vo.backends import ekf as ekf_mod  # noqa: E402
from fusion_vo.backends.batch import synchronise_odometry, with_recorded_noise  # noqa: E402
from fusion_vo.backends.timeline import build_intervals  # noqa: E402
from fusion_vo.geometry import se2  # noqa: E402
from fusion_vo.measurements import PoseData  # noqa: E402
from fusion_vo.recording import Recording  # noqa: E402
from fusion_vo.recording.rosbag import import_bag, parse_static_tf  # noqa: E402
from fusion_vo.sensors.imu import (ImuNoise, ahrs_heading, cumulative_angle, gated_yaw_rate, gyro_yaw,  # noqa: E402
                                   quat_to_matrix, rest_noise_density)
from fusion_vo.sensors.sync import rate_delay  # noqa: E402

BINS = 50.0  # [s] error-over-time bins
JACKAL_BAG = REPO / "tests" / "data" / "robot_localization" / "test2.bag"
COURSE_BIN = 25.0  # [s] heading-against-GPS-course bins


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``[a, b)`` index runs where ``mask`` is True."""
    edges = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)))


def dead_reckoning(odom, gyro, bias: float, delay: float, speed_scale: float = 1.0) -> PoseData:
    """Odometry speed along the gyro's heading minus a constant ``bias``, twist moved back by ``delay``."""
    t = np.asarray(odom.t) - delay
    angle = cumulative_angle(gyro) - bias * (gyro.t - gyro.t[0])
    dist = np.diff(t) * np.asarray(odom.vx)[:-1] * speed_scale
    dyaw = np.diff(np.interp(t, gyro.t, angle))
    yaw = np.concatenate([[0.0], np.cumsum(dyaw)])
    mid = yaw[:-1] + 0.5 * dyaw
    x = np.concatenate([[0.0], np.cumsum(dist * np.cos(mid))])
    y = np.concatenate([[0.0], np.cumsum(dist * np.sin(mid))])
    return PoseData(t, np.stack([x, y, yaw], axis=1))


def gps_course(t_gps: np.ndarray, enu: np.ndarray, half: int = 4, min_speed: float = 0.5):
    """Times and heading [rad] of the GPS track where it moves faster than ``min_speed`` [m/s].

    The fixes are averaged over 5 (2 s at 2.5 Hz), then differenced over ``2 half`` fixes (3.2 s): with
    the fixes' ~0.9 m scatter, one bin of the course is good to a few degrees, not to one.
    """
    e = np.convolve(enu[:, 0], np.ones(5) / 5.0, mode="same")
    n = np.convolve(enu[:, 1], np.ones(5) / 5.0, mode="same")
    de, dn = e[2 * half:] - e[:-2 * half], n[2 * half:] - n[:-2 * half]
    t = t_gps[half:-half]
    speed = np.hypot(de, dn) / (t_gps[2 * half:] - t_gps[:-2 * half])
    keep = (speed > min_speed) & (np.arange(len(t)) >= 2) & (np.arange(len(t)) < len(t) - 2)
    return t[keep], np.arctan2(dn, de)[keep]


def heading_departure(t: np.ndarray, angle: np.ndarray, course_t: np.ndarray, course: np.ndarray) -> np.ndarray:
    """GPS course minus a heading source at the course's times [rad], with the source's constant offset
    (its unknown north) taken as the circular mean over the first 60 s."""
    dev = np.angle(np.exp(1j * (course - np.interp(course_t, t, angle))))
    first = course_t - course_t[0] < 60.0
    return np.angle(np.exp(1j * (dev - np.angle(np.mean(np.exp(1j * dev[first]))))))


def rms(err: np.ndarray) -> float:
    return float(np.sqrt(np.mean(err**2)))


def ekf_bias_track(streams: SensorStreams, config: FusionConfig, drop_wheel_yaw: bool = False):
    """Node times, filtered and smoothed gyro bias and its sigma, and the filtered/smoothed tracks."""
    config = with_recorded_noise(config, streams)
    streams, _ = synchronise_odometry(streams, config)
    iv = build_intervals(streams, config)
    if drop_wheel_yaw:
        iv.wheel_yaw_ok[:] = False
    kv, kb = ekf_mod.calibration_observable(iv)
    f = ekf_mod.PlanarEkf(config, iv.camera_height, kv, kb, iv.twist, iv.visual_scale_sigma, iv.wheel_scale_sigma)
    meas = ekf_mod.interval_measurements(iv, config)
    n = iv.n_steps + 1
    xs, Ps = np.zeros((n, ekf_mod.DIM)), np.zeros((n, ekf_mod.DIM, ekf_mod.DIM))
    xp, Pp, Fs = np.zeros_like(xs), np.zeros_like(Ps), np.zeros_like(Ps)
    xs[0], Ps[0] = f.x, f.P
    for k in range(iv.n_steps):
        Fs[k + 1] = f.predict(iv.dt[k])
        xp[k + 1], Pp[k + 1] = f.x, f.P
        f.update(ekf_mod.step_blocks(f, meas, k))
        xs[k + 1], Ps[k + 1] = f.x, f.P
    xsm, Psm = ekf_mod.rts_smooth(xs, Ps, xp, Pp, Fs)
    b = ekf_mod.BG
    return (iv.t, xs[:, b], np.sqrt(Ps[:, b, b]), xsm[:, b],
            PoseData(iv.t.copy(), xs[:, :3].copy()), PoseData(iv.t.copy(), xsm[:, :3].copy()))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("bag", nargs="?", default=str(DEFAULT_BAG), help="robot_localization's test1.bag")
    parser.add_argument("--section9", action="store_true", help="print section 9 only")
    parser.add_argument("--section10", action="store_true", help="print section 10 only")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        seq = Path(tmp) / "husky"
        import_bag(args.bag, seq, static_tfs=[parse_static_tf(HUSKY_IMU_TF)], overwrite=True)
        rec = Recording(seq)
        odom, imu = rec.odom(), rec.imu()
        t_gps, enu = read_gps(seq)
    t0 = float(odom.t[0])
    if args.section9:
        gyro = gyro_yaw(imu, ImuNoise())
        sensor_model_candidates(odom, imu, t_gps, enu, rate_delay(odom.t, odom.wz, gyro.t, gyro.rate) or 0.0)
        return 0
    if args.section10:
        gyro = gyro_yaw(imu, ImuNoise())
        likelihood_candidates(odom, imu, t_gps, enu, rate_delay(odom.t, odom.wz, gyro.t, gyro.rate) or 0.0, JACKAL_BAG)
        return 0
    claimed = float(imu.noise.get("gyroscope_noise_density", np.nan))
    gyro = gyro_yaw(imu, ImuNoise())
    rate_hz = 1.0 / float(np.median(np.diff(gyro.t)))

    print("1. clocks and standstills")
    delay = rate_delay(odom.t, odom.wz, gyro.t, gyro.rate) or 0.0
    print(f"  odometry twist behind the gyro (yaw-rate cross-correlation): {delay * 1e3:.0f} ms")
    gspeed = np.linalg.norm(np.diff(enu, axis=0), axis=1) / np.diff(t_gps)
    gps_delay = rate_delay(t_gps[1:] - 0.5 * np.diff(t_gps), gspeed, odom.t - delay, np.abs(odom.vx),
                           min_correlation=0.3)
    print("  GPS speed behind the odometry speed: "
          + ("not resolved" if gps_delay is None else f"{gps_delay * 1e3:.0f} ms"))
    still = (np.abs(odom.vx) < 1e-3) & (np.abs(odom.wz) < 1e-3)
    at_imu = np.interp(gyro.t, odom.t, still.astype(float)) > 0.999
    for a, b in runs(at_imu):
        if gyro.t[b - 1] - gyro.t[a] > 1.0:
            r = gyro.rate[a:b]
            print(f"  standstill {gyro.t[a] - t0:6.1f}-{gyro.t[b - 1] - t0:6.1f} s: "
                  f"gyro median {np.median(r):+.5f} rad/s, "
                  f"scatter {np.std(r):.5f} rad/s = noise density {np.std(r) / np.sqrt(rate_hz):.2e} rad/s/sqrt(Hz) "
                  f"(recording claims {claimed:.2e})")
    bias0 = float(np.median(gyro.rate[at_imu])) if at_imu.sum() > 10 else 0.0
    print(f"  whole-log standstill bias (used by the dead-reckoning baseline): {bias0:+.5f} rad/s")
    window = int(round(2.0 * rate_hz))
    quiet = np.array([np.std(gyro.rate[i:i + window]) for i in range(0, len(gyro.rate) - window, window)])
    print(f"  gyro scatter over 2 s windows while driving: 5th percentile {np.quantile(quiet, 0.05):.4f} rad/s "
          f"(at rest {np.std(gyro.rate[at_imu]):.4f}): a gyro-variance detector finds no other standstill")

    print("2. wheels' yaw rate against the gyro's (twist moved back by its delay)")
    g = np.interp(odom.t - delay, gyro.t, gyro.rate) - bias0
    moving = np.abs(odom.vx) > 0.1
    for name, sel in (("turns |w| > 0.1 rad/s", moving & (np.abs(g) > 0.1)),
                      ("gentle curves 0.002 < |w| < 0.05", moving & (np.abs(g) > 0.002) & (np.abs(g) < 0.05))):
        ratio = float(np.sum(odom.wz[sel] * g[sel]) / np.sum(g[sel] ** 2))
        print(f"  {name:34s} wheels/gyro {ratio:.2f} over {sel.sum() / 10:.0f} s")
    legs = moving & (np.abs(g) < 0.05)
    k_turn = float(np.sum(odom.wz[moving & (np.abs(g) > 0.1)] * g[moving & (np.abs(g) > 0.1)])
                   / np.sum(g[moving & (np.abs(g) > 0.1)] ** 2))
    pull = []
    for s in range(0, 240, 40):
        m = legs & (odom.t - t0 >= s) & (odom.t - t0 < s + 40)
        if m.sum() > 20:
            pull.append(float(np.mean(g[m] + bias0 - odom.wz[m] / k_turn)))
    print(f"  gyro bias the wheels imply on the legs before the stop (turn ratio {k_turn:.2f}), per 40 s: "
          + " ".join(f"{p:+.4f}" for p in pull) + f" rad/s (standstill: {bias0:+.5f})")

    print("3. odometry speed scale against GPS, AHRS heading")
    ratios = []
    for s in range(0, int(t_gps[-1] - t_gps[0]), 40):
        m = (t_gps - t_gps[0] >= s) & (t_gps - t_gps[0] < s + 40)
        path_gps = float(np.sum(np.linalg.norm(np.diff(enu[m][::5], axis=0), axis=1)))
        mo = (odom.t - t0 >= s) & (odom.t - t0 < s + 40)
        path_odom = float(np.sum(np.abs(odom.vx[mo][:-1]) * np.diff(odom.t[mo])))
        ratios.append(path_gps / path_odom)
    print("  GPS path / odometry path per 40 s (fixes every 2 s): " + " ".join(f"{r:.2f}" for r in ratios)
          + f"; median {np.median(ratios):.3f}")
    heading = ahrs_heading(imu)
    if heading is not None:
        yaw = np.unwrap(heading.yaw[heading.valid])
        ht = heading.t[heading.valid]
        gi = np.interp(ht, gyro.t, cumulative_angle(gyro) - bias0 * (gyro.t - gyro.t[0]))
        dev = (yaw - yaw[0]) - (gi - gi[0])
        print(f"  AHRS heading minus the gyro's integral: largest {np.degrees(np.abs(dev).max()):.0f} deg "
              f"(at {ht[np.argmax(np.abs(dev))] - t0:.0f} s)")

    print("3b. which heading is right where: each source against the GPS course (speed > 0.5 m/s)")
    course_t, course = gps_course(t_gps, enu)
    sources = {"gyro (standstill bias)": (gyro.t, cumulative_angle(gyro) - bias0 * (gyro.t - gyro.t[0])),
               "wheels (twist yaw rate)": (odom.t - delay, np.concatenate([[0.0], np.cumsum(np.diff(odom.t) * odom.wz[:-1])]))}
    if heading is not None:
        sources["AHRS"] = (ht, yaw)
    departures = {name: heading_departure(tt, ang, course_t, course) for name, (tt, ang) in sources.items()}
    edges = np.arange(0.0, course_t[-1] - t0 + COURSE_BIN, COURSE_BIN)
    print(f"  median of (GPS course - source) per {COURSE_BIN:.0f} s [deg], each source's offset set on the first 60 s")
    print(f"  {'source':26s} " + " ".join(f"{int(e):>4d}" for e in edges[:-1]) + "   |dev| <= 10 deg before / after 190 s")
    for name, dev in departures.items():
        tt = course_t - t0
        med = [np.degrees(np.median(dev[(tt >= a) & (tt < b)])) if np.any((tt >= a) & (tt < b)) else np.nan
               for a, b in zip(edges[:-1], edges[1:])]
        early, late = tt < 190.0, tt >= 190.0
        share = [100.0 * np.mean(np.abs(np.degrees(dev[m])) <= 10.0) for m in (early, late)]
        print(f"  {name:26s} " + " ".join(f"{v:4.0f}" for v in med) + f"   {share[0]:3.0f} % / {share[1]:3.0f} %")

    print("4. dead-reckoning baselines (odometry speed, gyro heading), RMS against GPS [m]")
    biases = np.linspace(-0.0008, 0.0004, 25)
    scan = [rms(gps_errors(dead_reckoning(odom, gyro, b, delay), t_gps, enu)) for b in biases]
    best = int(np.argmin(scan))
    for label, b in (("standstill bias", bias0), ("bias 0", 0.0), ("bias +0.0005", 0.0005), ("bias -0.0005", -0.0005)):
        print(f"  {label:36s} {rms(gps_errors(dead_reckoning(odom, gyro, b, delay), t_gps, enu)):5.2f}")
    print(f"  {'best constant bias ' + f'{biases[best]:+.5f}':36s} {scan[best]:5.2f}  (hindsight from GPS)")
    lags = [rms(gps_errors(dead_reckoning(odom, gyro, bias0, d), t_gps, enu)) for d in (0.0, 0.2, delay, 0.6)]
    print(f"  {'standstill bias, twist delay 0/0.2/' + f'{delay:.2f}' + '/0.6 s':36s} "
          + " / ".join(f"{v:.2f}" for v in lags))
    for scale in (0.96, 0.97, 0.98):
        print(f"  {f'standstill bias, speed x {scale}':36s} "
              f"{rms(gps_errors(dead_reckoning(odom, gyro, bias0, delay, scale), t_gps, enu)):5.2f}  (scale from GPS)")

    print("5. EKF gyro bias [rad/s] over time (GPS not fused)")
    base = SensorStreams(odom=odom, imu=dataclasses.replace(imu, orientation=None))
    variants = {"default": (FusionConfig(), False),
                "wheel yaw rate not used": (FusionConfig(), True),
                "bias prior 0.002": (FusionConfig.from_dict({"imu": {"gyro_bias_sigma": 0.002}}), False)}
    marks = (20, 100, 200, 235, 250, 395)
    print(f"  {'variant':26s} " + " ".join(f"{m:>16d}" for m in marks) + "   EKF / RTS RMS m")
    for name, (cfg, drop) in variants.items():
        t, bf, sf, bs, trk, trk_s = ekf_bias_track(base, cfg, drop)
        idx = [int(np.searchsorted(t - t0, m)) - 1 for m in marks]
        print(f"  {name:26s} " + " ".join(f"{bf[i]:+.4f}/{bs[i]:+.4f}" for i in idx)
              + f"   {rms(gps_errors(trk, t_gps, enu)):.2f} / {rms(gps_errors(trk_s, t_gps, enu)):.2f}")
        if name == "default":
            print(f"  {'(filter sigma)':26s} " + " ".join(f"{sf[i]:16.4f}" for i in idx))
    print("  (filtered/smoothed; the standstill median is " f"{bias0:+.5f})")

    print("6. error against GPS over time [m], mean per 50 s bin (default configuration)")
    tracks = {"dead reckoning (standstill bias)": dead_reckoning(odom, gyro, bias0, delay)}
    for label, streams in (("gyro + AHRS", SensorStreams(odom=odom, imu=imu)), ("gyro only", base)):
        result = fuse(streams, "all", FusionConfig())
        tracks.update({f"{label}: {k}": result.trajectories[k] for k in ("ekf", "ekf_smoothed", "gtsam", "gtsam_online")})
        for note in result.notes:
            if "inconsistent" in note:
                print(f"  {label}: {note}")
    edges = np.arange(0.0, t_gps[-1] - t_gps[0] + BINS, BINS)
    print(f"  {'track':38s} {'RMS':>5s} " + " ".join(f"{int(e):>5d}" for e in edges[:-1]))
    for name, trk in tracks.items():
        inside = (t_gps >= trk.t[0]) & (t_gps <= trk.t[-1])
        err = gps_errors(trk, t_gps, enu)
        tt = t_gps[inside][: len(err)] - t_gps[0]
        bins = [float(np.mean(err[(tt >= a) & (tt < b)])) if np.any((tt >= a) & (tt < b)) else np.nan
                for a, b in zip(edges[:-1], edges[1:])]
        print(f"  {name:38s} {rms(err):5.2f} " + " ".join(f"{v:5.1f}" for v in bins))
    model_candidates(odom, imu, t_gps, enu, t0)
    rest_noise_candidate(odom, imu, t_gps, enu, delay)
    sensor_model_candidates(odom, imu, t_gps, enu, delay)
    likelihood_candidates(odom, imu, t_gps, enu, delay, JACKAL_BAG)
    return 0


@contextlib.contextmanager
def ahrs_kept_until(seconds: float | None):
    """Diagnosis only: the whole-log monitor's decisions, with the AHRS kept up to ``seconds`` after the first node."""
    from fusion_vo.backends import monitor

    check = monitor.check_heading_sources

    def patched(iv, config, gyro_bias=None):
        before = iv.ahrs_ok.copy()
        episodes = check(iv, config, gyro_bias)
        if seconds is not None:
            iv.ahrs_ok = iv.ahrs_ok | (before & (iv.t < iv.t[0] + seconds))
        return episodes

    monitor.check_heading_sources = patched
    try:
        yield
    finally:
        monitor.check_heading_sources = check


def smoother_rms(streams: SensorStreams, t_gps, enu) -> str:
    ekf, graph = fuse(streams, "ekf", FusionConfig()), fuse(streams, "gtsam", FusionConfig())
    return (f"EKF+RTS {rms(gps_errors(ekf.trajectories['ekf_smoothed'], t_gps, enu)):.2f}, "
            f"GTSAM batch {rms(gps_errors(graph.trajectories['gtsam'], t_gps, enu)):.2f} m")


def model_candidates(odom, imu, t_gps, enu, t0: float) -> None:
    print("7. candidate models for the last metres (GPS only as the reference)")
    streams = SensorStreams(odom=odom, imu=imu)
    print("  AHRS kept until [s] (the monitor drops it from 180.3 s):")
    for edge in (None, 182.0, 183.0, 184.0, 185.0, 186.0, 188.0, 190.0):
        with ahrs_kept_until(edge):
            print(f"    {'monitor' if edge is None else f'{edge:.0f}':>8s}: {smoother_rms(streams, t_gps, enu)}")
    gyro = gyro_yaw(imu, ImuNoise().with_sensor_keys(imu.noise))
    angle = cumulative_angle(gyro)
    ahrs = ahrs_heading(imu)
    for lo, hi in ((0.0, 180.0), (60.0, 180.0)):
        m = ahrs.valid & (ahrs.t >= t0 + lo) & (ahrs.t < t0 + hi)
        g = np.interp(ahrs.t[m], gyro.t, angle)
        design = np.column_stack([g, ahrs.t[m] - t0, np.ones(np.count_nonzero(m))])
        coef = np.linalg.lstsq(design, np.unwrap(ahrs.yaw[m]), rcond=None)[0]
        print(f"  AHRS heading = {coef[0]:.4f} x gyro angle + bias x t over {lo:.0f}-{hi:.0f} s "
              "(a gyro scale factor the AHRS would teach)")
    for scale in (0.99, 0.995, 1.005):
        scaled = SensorStreams(odom=odom, imu=dataclasses.replace(imu, gyro=imu.gyro * scale))
        print(f"    gyro x {scale}: {smoother_rms(scaled, t_gps, enu)}")
    accel = (np.asarray(imu.accel) @ np.asarray(imu.T_BS)[:3, :3].T)[:, 0]
    rest = (imu.t > t0 + 237.0) & (imu.t < t0 + 246.0)
    drive = (imu.t > t0 + 20.0) & (imu.t < t0 + 30.0)
    a0, sd = float(np.median(accel[rest])), float(np.std(accel[drive]))
    print(f"  forward acceleration: {a0:+.3f} m/s² at rest (its offset, removed), scatter {sd:.2f} m/s² while driving")
    for lo, hi in ((0.0, 4.0), (233.5, 237.0), (246.0, 250.0)):
        m = (imu.t >= t0 + lo) & (imu.t <= t0 + hi)
        dv_acc = float(np.trapezoid(accel[m] - a0, imu.t[m]))
        dv_odom = float(np.interp(t0 + hi, odom.t, odom.vx) - np.interp(t0 + lo, odom.t, odom.vx))
        white = sd * np.sqrt((hi - lo) * float(np.median(np.diff(imu.t))))
        print(f"    {lo:5.1f}-{hi:5.1f} s: accelerometer {dv_acc:+.2f} m/s, odometry {dv_odom:+.2f} m/s, "
              f"ratio {dv_acc / dv_odom:.2f} ± {white / abs(dv_odom):.2f} (white-noise part only)")


def rest_noise_candidate(odom, imu, t_gps, enu, delay: float) -> None:
    print("8. the gyro's noise at rest used where the wheels are at rest, and other settings (GPS only as the reference)")
    gyro = gyro_yaw(imu, ImuNoise())
    still = ((np.abs(odom.vx) < 1e-3) & (np.abs(odom.wz) < 1e-3)).astype(float)
    resting = np.interp(gyro.t, np.asarray(odom.t) - delay, still) > 0.999  # on the gyro's clock
    density = rest_noise_density(gyro, resting)
    print(f"  density at rest {density:.2e} rad/s/√Hz over {np.count_nonzero(resting)} samples "
          f"(recorded {imu.noise.get('gyroscope_noise_density', float('nan')):.2e})")
    names = ("ekf", "ekf_smoothed", "gtsam", "gtsam_online")
    rest = {"imu": {"gyro_rest_noise_density": density}}
    variants = [("gyro + AHRS", "default", {}), ("gyro + AHRS", "rest density", rest),
                ("gyro only", "default", {}), ("gyro only", "rest density", rest)]
    variants += [("gyro + AHRS", f"rest density, standstill_yaw_rate {v:g}",
                  {**rest, "odom": {"standstill_yaw_rate": v}}) for v in (3e-3, 2e-3, 1e-3)]
    variants += [("gyro + AHRS", f"standstill_yaw_rate {v:g}", {"odom": {"standstill_yaw_rate": v}}) for v in (3e-3, 1e-3)]
    variants += [("gyro + AHRS", f"yaw_scale_time {v:g}", {"odom": {"yaw_scale_time": v}}) for v in (2.0, 10.0, 20.0)]
    variants += [("gyro + AHRS", f"scale_random_walk {v:g}", {"ekf": {"scale_random_walk": v}}) for v in (3e-5, 1e-3)]
    print(f"  {'RMS [m]':52s}" + " ".join(f"{n:>13s}" for n in names) + "  batch gyro bias at the end")
    for label, setting, options in variants:
        source = imu if label == "gyro + AHRS" else dataclasses.replace(imu, orientation=None)
        result = fuse(SensorStreams(odom=odom, imu=source), "all", FusionConfig.from_dict(options))
        errors = [rms(gps_errors(result.trajectories[n], t_gps, enu)) for n in names]
        bias = result.calibration["gtsam"]["gyro_bias"]
        print(f"  {label + ', ' + setting:52s}" + " ".join(f"{e:13.3f}" for e in errors) + f"  {bias * 1e3:+.3f} mrad/s")

def allan_deviation(rate: np.ndarray, dt: float, taus: tuple) -> list[float]:
    """Overlapping Allan deviation [rad/s] of rate samples ``rate`` spaced ``dt`` at averaging times ``taus`` [s]."""
    angle = np.concatenate([[0.0], np.cumsum(rate) * dt])
    out = []
    for tau in taus:
        m = int(round(tau / dt))
        if 2 * m >= len(angle):
            out.append(float("nan"))
            continue
        d = angle[2 * m:] - 2.0 * angle[m:-m] + angle[:-2 * m]
        out.append(float(np.sqrt(np.mean(d**2) / (2.0 * tau**2))))
    return out


def with_yaw_rate(imu, rate: np.ndarray):
    """``imu`` with its gyro changed along the body-z row of ``R_BS`` so that its body yaw rate is ``rate``."""
    axis = np.asarray(imu.T_BS, dtype=np.float64)[2, :3]
    gyro = np.asarray(imu.gyro, dtype=np.float64)
    return dataclasses.replace(imu, gyro=gyro + (rate - gyro @ axis)[:, None] * axis[None, :])


def sensor_model_candidates(odom, imu, t_gps, enu, delay: float) -> None:
    print("9. sensor models against their measured behaviour (GPS only as the reference)")
    names = ("ekf", "ekf_smoothed", "gtsam", "gtsam_online")
    r_bs = np.asarray(imu.T_BS, dtype=np.float64)[:3, :3]
    acc_b = np.asarray(imu.accel, dtype=np.float64) @ r_bs.T
    w_b = np.asarray(imu.gyro, dtype=np.float64) @ r_bs.T
    still = ((np.abs(odom.vx) < 1e-3) & (np.abs(odom.wz) < 1e-3)).astype(float)
    rest = np.interp(imu.t, np.asarray(odom.t) - delay, still) > 0.999
    print("  9a. the IMU's mounting: gravity in the body frame (launch file's static transform applied)")
    for label, m in (("at rest", rest), ("whole log", np.ones(len(rest), bool))):
        g = acc_b[m].mean(axis=0)
        g /= np.linalg.norm(g)
        print(f"    mean accelerometer direction {label:9s}: ({g[0]:+.4f}, {g[1]:+.4f}, {g[2]:+.4f}), "
              f"{np.degrees(np.arccos(g[2])):.2f} deg from body z")
    heading = ahrs_heading(imu)
    r_wb = quat_to_matrix(imu.orientation) @ r_bs.T
    up = r_wb[:, 2, :]  # the world's vertical in body coordinates (AHRS roll and pitch)
    tilt = np.degrees(np.arccos(np.clip(up[:, 2], -1.0, 1.0)))
    print(f"    AHRS tilt of the body: median {np.median(tilt):.2f} deg, 95th percentile {np.quantile(tilt, 0.95):.2f} deg; "
          f"body-z turn {np.sum(np.abs(w_b[:-1, 2]) * np.diff(imu.t)):.3f} rad, about the vertical "
          f"{np.sum(np.abs(np.einsum('nj,nj->n', up, w_b)[:-1]) * np.diff(imu.t)):.3f} rad")
    g_all = acc_b.mean(axis=0) / np.linalg.norm(acc_b.mean(axis=0))
    # the rate of the heading (the yaw of roll-pitch-yaw), psi' = (sin(roll) w_y + cos(roll) w_z) / cos(pitch)
    euler = (up[:, 1] * w_b[:, 1] + up[:, 2] * w_b[:, 2]) / (1.0 - up[:, 0] ** 2)
    rates = {"body z (default)": w_b[:, 2],
             "heading rate, AHRS roll and pitch per sample": euler,
             "about the AHRS vertical, per sample": np.einsum("nj,nj->n", up, w_b),
             "about the mean gravity axis (mounting corrected)": w_b @ g_all}
    print(f"    {'yaw rate':48s} {'DR':>6s}" + " ".join(f"{n:>13s}" for n in names)
          + "  bias at rest (DR) mrad/s")
    for label, rate in rates.items():
        gy = gated_yaw_rate(imu.t, rate)
        bias = float(np.median(gy.rate[rest]))
        dr = rms(gps_errors(dead_reckoning(odom, gy, bias, delay), t_gps, enu))
        result = fuse(SensorStreams(odom=odom, imu=with_yaw_rate(imu, rate)), "all", FusionConfig())
        errors = [rms(gps_errors(result.trajectories[n], t_gps, enu)) for n in names]
        print(f"    {label:48s} {dr:6.3f}" + " ".join(f"{e:13.3f}" for e in errors) + f"  {bias * 1e3:+.3f}")
    b_rest = np.median(w_b[rest], axis=0)
    print(f"    gyro at rest, body x/y/z: {b_rest[0] * 1e3:+.2f} / {b_rest[1] * 1e3:+.2f} / {b_rest[2] * 1e3:+.2f} mrad/s; "
          f"roll at rest {np.degrees(np.median(np.arctan2(up[rest, 1], up[rest, 2]))):+.2f} deg, while driving "
          f"{np.degrees(np.median(np.arctan2(up[~rest, 1], up[~rest, 2]))):+.2f} deg (the tilted rates mix the "
          "y-axis bias into the heading rate's)")

    print("  9b. the gyro at rest: Allan deviation [rad/s] of the standstill (white noise falls as 1/sqrt(tau))")
    gyro = gyro_yaw(imu, ImuNoise())
    dt = float(np.median(np.diff(gyro.t)))
    longest = max(runs(rest), key=lambda r: r[1] - r[0])
    taus = (0.1, 0.3, 1.0, 2.0, 3.0)
    adev = allan_deviation(gyro.rate[longest[0]:longest[1]], dt, taus)
    print("    tau " + " ".join(f"{t:g} s: {a:.2e}" for t, a in zip(taus, adev))
          + f"; white density {adev[0] * np.sqrt(taus[0]):.2e} rad/s/sqrt(Hz); a "
          f"{(longest[1] - longest[0]) * dt:.1f} s standstill cannot show a bias walk")
    for walk in (2e-5, 1e-5, 5e-5, 1e-4):
        result = fuse(SensorStreams(odom=odom, imu=imu), "all",
                      FusionConfig.from_dict({"imu": {"gyro_random_walk": walk}}))
        errors = [rms(gps_errors(result.trajectories[n], t_gps, enu)) for n in names]
        print(f"    gyro_random_walk {walk:g}{' (default)' if walk == 2e-5 else '':10s}"
              + " ".join(f"{e:13.3f}" for e in errors))

    print("  9c. the odometry twist's yaw rate against the gyro (twist moved back by its delay)")
    bias0 = float(np.median(gyro.rate[rest]))
    g = np.interp(np.asarray(odom.t) - delay, gyro.t, gyro.rate) - bias0
    moving = np.abs(odom.vx) > 0.1
    turn = moving & (np.abs(g) > 0.1)
    k = float(np.sum(odom.wz[moving] * g[moving]) / np.sum(g[moving] ** 2))
    rel = odom.wz / k - g
    print(f"    ratio over all motion {k:.3f}; residual yaw rate/gyro rate in turns: std {np.std(rel[turn] / g[turn]):.3f} "
          f"(model yaw_scale 0.3); on straight legs (|w|<0.02): residual std {np.std(rel[moving & (np.abs(g) < 0.02)]):.4f} rad/s")
    r = rel[moving] - rel[moving].mean()
    ac = [float(np.sum(r[:-L] * r[L:]) / np.sum(r * r)) for L in (1, 5, 10, 20, 50, 100)]
    print("    residual autocorrelation at lag 0.1/0.5/1/2/5/10 s: " + " ".join(f"{a:.2f}" for a in ac)
          + " (model yaw_scale_time 5 s)")
    in_turn = [(a, b) for a, b in runs(turn) if b - a >= 30]
    rt = [rel[a:b] / g[a:b] - np.mean(rel[a:b] / g[a:b]) for a, b in in_turn]
    ac = [float(sum(np.sum(x[:-L] * x[L:]) for x in rt if len(x) > L) / sum(np.sum(x * x) for x in rt))
          for L in (1, 5, 10, 20)]
    print(f"    within {len(in_turn)} turns of 3 s or more: relative error about each turn's mean, autocorrelation at "
          "lag 0.1/0.5/1/2 s: " + " ".join(f"{a:.2f}" for a in ac) + "; std of the turns' mean relative error "
          f"{np.std([np.mean(rel[a:b] / g[a:b]) for a, b in in_turn]):.3f}")
    for opts in ({}, {"odom": {"yaw_scale": 0.15}}, {"odom": {"yaw_scale_time": 10.0, "yaw_scale": 0.15}},
                 {"odom": {"k_yaw": 0.05}}, {"odom": {"k_yaw": 0.01}}):
        result = fuse(SensorStreams(odom=odom, imu=imu), "all", FusionConfig.from_dict(opts))
        errors = [rms(gps_errors(result.trajectories[n], t_gps, enu)) for n in names]
        print(f"    {str(opts or 'default'):48s}" + " ".join(f"{e:13.3f}" for e in errors))

    print("  9d. the AHRS heading against the gyro's integral where the monitor keeps it (first 180 s)")
    ahrs = ahrs_heading(imu)
    m = ahrs.valid & (ahrs.t < ahrs.t[0] + 180.0)
    angle = np.interp(ahrs.t[m], gyro.t, cumulative_angle(gyro))
    dev = np.unwrap(ahrs.yaw[m]) - angle
    tt = ahrs.t[m] - ahrs.t[0]
    dev -= np.polyval(np.polyfit(tt, dev, 1), tt)  # a constant gyro bias and the AHRS north removed
    step = float(np.median(np.diff(tt)))
    acf = np.array([np.sum(dev[:-L] * dev[L:]) / np.sum(dev * dev) for L in range(1, int(60.0 / step))])
    tau = step * (1 + int(np.argmax(acf < np.exp(-1.0)))) if np.any(acf < np.exp(-1.0)) else float("nan")
    config = with_recorded_noise(FusionConfig(), SensorStreams(odom=odom, imu=imu))
    node = float(np.median(np.diff(build_intervals(synchronise_odometry(SensorStreams(odom=odom, imu=imu), config)[0],
                                                   config).t)))
    high = dev - np.convolve(dev, np.ones(150) / 150.0, mode="same")
    ahrs_rate = np.gradient(np.unwrap(ahrs.yaw[ahrs.valid]), ahrs.t[ahrs.valid])
    lag = rate_delay(ahrs.t[ahrs.valid], ahrs_rate, gyro.t, gyro.rate, min_correlation=0.3)
    print(f"    AHRS heading behind the gyro (yaw-rate cross-correlation): "
          + ("not resolved" if lag is None else f"{lag * 1e3:.0f} ms")
          + f"; its white part (departure minus its 5 s running mean) {np.degrees(np.std(high[150:-150])):.2f} deg")
    print(f"    departure after the best constant bias: std {np.degrees(np.std(dev)):.1f} deg, correlation time "
          f"{tau:.1f} s; as white noise at the fusion's "
          f"{node:.2f} s nodes that is sigma {np.std(dev) * np.sqrt(2.0 * tau / node):.2f} rad "
          f"(stated ahrs_yaw_sigma 0.02 rad; benchmarks/findings/robot_logs.md: "
          "the fusion given 0.04 to 0.15 rad, the monitor left at 0.02, "
          "gives RTS 2.51 to 2.56 m)")
    implied = []
    for lo, hi in ((0.0, 60.0), (60.0, 120.0), (120.0, 180.0)):
        w = (tt >= lo) & (tt < hi)
        design = np.column_stack([tt[w], np.ones(np.count_nonzero(w))])
        implied.append(-np.linalg.lstsq(design, (np.unwrap(ahrs.yaw[m]) - angle)[w], rcond=None)[0][0])
    print("    gyro bias the AHRS implies over 0-60 / 60-120 / 120-180 s: "
          + " / ".join(f"{b * 1e3:+.2f}" for b in implied) + f" mrad/s (at rest {bias0 * 1e3:+.2f}); a bias walk of "
          f"2e-5 rad/s/sqrt(s) allows about {2e-5 * np.sqrt(60.0) * 1e3:.2f} mrad/s per minute: the AHRS's wander "
          "and a wandering bias cannot be told apart")
    print("  9e. the AHRS offset as a Gauss-Markov error of the measured size (EKF only; the monitor as by default)")
    print(f"    {'offset sigma, correlation time, white sigma':48s}" + " ".join(f"{n:>13s}" for n in names[:2]))
    for sigma, tau_o, white in ((0.0, 0.0, 0.02), (0.08, 12.0, 0.02), (0.08, 12.0, 0.005), (0.04, 12.0, 0.02),
                                (0.08, 60.0, 0.02), (0.04, 60.0, 0.02)):
        with gauss_markov_ahrs_offset(sigma, tau_o):
            cfg = FusionConfig.from_dict({"imu": {"ahrs_yaw_sigma": white, "ahrs_offset_walk": 1e-9 if sigma else 0.0}})
            result = fuse(SensorStreams(odom=odom, imu=imu), "ekf", cfg)
        errors = [rms(gps_errors(result.trajectories[n], t_gps, enu)) for n in names[:2]]
        dropped = sum(1 for n in result.notes if "inconsistent" in n)
        label = "default (absolute heading)" if not sigma else f"{sigma:g} rad, {tau_o:g} s, {white:g} rad"
        print(f"    {label:48s}" + " ".join(f"{e:13.3f}" for e in errors) + f"  ({dropped} spans dropped)")


@contextlib.contextmanager
def gauss_markov_ahrs_offset(sigma: float, tau: float):
    """Diagnosis only: the EKF's AHRS offset as a first-order Gauss-Markov error (stationary ``sigma`` [rad],
    correlation time ``tau`` [s]) instead of a random walk; nothing changes when ``sigma`` is 0."""
    if not sigma:
        yield
        return
    init, predict = ekf_mod.PlanarEkf.__init__, ekf_mod.PlanarEkf.predict
    ao = ekf_mod.AO

    def patched_init(self, *args, **kwargs):
        init(self, *args, **kwargs)
        self.kf.P[ao, ao] = sigma**2

    def patched_predict(self, dt, frame_cov=None):
        phi = float(np.exp(-dt / tau))
        self.kf.x[ao, 0] *= phi
        self.kf.P[ao, :] *= phi
        self.kf.P[:, ao] *= phi
        F = predict(self, dt, frame_cov).copy()
        self.kf.P[ao, ao] += sigma**2 * (1.0 - phi**2)
        self.kf.P_prior = self.kf.P.copy()
        F[ao, ao] = phi
        return F

    ekf_mod.PlanarEkf.__init__, ekf_mod.PlanarEkf.predict = patched_init, patched_predict
    try:
        yield
    finally:
        ekf_mod.PlanarEkf.__init__, ekf_mod.PlanarEkf.predict = init, predict



def rest_walk_likelihood(rate: np.ndarray, dt: float, walk: float) -> float:
    """Log-likelihood of gyro samples at rest as a bias random walk ``walk`` [rad/s/√s] plus white noise, the
    white noise's variance at its maximum-likelihood value (a scalar Kalman filter, diffuse initial bias).

    ``rate`` should be white apart from the walk: the Husky's 30 Hz samples at rest correlate at lag one
    (0.54: the IMU filters its output), which a white-noise model takes for a walk; their 0.1 s means do not
    (0.05), so :func:`likelihood_candidates` passes those.
    """
    def nll(log_var: float) -> float:
        var = float(np.exp(log_var))
        b, p, total = float(rate[0]), 1.0, 0.0
        for y in rate[1:]:
            p += walk**2 * dt
            s = p + var
            total += 0.5 * (np.log(2.0 * np.pi * s) + (y - b) ** 2 / s)
            k = p / s
            b, p = b + k * (y - b), (1.0 - k) * p
        return total

    from scipy.optimize import minimize_scalar

    v0 = float(np.log(np.var(rate)))
    return -float(minimize_scalar(nll, bounds=(v0 - 3.0, v0 + 1.0), method="bounded").fun)


def likelihood_candidates(odom, imu, t_gps, enu, delay: float, jackal_bag: Path | None) -> None:
    import noise_likelihood as nl

    print("10. the gyro bias walk (and the AHRS noise) by maximum likelihood of the EKF's innovations, GPS not used")
    names = ("ekf", "ekf_smoothed", "gtsam", "gtsam_online")
    gyro = gyro_yaw(imu, ImuNoise())
    still = ((np.abs(odom.vx) < 1e-3) & (np.abs(odom.wz) < 1e-3)).astype(float)
    rest = np.interp(gyro.t, np.asarray(odom.t) - delay, still) > 0.999
    longest = max(runs(rest), key=lambda r: r[1] - r[0])
    dt = float(np.median(np.diff(gyro.t)))
    at_rest = gyro.rate[longest[0]:longest[1]]
    walks = (1e-6, 1e-5, 2e-5, 5e-5, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2)
    m = 3  # samples per 0.1 s mean (see rest_walk_likelihood)
    means = at_rest[: len(at_rest) // m * m].reshape(-1, m).mean(axis=1)
    centred = [x - x.mean() for x in (at_rest, means)]
    lag1 = [float(np.sum(x[:-1] * x[1:]) / np.sum(x * x)) for x in centred]
    rest_l = np.array([rest_walk_likelihood(means, dt * m, w) for w in walks])
    best = int(np.argmax(rest_l))
    lo, hi = nl.interval(np.array(walks), rest_l, walks[best], float(rest_l[best]))
    print(f"  10a. the {len(at_rest) * dt:.1f} s standstill alone, as a bias walk + white noise (lag-1 correlation of "
          f"the samples {lag1[0]:.2f}, of their {len(means)} means over {m * dt:.2f} s {lag1[1]:.2f}, which are used):")
    print("    L - Lmax at walk " + ", ".join(f"{w:g}: {v - rest_l.max():.1f}" for w, v in zip(walks, rest_l))
          + f"; 95 % interval [{lo:.1e}, {hi:.1e}]")
    print("  10b. profile of L over the walk (EKF, default configuration otherwise); RMS against GPS [m]")
    with_ahrs = SensorStreams(odom=odom, imu=imu)
    gyro_only = SensorStreams(odom=odom, imu=dataclasses.replace(imu, orientation=None))
    ml = {}
    for label, streams in (("gyro + AHRS", with_ahrs), ("gyro only", gyro_only)):
        prof = []
        for w in walks:
            value, result = nl.log_likelihood(streams, {"imu.gyro_random_walk": w})
            prof.append(value)
            errors = [rms(gps_errors(result.trajectories[n], t_gps, enu)) for n in names[:2]]
            print(f"    {label:12s} walk {w:7.0e}{' (default)' if w == 2e-5 else '':10s} L {value:11.2f}   "
                  f"EKF {errors[0]:.3f}  RTS {errors[1]:.3f}", flush=True)
        best, l_max, calls = nl.estimate(streams, ("imu.gyro_random_walk",))
        w_ml = best["imu.gyro_random_walk"]
        prof = np.array(prof)
        lo, hi = nl.interval(np.array(walks), prof, w_ml, l_max)
        ml[label] = w_ml
        print(f"    {label:12s} ML walk {w_ml:.2e} (bounded search over log10 in {nl.BOUNDS['imu.gyro_random_walk']}, "
              f"{calls} runs), L {l_max:.2f}; 95 % interval [{lo:.1e}, {hi:.1e}]", flush=True)
    print("  10c. the same jointly with the AHRS's noise model (L is comparable only where the monitor drops the same "
          "span, 180.3 s to the end)")
    grid = (1e-5, 1e-4, 1e-3, 3e-3)
    models = [(f"white sigma {s:g} rad", {"imu.ahrs_yaw_sigma": s}, None) for s in (0.02, 0.04, 0.08)]
    models += [(f"+ offset walk {w:g} rad/sqrt(s)", {"imu.ahrs_offset_walk": w}, None) for w in (1e-3, 3e-3)]
    models += [(f"+ Gauss-Markov offset {s:g} rad, {tau:g} s", {"imu.ahrs_offset_walk": 1e-9}, (s, tau))
               for s, tau in ((0.02, 12.0), (0.04, 12.0), (0.08, 12.0), (0.04, 60.0))]
    print(f"    {'AHRS model':40s}" + "".join(f"{f'L at {w:g}':>14s}" for w in grid) + "   RTS RMS at each walk [m]")
    for label, values, gm in models:
        row, rts = [], []
        for w in grid:
            with gauss_markov_ahrs_offset(*gm) if gm else contextlib.nullcontext():
                value, result = nl.log_likelihood(with_ahrs, {**values, "imu.gyro_random_walk": w})
            same = any("(180.3 s in) to" in n and "(395.6 s in)" in n for n in result.notes)
            row.append(f"{value:13.1f}{'' if same else '*'}")
            rts.append(rms(gps_errors(result.trajectories["ekf_smoothed"], t_gps, enu)))
        print(f"    {label:40s}" + "".join(f"{v:>14s}" for v in row) + "   " + " / ".join(f"{e:.2f}" for e in rts),
              flush=True)
    print("    (* the monitor dropped another span: that L is over other measurements)")
    print("  10d. all four backends at the ML walks, beside the default and dead reckoning (same run)")
    bias0 = float(np.median(gyro.rate[rest]))
    print(f"    {'wheel + gyro dead reckoning (standstill bias)':48s} "
          f"{rms(gps_errors(dead_reckoning(odom, gyro, bias0, delay), t_gps, enu)):13.3f}")
    print(f"    {'':48s}" + " ".join(f"{n:>13s}" for n in names))
    for label, walk in (("default (2e-05)", 2e-5), (f"ML with the AHRS ({ml['gyro + AHRS']:.1e})", ml["gyro + AHRS"]),
                        (f"ML gyro only ({ml['gyro only']:.1e}), used with the AHRS", ml["gyro only"])):
        result = fuse(with_ahrs, "all", FusionConfig.from_dict({"imu": {"gyro_random_walk": walk}}))
        errors = [rms(gps_errors(result.trajectories[n], t_gps, enu)) for n in names]
        print(f"    {label:48s}" + " ".join(f"{e:13.3f}" for e in errors), flush=True)
    if jackal_bag is None or not jackal_bag.exists():
        return
    print("  10e. robot_localization's Jackal (test2.bag): L over the walk and the final position's distance to "
          "robot_localization's (1.0206, 3.4292) [m]")
    with tempfile.TemporaryDirectory() as tmp:
        seq = Path(tmp) / "jackal"
        import_bag(jackal_bag, seq, imu_topic="/imu/data", odom_topic="/jackal_velocity_controller/odom", overwrite=True)
        rec = Recording(seq)
        j_odom, j_imu = rec.odom(), rec.imu()
    yaw0 = float(se2.yaw_of_quaternion(np.asarray(j_imu.orientation[:1]))[0])  # the IMU's absolute heading
    jackal = SensorStreams(odom=j_odom, imu=j_imu)
    for w in (1e-6, 2e-5, 1e-4, 1e-3):
        value, result = nl.log_likelihood(jackal, {"imu.gyro_random_walk": w})
        dist = []
        for n in names[:2]:
            xy = result.trajectories[n].xyyaw
            d = yaw0 - xy[0, 2]
            final = np.array([[np.cos(d), -np.sin(d)], [np.sin(d), np.cos(d)]]) @ (xy[-1, :2] - xy[0, :2])
            dist.append(float(np.linalg.norm(final - np.array([1.0206, 3.4292]))))
        print(f"    walk {w:7.0e} L {value:11.2f}   EKF {dist[0]:.3f}  RTS {dist[1]:.3f}", flush=True)
    best, l_max, calls = nl.estimate(jackal, ("imu.gyro_random_walk",))
    print(f"    ML walk {best['imu.gyro_random_walk']:.2e} (L {l_max:.2f}, {calls} runs)")


if __name__ == "__main__":
    sys.exit(main())
