"""``fusion-vo replay``: a recording through the streaming path, as a live stack would see it.

The visual odometry runs first (as in ``fusion-vo run``); then every sample is handed to
:class:`~fusion_vo.backends.streaming.StreamingFusion` in arrival order (the camera's increments
``--camera-delay`` seconds after their frame, as a frontend delivers them), at the recording's own pace
(``--speed 1``), N times faster (``--speed N``) or as fast as possible (``--speed 0``). At a fixed
rate (``--rate``, recording time) the command asks for ``current_estimate()`` as a controller would,
and writes what it got:

* ``live_<backend>.csv``: ``t_query, t, x, y, yaw, var_x, var_y, var_yaw, predicted, call_ms``
  (``predicted``: seconds the pose was predicted beyond the processed state; ``call_ms``: wall time of
  the call);
* ``live_<backend>.tum``: the live poses at the query times;
* beside them the batch results of the same backend on the same streams (``ekf.tum``,
  ``ekf_smoothed.tum`` or ``gtsam.tum``, ``gtsam_online.tum``), the streaming run's own node
  trajectory ``stream_<backend>.tum`` and ``replay.json`` (counts, rewinds, call-time percentiles).

Files appear only when the replay finished (written to a staging folder, then moved).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from fusion_vo.cli.arguments import non_empty, non_negative_number, number_up_to, playback_speed
from fusion_vo.outputs import StagedFiles, check_folder_target
from fusion_vo.errors import InputError

OUTPUTS = ("live_{b}.csv", "live_{b}.tum", "stream_{b}.tum", "replay.json")

#: the highest ``--rate`` [Hz]: every query is a call of ``current_estimate()``, so the work grows with the
#: rate, and a controller asks at most about once a millisecond
MAX_RATE_HZ = 1000.0


def register(sub) -> None:
    p = sub.add_parser("replay", help="run a recording through the streaming path and write the live poses",
                       description=__doc__.split("\n")[0])
    p.add_argument("sequence", help="recording folder (as for fusion-vo run)")
    p.add_argument("--out", "-o", required=True, help="output folder (created if needed)")
    p.add_argument("--backend", choices=["ekf", "gtsam"], default="ekf", help="streaming backend (default: ekf)")
    p.add_argument("--config", "-c", type=non_empty("a configuration file"), help="YAML configuration file (as for fusion-vo run)")
    p.add_argument("--sensors", help="comma-separated sensors to use (default: what the recording has)")
    p.add_argument("--speed", type=playback_speed, default=1.0,
                   help="playback speed: 1 = the recording's own pace, N = N times faster (0.01 to 1e6), "
                        "0 = as fast as possible")
    p.add_argument("--rate", type=number_up_to(MAX_RATE_HZ, "a query per millisecond of the recording"), default=50.0,
                   help=f"rate [Hz] at which live poses are read (default 50, at most {MAX_RATE_HZ:g})")
    p.add_argument("--camera-delay", type=non_negative_number, default=0.0,
                   help="seconds after its frame that a visual increment arrives (frontend latency, default 0)")
    p.add_argument("--window", type=non_negative_number,
                   help="reorder window [s] (default: the configuration's reorder_window)")
    p.add_argument("--background", action="store_true",
                   help="with --backend gtsam: run iSAM2's updates on a worker thread, off the caller's")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from fusion_vo.backends import batch
    from fusion_vo.backends.batch import fuse
    from fusion_vo.backends.result import write_pose_covariances
    from fusion_vo.backends.streaming import streaming_for, time_ordered_messages
    from fusion_vo.cli.progress import progress_bar
    from fusion_vo.cli.run import apply_overrides
    from fusion_vo.config import load_config
    from fusion_vo.pipeline import resolve_sensors
    from fusion_vo.recording import Recording, write_tum

    if args.background and args.backend != "gtsam":
        raise InputError("--background is for --backend gtsam (the EKF's steps are cheap)")
    cfg = apply_overrides(load_config(args.config), argparse.Namespace(sensors=args.sensors))  # --backend: its own
    rec = Recording(args.sequence)
    sensors = resolve_sensors(rec, cfg)  # GPS only when --sensors names it, as in `run`
    fusion_cfg = cfg.fusion
    if args.window is not None:
        try:
            fusion_cfg = fusion_cfg.merged({"reorder_window": args.window})
        except ValueError as exc:
            raise InputError(f"--window {args.window:g}: {str(exc).removeprefix('FusionConfig: ')}") from None
    out = check_folder_target(args.out)  # a file there, or in the way above it: before any work
    _check_output_folder(out, rec)
    _check_timing(args, rec, sensors)
    vo = None
    if "camera" in sensors:
        from fusion_vo.odometry import run_visual_odometry

        with progress_bar("visual odometry") as update:
            vo = run_visual_odometry(rec, cfg.odometry_config(), update)
    streams = batch.streams_from_recording(rec, vo, sensors, fusion_cfg)
    msgs = time_ordered_messages(streams, args.camera_delay)
    if not msgs:
        raise InputError("the recording has no samples of the chosen sensors", rec.path)
    fusion = streaming_for(streams, args.backend, fusion_cfg, background=args.background)
    rows, call_ms = _play(fusion, msgs, args.speed, args.rate)
    if not rows:
        raise InputError(f"--rate {args.rate:g}: no live pose read in the recording's "
                         f"{msgs[-1][0] - msgs[0][0]:.3g} s; give a higher rate")
    online = fusion.finish()
    offline = fuse(streams, args.backend, fusion_cfg)

    b = args.backend
    # every file together or none (a failure or Ctrl-C keeps an earlier replay's files whole)
    with StagedFiles(out, what="output folder", create=True) as staged:
        staging = staged.path
        table = np.array(rows, dtype=np.float64).reshape(-1, 10)
        np.savetxt(staging / f"live_{b}.csv", table, delimiter=",",
                   fmt=["%.9f", "%.9f", "%.9g", "%.9g", "%.9g", "%.6g", "%.6g", "%.6g", "%.6f", "%.4f"],
                   header="t_query,t,x,y,yaw,var_x,var_y,var_yaw,predicted,call_ms", comments="")
        write_tum(staging / f"live_{b}.tum", table[:, 0], table[:, 2:5])
        name = "ekf" if b == "ekf" else "gtsam_online"
        if name in online.trajectories:
            write_tum(staging / f"stream_{b}.tum", online.trajectories[name].t, online.trajectories[name].xyyaw)
        for key, traj in offline.trajectories.items():
            if len(traj):
                write_tum(staging / f"{key}.tum", traj.t, traj.xyyaw)
                cov = offline.covariances.get(key)
                if cov is not None and len(cov) == len(traj):
                    write_pose_covariances(staging / f"{key}.cov.csv", traj.t, cov)
        lat = np.array(call_ms) if call_ms else np.zeros(1)
        info = {
            "sequence": str(rec.path.resolve()), "backend": b, "sensors": sensors, "speed": args.speed,
            "rate_hz": args.rate, "camera_delay_s": args.camera_delay,
            "reorder_window_s": fusion_cfg.reorder_window, "samples": len(msgs), "live_poses": len(table),
            "call_ms": {"p50": float(np.percentile(lat, 50)), "p99": float(np.percentile(lat, 99)),
                        "max": float(lat.max())},
            "rewinds": fusion.rewinds,
            "counts": {s: c.as_dict() for s, c in online.counts.get(name, {}).items()},
            "notes": online.notes,
        }
        with open(staging / "replay.json", "w") as f:
            json.dump(info, f, indent=2)
        staged.commit()
    print(f"replayed {len(msgs)} samples; {len(table)} live poses at {args.rate:g} Hz -> {out / f'live_{b}.tum'}; "
          f"call p50 {info['call_ms']['p50']:.3f} ms, p99 {info['call_ms']['p99']:.3f} ms, "
          f"max {info['call_ms']['max']:.3f} ms")
    for note in online.notes:
        print(f"note: {note}")
    return 0


def _check_output_folder(out: Path, rec) -> None:
    """The live poses go beside, never into, the recording, and never over a run's own trajectories."""
    from fusion_vo.outputs import check_outside
    from fusion_vo.pipeline import RUN_MARKER

    check_outside(out, [rec.path])
    if (out / RUN_MARKER).is_file():
        raise InputError("the output folder holds a 'fusion-vo run' (replay would overwrite its trajectories "
                         "but not its metrics); give another output folder", out)


def _check_timing(args: argparse.Namespace, rec, sensors: list[str]) -> None:
    """A camera delay longer than the recording would only make the player wait (or query) past its end."""
    t = rec.frame_times if "camera" in sensors else None
    if t is None or len(t) < 2:
        return
    span = float(t[-1] - t[0])
    if args.camera_delay > span:
        raise InputError(f"--camera-delay {args.camera_delay:g}: longer than the recording's {span:.3g} s of frames")


def _play(fusion, msgs, speed: float, rate: float) -> tuple[list, list]:
    """Feed ``msgs`` at ``speed`` and read the estimate every ``1/rate`` s of recording time."""
    import numpy as np

    t_first = msgs[0][0]
    wall0 = time.perf_counter()
    period = 1.0 / rate
    next_query = t_first + period
    rows: list[list[float]] = []
    call_ms: list[float] = []

    def wait_until(t_rec: float) -> None:
        if speed > 0:
            delay = wall0 + (t_rec - t_first) / speed - time.perf_counter()
            if delay > 0:
                time.sleep(delay)

    def query(t_query: float) -> None:
        wait_until(t_query)
        c0 = time.perf_counter()
        est = fusion.current_estimate()
        ms = (time.perf_counter() - c0) * 1e3
        if est is not None:
            d = np.diag(est.covariance)
            rows.append([t_query, est.t, *est.pose, *d, est.predicted, ms])

    for t_arrival, kind, m in msgs:
        while next_query < t_arrival:
            query(next_query)
            next_query += period
        wait_until(t_arrival)
        c0 = time.perf_counter()
        fusion.feed([(t_arrival, kind, m)])
        call_ms.append((time.perf_counter() - c0) * 1e3)
    return rows, call_ms
