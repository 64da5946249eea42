"""The scale priors' defaults on clean generated drives: fused tracks beside visual odometry, over seeds.

Camera and wheels measure only the ratio of their distance scales (the visual scale ``k_v``, the camera
height, and the wheels' ``k_r``, their common radius); the priors of the two decide who sets the common
scale (``docs/decisions/0036-visual-scale-model.md``). This benchmark measures what that choice does when
nothing states how well the camera height and the wheel radius are known, on drives where visual odometry
is right, and what the camera's heading floor (``odometry.min_sigma_yaw``,
``docs/decisions/0037-camera-heading-floor-stays.md``) does to the weight the gyro takes from the camera there.

Drives
------
``--profiles`` (default: every generated motion profile that moves the camera over a distance: ``square``,
``circle``, ``random`` (60 s), ``umbmark_cw``, ``umbmark_ccw``, ``straight``; ``turn_in_place`` and
``standstill`` have no distance to scale) each with ``--seeds`` seeds (``--first-seed``, +1, ...: held out,
the standard recordings use seeds 1-24), generated with the simulator's defaults: camera height exact, wheels
with their default calibration errors (left radius +0.6 %, right -0.4 %, so a common radius error of +0.1 %
and a curvature bias; wheel base +1.5 %; slip 0.0005 √m), gyro biases and noise.

``--wrong`` (default ``height_error,hard,tilted``) adds the standard recordings whose camera is NOT right
(:mod:`fusion_vo.simulation.standard`: a 2 % wrong height in ``sensor.yaml``; slip, dropped frames, blur and
a featureless stretch; a tilted camera with a vibrating height and a range finder), with their options and
``--wrong-seeds`` seeds each: there the figure is each fused track's ATE under a configuration divided by
its ATE under the old defaults (how much worse the new defaults make a run whose camera is wrong).

Each drive is generated once and its visual odometry run once (the default configuration of ``fusion-vo
run``, KLT frontend, with the covariance floors off: each increment keeps the frontend's own covariance); the
sensor streams, the visual track and the ground truth are cached in ``--cache`` (one pickle per drive; the
rendered frames are deleted unless ``--keep-recordings``), so a second run only fuses. Then the same streams
are fused (:func:`fusion_vo.backends.fuse`, every backend) under each configuration, the configuration's
floors ``odometry.min_sigma_xy`` and ``odometry.min_sigma_yaw`` applied to every increment first with
:func:`fusion_vo.geometry.ground.floor_covariance`, the function the ground geometry ends with (so the
streams are those ``fusion-vo run`` would fuse with those floors):

``old``        the defaults before decision 0036 (visual scale prior 5 %, wheels 1 %, walks 1e-5 and
               1e-4 /√s; heading floor 20 µrad), nothing stated in the sensors' files;
``new``        the library's defaults (:class:`fusion_vo.backends.FusionConfig`, :class:`fusion_vo.config.odometry.OdometryConfig`),
               nothing stated;
``vs 0.002``   the old defaults with ``fusion.visual_scale_sigma: 0.002`` (the camera height stated as known
               to 0.2 %), nothing else stated;
``yaml``       the library's defaults with ``height_sigma`` and ``radius_sigma`` as the simulator writes them
               (the size of its calibration error, at least 0.1 mm: 0.1 % of the height, 0.6 % of the radius);

plus any ``--variant NAME:KEY=VALUE,...`` (fusion keys, ``ekf.`` / ``graph.`` prefixes for the nested ones,
``odometry.min_sigma_xy`` and ``odometry.min_sigma_yaw`` for the floors;
nothing stated), whose ``streams.`` keys change the streams fused instead: ``streams.yaw_sigma=F`` multiplies
the standard deviation of every visual increment's heading by ``F`` (its covariance row and column),
``streams.no_imu=1`` and ``streams.no_wheel=1`` leave the gyro or the wheels out, ``streams.camera_noise=1`` gives
the increments the camera's heading noise model (:mod:`fusion_vo.calibration.camera_noise`, what ``fusion-vo
calibrate camera-noise`` states in ``cam0/sensor.yaml``) measured on the next seed's drive of the same profile
(the last seed's on the first seed's), never on the drive it is applied to. ``--configs`` limits the four
above (default all). "Nothing stated" removes ``height_sigma`` and ``radius_sigma`` from the streams.

Printed per profile: the mean ATE [mm] of visual odometry and of wheel dead reckoning; the camera's heading
error per increment against the ground truth (RMS, and its growth over 100 increments per √increment, in µrad)
beside the standard deviation its covariance states, and its error along the turns (the sum over the turning
increments of the error signed by the turn's direction, and that per radian turned: :func:`camera_heading_error`);
per configuration the
mean and the worst (largest) ratio over the seeds of each fused track's ATE (EKF, RTS, GTSAM batch, iSAM2)
to visual odometry's; how often the RTS smoother is at most the EKF and the batch at most iSAM2 (with the
mean ratio); the mean ``|k_v - 1|`` of the smoothed EKF and the batch (the visual scale's error; the
camera height is exact) and the mean over the seeds of the largest ``|k_v - 1|`` the EKF's filtered estimate
reaches over the drive (its excursion, which shapes the filtered track); the mean ATE [mm] of the EKF's and the
batch's track against visual odometry's (how far fusion moves the track from the camera's, whichever is right). ATE is the RMS position error after an SE(2) alignment
(:func:`fusion_vo.evaluation.metrics.align_se2`), in mm.

Run (long: generation renders every frame; use ``nice``)::

    nice -n 10 python benchmarks/scale_defaults.py --cache DIR [--seeds 10] [--profiles square,circle]
        [--wrong height_error,hard,tilted] [--wrong-seeds 3] [--variant NAME:visual_scale_sigma=0.005,...]
        [--configs new] [--variant NAME:streams.yaw_sigma=0.5] [--vo-set klt.min_sigma=0.01]
"""

from __future__ import annotations

import argparse
import dataclasses
import pickle
import shutil
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import common
import numpy as np

from threadpoolctl import threadpool_limits

from fusion_vo.backends import ekf, fuse
from fusion_vo.backends.batch import as_config, streams_from_recording, with_recorded_noise
from fusion_vo.backends.timeline import SensorStreams, build_intervals
from fusion_vo.calibration.camera_noise import CameraNoise, measure
from fusion_vo.calibration.camera_noise_drive import heading_errors
from fusion_vo.config import RunConfig
from fusion_vo.errors import InputError
from fusion_vo.geometry.ground import floor_covariance
from fusion_vo.odometry import run_visual_odometry
from fusion_vo.recording import Recording
from fusion_vo.simulation.generate import simulate
from fusion_vo.simulation.standard import STANDARD

#: profile -> simulator options of the clean drives
PROFILES = {"square": {}, "circle": {}, "random": {"duration": 60.0}, "umbmark_cw": {}, "umbmark_ccw": {},
            "straight": {}}
FUSED = ("ekf", "ekf_smoothed", "gtsam", "gtsam_online")
LABELS = {"ekf": "EKF", "ekf_smoothed": "RTS", "gtsam": "batch", "gtsam_online": "iSAM2"}
#: the defaults before decision 0036 (every key, so that they hold whatever the library's are)
OLD = {"visual_scale_sigma": 0.05, "wheel_scale_sigma": 0.01,
       "ekf": {"visual_scale_random_walk": 1e-5, "scale_random_walk": 1e-4},
       "odometry": {"min_sigma_xy": 2e-5, "min_sigma_yaw": 2e-5}}
#: name -> (options, keep the sensors' stated height_sigma / radius_sigma)
CONFIGS = {"old": (OLD, False), "new": ({}, False),
           "vs 0.002": ({**OLD, "visual_scale_sigma": 0.002}, False), "yaml": ({}, True)}
#: the cached visual odometry: the default configuration without the covariance floors
RAW = {"odometry": {"min_sigma_xy": 0.0, "min_sigma_yaw": 0.0}}
#: bump when the cached content changes (2: increments without the floors)
CACHE_VERSION = 2


@dataclasses.dataclass
class Drive:
    """What a drive leaves in the cache: the streams ``fusion-vo run`` fuses by default, the visual track and
    the ground truth."""

    name: str
    streams: SensorStreams
    vo_track: object
    truth: object
    version: int = CACHE_VERSION


def log(text: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {text}", file=sys.stderr, flush=True)


def cached_drive(cache: Path, name: str, profile: str, seed: int, options: dict, keep: bool,
                 vo: dict | None = None) -> Drive:
    """The drive ``name`` from ``cache``, generated and run through visual odometry when not there yet."""
    path = cache / f"{name}.pkl"
    if path.exists():
        try:
            drive = pickle.loads(path.read_bytes())
            if isinstance(drive, Drive) and drive.version == CACHE_VERSION:
                return drive
        except Exception as exc:  # an unreadable cache entry is made again
            log(f"{path}: {exc}; generating again")
    seq = cache / name
    t0 = time.time()
    if not (seq / "simulation.yaml").exists():
        simulate(seq, profile=profile, seed=seed, **options)
    rec = Recording(seq)
    vo = run_visual_odometry(rec, RunConfig.model_validate(common.with_settings(RAW, vo or [])).odometry_config())
    streams = streams_from_recording(rec, vo)
    drive = Drive(name, streams, vo.track, rec.groundtruth())
    tmp = path.with_suffix(".tmp")
    tmp.write_bytes(pickle.dumps(drive))
    tmp.replace(path)
    if not keep:
        shutil.rmtree(seq)
    log(f"{name}: generated and visual odometry in {time.time() - t0:.0f} s")
    return drive


def filtered_visual_scale(streams: SensorStreams, config) -> np.ndarray:
    """The EKF's filtered visual scale ``k_v`` at every node (the loop of :func:`fusion_vo.backends.ekf.run_ekf`,
    keeping the state; the streams have no GPS, so nothing is applied at the nodes on its own). Its last
    value is the ``visual_scale`` of the EKF's calibration."""
    config = with_recorded_noise(config, streams)
    iv = build_intervals(streams, config)
    readings = ekf.interval_readings(iv, config)
    f = ekf.filter_for(iv, config, readings)
    f.begin(readings)
    kv = f.columns["visual_scale"].start
    out = np.empty(iv.n_steps + 1)
    out[0] = f.x[kv]
    for k in range(iv.n_steps):
        f.step(readings, k)
        out[k + 1] = f.x[kv]
    return out


def floored(streams: SensorStreams, floors: dict | None = None) -> SensorStreams:
    """``streams`` with the covariance floors of the odometry configuration (the library's defaults, with
    ``floors``' keys ``min_sigma_xy`` / ``min_sigma_yaw`` where given) applied to every visual increment."""
    odometry = RunConfig().odometry_config()
    xy = float((floors or {}).get("min_sigma_xy", odometry.min_sigma_xy))
    yaw = float((floors or {}).get("min_sigma_yaw", odometry.min_sigma_yaw))
    if streams.visual is None:
        return streams
    return streams.replace(visual=[dataclasses.replace(v, covariance=floor_covariance(v.covariance, xy, yaw))
                                                for v in streams.visual])


#: an increment turns when its true heading change exceeds this [rad] (20 mrad/s at 20 Hz)
TURNING = 1e-3


def camera_heading_error(drive: Drive) -> tuple[float, float, float, float, float]:
    """The camera's heading error per visual increment against the ground truth [rad]: its RMS, its drift over
    100 increments divided by √100 (equal to the RMS for independent errors, larger when they persist), the
    mean standard deviation the increments' covariances state at the library's default floors, and over the
    turning increments (true ``|Δψ| >`` :data:`TURNING`) the error along the turn, ``Σ e_k sign(Δψ_k)``
    (negative: the camera turns less than the robot), and the same divided by ``Σ |Δψ_k|`` (a rotation scale
    error; a zero-mean error gives about ``RMS √n / Σ |Δψ|``)."""
    yaw = np.unwrap(drive.truth.xyyaw[:, 2])
    ok = [v for v in floored(drive.streams).visual if v.ok]
    true = np.array([np.interp(v.t1, drive.truth.t, yaw) - np.interp(v.t0, drive.truth.t, yaw) for v in ok])
    err = np.array([v.delta[2] for v in ok]) - true
    walk = np.cumsum(err)
    drift = float(np.std(walk[100:] - walk[:-100]) / 10.0) if len(err) > 100 else np.nan
    stated = float(np.mean([np.sqrt(v.covariance[2, 2]) for v in ok]))
    turning = np.abs(true) > TURNING
    along = float(np.sum(err[turning] * np.sign(true[turning])))
    turned = float(np.sum(np.abs(true[turning])))
    return float(np.sqrt(np.mean(err**2))), drift, stated, along, along / turned if turned > 0 else np.nan


def camera_noise_of(drive: Drive) -> CameraNoise:
    """The camera's heading noise model measured on ``drive`` against its ground truth
    (:func:`fusion_vo.calibration.camera_noise.measure`, as ``fusion-vo calibrate camera-noise`` does)."""
    errors, turns, chained = heading_errors(SimpleNamespace(groundtruth=lambda: drive.truth), drive.streams.visual)
    if len(chained):
        chained[0] = False
    return measure(errors, turns, chained, RunConfig().odometry_config().frontend)


def with_stream_options(streams: SensorStreams, options: dict, noise: CameraNoise | None = None) -> SensorStreams:
    """``streams`` changed by a variant's ``streams.`` keys (``yaw_sigma``, ``no_imu``, ``no_wheel``,
    ``camera_noise``: ``noise`` applied to the increments)."""
    out = streams.replace()
    if options.get("camera_noise"):
        out.visual = noise.apply(out.visual)
    factor = options.get("yaw_sigma", 1.0)
    if factor != 1.0 and out.visual is not None:
        scale = np.diag([1.0, 1.0, factor])
        out.visual = [dataclasses.replace(v, covariance=scale @ v.covariance @ scale) for v in out.visual]
    if options.get("no_imu"):
        out.imu = None
    if options.get("no_wheel"):
        out.wheel = None
    return out


def unstated(streams: SensorStreams) -> SensorStreams:
    """``streams`` as if neither ``cam0/sensor.yaml`` stated ``height_sigma`` nor ``wheel0/sensor.yaml``
    ``radius_sigma``."""
    out = streams.replace(camera_height_sigma=None)
    if out.wheel is not None:
        out.wheel = dataclasses.replace(out.wheel, config=dataclasses.replace(out.wheel.config, radius_sigma=None))
    return out


def run_configs(drive: Drive, configs: dict, noise: CameraNoise | None = None) -> dict:
    """ATE [mm] of VO, the wheels and each fused track, and the final visual scales, per configuration
    (``noise``: the camera noise model of ``streams.camera_noise``)."""
    out = {"vo": common.ate_mm(drive.truth, drive.vo_track), "heading": camera_heading_error(drive)}
    for label, (options, stated) in configs.items():
        options = dict(options)
        streams = floored(drive.streams, options.pop("odometry", None))
        streams = with_stream_options(streams if stated else unstated(streams), options.pop("streams", {}), noise)
        try:
            result = fuse(streams, "all", as_config(options))
        except InputError as exc:  # e.g. a walk too stiff for GTSAM's elimination: the row says so
            log(f"{drive.name} {label}: {exc}")
            out[label] = {**{k: np.nan for k in FUSED}, "kv": {"ekf_smoothed": np.nan, "gtsam": np.nan},
                          "from_vo": {k: np.nan for k in FUSED},
                          "kv_excursion": np.nan}
            continue
        if "wheel" in result.trajectories:
            out.setdefault("wheel", common.ate_mm(drive.truth, result.trajectories["wheel"]))
        row = {k: common.ate_mm(drive.truth, result.trajectories[k]) for k in FUSED}
        row["from_vo"] = {k: common.ate_mm(drive.vo_track, result.trajectories[k]) for k in FUSED}
        row["kv"] = {k: result.calibration.get(k, {}).get("visual_scale", np.nan) for k in ("ekf_smoothed", "gtsam")}
        with threadpool_limits(limits=1, user_api="blas"):
            row["kv_excursion"] = float(np.max(np.abs(filtered_visual_scale(streams, as_config(options)) - 1.0)))
        out[label] = row
    return out


def variant(text: str) -> tuple[str, tuple[dict, bool]]:
    """``NAME:KEY=VALUE,...`` -> (name, (options, False)); ``ekf.KEY``, ``graph.KEY``, ``odometry.KEY`` and
    ``streams.KEY`` nest (the last two are taken out before fusing: :func:`floored`, :func:`with_stream_options`)."""
    name, _, items = text.partition(":")
    options: dict = {}
    for item in filter(None, items.split(",")):
        key, _, value = item.partition("=")
        section, _, leaf = key.rpartition(".")
        (options.setdefault(section, {}) if section else options)[leaf] = float(value)
    return name, (options, False)


def clean_summary(name: str, rows: list[dict], configs) -> list[str]:
    vo = np.array([r["vo"] for r in rows])
    heading = np.mean([r["heading"] for r in rows], axis=0) * 1e6
    lines = [f"{name} ({len(rows)} seeds): VO {vo.mean():.3f} mm, wheels {np.nanmean([r.get('wheel', np.nan) for r in rows]):.2f} mm"
             f" (mean ATE); camera heading error per increment {heading[0]:.1f} µrad RMS, drift {heading[1]:.1f}"
             f" µrad/√increment, stated {heading[2]:.1f} µrad; along the turns {heading[3]:+.0f} µrad"
             f" ({heading[4]:+.1f} µrad/rad turned)",
             "  config       " + "".join(f"{LABELS[k] + ' /VO mean worst':>22s}" for k in FUSED)
             + "   RTS<=EKF      batch<=iSAM2   |kv-1| RTS batch, EKF worst [1e-4]   from VO EKF batch [mm]"]
    for label in configs:
        cells = []
        for k in FUSED:
            ratio = np.array([r[label][k] for r in rows]) / vo
            cells.append(f"{ratio.mean():>14.2f} {ratio.max():>6.2f}")
        smooth = []
        for a, b in (("ekf_smoothed", "ekf"), ("gtsam", "gtsam_online")):
            ratio = np.array([r[label][a] / r[label][b] for r in rows])
            smooth.append(f"{int(np.sum(ratio <= 1.0)):>2d}/{len(rows)} ({ratio.mean():.2f})")
        kv = [np.nanmean([abs(r[label]["kv"][k] - 1.0) * 1e4 for r in rows]) for k in ("ekf_smoothed", "gtsam")]
        excursion = np.nanmean([r[label]["kv_excursion"] * 1e4 for r in rows])
        from_vo = [np.mean([r[label]["from_vo"][k] for r in rows]) for k in ("ekf", "gtsam")]
        lines.append(f"  {label:12s}" + "".join(f"{c:>22s}" for c in cells) + "   " + "   ".join(smooth)
                     + f"   {kv[0]:6.2f} {kv[1]:6.2f} {excursion:6.1f}   {from_vo[0]:6.3f} {from_vo[1]:6.3f}")
    return lines


def wrong_summary(name: str, rows: list[dict], configs) -> list[str]:
    """Per configuration: mean ATE [mm] of each fused track, and the mean and worst ratio to the old defaults'."""
    lines = [f"{name} ({len(rows)} seeds, camera not right): VO {np.mean([r['vo'] for r in rows]):.3f} mm, wheels "
             f"{np.nanmean([r.get('wheel', np.nan) for r in rows]):.2f} mm (mean ATE)",
             "  config       " + "".join(f"{LABELS[k] + ' mm /old mean worst':>28s}" for k in FUSED)]
    for label in configs:
        cells = []
        for k in FUSED:
            ate = np.array([r[label][k] for r in rows])
            ratio = ate / np.array([r["old"][k] for r in rows])
            cells.append(f"{ate.mean():>10.3f} {ratio.mean():>7.2f} {ratio.max():>6.2f}")
        lines.append(f"  {label:12s}" + "".join(f"{c:>28s}" for c in cells))
    return lines


def main(argv=None) -> int:
    parser = common.parser(__doc__)
    parser.add_argument("--cache", type=Path, required=True, help="folder of the generated drives (made if missing)")
    parser.add_argument("--seeds", type=int, default=10, help="seeds per clean profile (default 10)")
    parser.add_argument("--first-seed", type=int, default=101, help="first seed (default 101)")
    parser.add_argument("--profiles", default=",".join(PROFILES), help="clean profiles (default: %(default)s)")
    parser.add_argument("--wrong", default="height_error,hard,tilted",
                        help="standard recordings whose camera is not right, '' for none (default: %(default)s)")
    parser.add_argument("--wrong-seeds", type=int, default=3, help="seeds per --wrong recording (default 3)")
    parser.add_argument("--variant", action="append", default=[], type=variant, metavar="NAME:KEY=VALUE,...",
                        help="another configuration to fuse with (nothing stated)")
    parser.add_argument("--configs", default=",".join(CONFIGS),
                        help="the built-in configurations to fuse with (default: %(default)s)")
    parser.add_argument("--keep-recordings", action="store_true", help="keep the rendered recordings in --cache")
    parser.add_argument("--vo-set", action="append", default=[], metavar="KEY=VALUE",
                        help="a run-configuration setting of the cached visual odometry (e.g. klt.min_sigma=0.01); "
                             "the cache holds one setting: give each its own --cache")
    args = parser.parse_args(argv)
    for p in filter(None, args.profiles.split(",")):
        if p not in PROFILES:
            parser.error(f"unknown profile {p!r} (choose from {', '.join(PROFILES)})")
    wrong = [w for w in args.wrong.split(",") if w]
    for w in wrong:
        if w not in STANDARD:
            parser.error(f"unknown standard recording {w!r}")
    unknown = [c for c in filter(None, args.configs.split(",")) if c not in CONFIGS]
    if unknown:
        parser.error(f"unknown configuration {unknown[0]!r} (choose from {', '.join(CONFIGS)})")
    configs = {c: CONFIGS[c] for c in filter(None, args.configs.split(","))}
    if wrong and "old" not in configs:
        parser.error("--wrong compares with the old defaults: keep 'old' in --configs")
    configs.update(dict(args.variant))
    if not configs:
        parser.error("no configuration to fuse with")
    args.cache.mkdir(parents=True, exist_ok=True)
    seeds = [args.first_seed + i for i in range(args.seeds)]
    report: list[str] = []
    groups = [(p, p, PROFILES[p], seeds, clean_summary) for p in filter(None, args.profiles.split(","))]
    groups += [(w, STANDARD[w][0], STANDARD[w][2], seeds[:args.wrong_seeds], wrong_summary) for w in wrong]
    for group, profile, options, group_seeds, summarise in groups:
        rows = []
        drives = [cached_drive(args.cache, f"{group}_s{seed}", profile, seed, options, args.keep_recordings, args.vo_set)
                  for seed in group_seeds]
        calibrated = any(c[0].get("streams", {}).get("camera_noise") for c in configs.values())
        for i, drive in enumerate(drives):
            noise = camera_noise_of(drives[(i + 1) % len(drives)]) if calibrated and len(drives) > 1 else None
            if calibrated and noise is None:
                parser.error("streams.camera_noise needs at least two seeds (one calibrates the other)")
            t0 = time.time()
            rows.append(run_configs(drive, configs, noise))
            log(f"{drive.name}: fused {len(configs)} configurations in {time.time() - t0:.0f} s; VO {rows[-1]['vo']:.3f}"
                + "".join(f", {c} EKF {rows[-1][c]['ekf']:.3f}" for c in configs))
        lines = summarise(group, rows, configs)
        print("\n".join(lines), flush=True)
        report += lines
    print("\n" + "\n".join(report))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
