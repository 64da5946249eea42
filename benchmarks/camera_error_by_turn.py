"""The camera's heading errors by how fast the robot turns, on the standard recordings.

For each standard recording named (default: square, random60, gps_outage), this generates it (or reuses it
from ``--out``), runs visual odometry (default configuration, KLT; ``--klt KEY=VALUE,...`` sets options of
``frontends.klt.KltConfig``) and sorts its usable increments by the true turn of their interval. Per band it
prints how many increments fall in it, the RMS of their heading errors against the ground truth, their mean
along the turn (the error times the sign of the turn: a bias that scales the turn),
and the correlation of consecutive errors within the band (lag 1; about -0.5 when each frame's own error
enters the two increments it belongs to with opposite signs, positive when errors persist). The KLT frontend
warps the reference by the predicted motion above ``warp_tolerance`` (0.015: 0.86 deg per frame), so the
band edge there separates the increments tracked from the reference as it is from the warped ones. Then the
ATE [mm] of visual odometry and of the default fusion (EKF / RTS / GTSAM batch / iSAM2).

With ``--variants`` the same increments (visual odometry run once without the frontend's floors) are
also fused with heading variances other than the default's (``max(stated, floor²)``, floor 20 µrad):

* ``band variance (oracle)``: each increment's heading variance set to the mean squared error of its turn
  band against the ground truth (a diagnostic: no run knows it);
* ``floor 10 µrad + unwarped turn``: the floor halved, and ``(k ψ)²`` added to the stated variance of an
  increment that turns by ``ψ`` below the warp tolerance (``k`` 0.0015: the 0.15 % rotation error of
  patches tracked without warping that the table measures);
* ``floor 10 µrad``: the floor halved alone.

Run::

    python benchmarks/camera_error_by_turn.py [--out DIR] [--only square,random60] [--klt warp_tolerance=0.005]
        [--variants]
"""

from __future__ import annotations

import argparse
import dataclasses
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

from fusion_vo import backends
from fusion_vo.odometry import OdometryConfig, OdometryResult, run_visual_odometry
from fusion_vo.recording import Recording
from fusion_vo.simulation.standard import make_standard

sys.path.insert(0, str(Path(__file__).parent))
from fusion_vs_best import FLOOR, FUSED, ate_against, camera_errors, with_floor  # noqa: E402

#: edges [rad per increment] of the turn bands; 0.015 is the KLT frontend's default warp tolerance
EDGES = (0.0, 0.002, 0.008, 0.015, 0.03, np.inf)


def turn_bands(errors: np.ndarray, turns: np.ndarray, chained: np.ndarray) -> list[tuple]:
    """Per band of ``|turns|`` (:data:`EDGES`): (low, high, count, RMS, mean along the turn, lag-1 correlation)
    of the heading ``errors``; the correlation is over consecutive increments that share a frame and are both in the band
    (NaN with fewer than 10 pairs)."""
    rows = []
    size = np.abs(turns)
    for lo, hi in zip(EDGES[:-1], EDGES[1:]):
        m = (size >= lo) & (size < hi)
        pairs = m[1:] & m[:-1] & chained[1:]
        lag = np.corrcoef(errors[:-1][pairs], errors[1:][pairs])[0, 1] if pairs.sum() >= 10 else np.nan
        rms = np.sqrt(np.mean(errors[m] ** 2)) if m.any() else np.nan
        mean = np.mean(errors[m] * np.sign(turns[m])) if m.any() else np.nan
        rows.append((lo, hi, int(m.sum()), rms, mean, lag))
    return rows


#: ``k`` of the ``floor 10 µrad + unwarped turn`` variant and the warp tolerance it applies below
TURN_ERROR, WARP_TOLERANCE = 0.0015, 0.015


def heading_variants(rec: Recording, options: dict) -> tuple[OdometryResult, dict[str, list]]:
    """One visual odometry run without floors, and label -> its visual increments with the heading
    variances of each ``--variants`` case (module docstring), floors applied as the frontend does."""
    vo = run_visual_odometry(rec, OdometryConfig(frontend_options=options, min_sigma_xy=0.0, min_sigma_yaw=0.0))
    errors, _, _ = camera_errors(rec, vo.increments)
    ok = [k for k, inc in enumerate(vo.increments) if inc.ok]
    turns = np.abs(np.array([vo.increments[k].delta[2] for k in ok]) - errors[:, 2])
    band_mse = np.zeros(len(ok))
    for lo, hi in zip(EDGES[:-1], EDGES[1:]):
        m = (turns >= lo) & (turns < hi)
        if m.any():
            band_mse[m] = np.mean(errors[m, 2] ** 2)

    def with_heading(variance) -> list:
        out = list(vo.increments)
        for j, k in enumerate(ok):
            cov = np.array(out[k].covariance, dtype=float)
            scale = np.sqrt(variance(j, cov[2, 2], abs(out[k].delta[2])) / cov[2, 2])
            cov[2, :] *= scale
            cov[:, 2] *= scale
            out[k] = dataclasses.replace(out[k], covariance=cov)
        return out

    def unwarped(j, stated, turn):
        return stated + (TURN_ERROR * turn) ** 2 if turn < WARP_TOLERANCE else stated

    return vo, {
        "default": with_floor(vo.increments, 1.0, FLOOR),
        "band variance (oracle)": with_heading(lambda j, stated, turn: band_mse[j]),
        "floor 10 µrad + unwarped turn": with_floor(with_heading(unwarped), 1.0, (FLOOR[0], 1e-5)),
        "floor 10 µrad": with_floor(vo.increments, 1.0, (FLOOR[0], 1e-5)),
    }


def parse_options(text: str | None) -> dict:
    """``KEY=VALUE,...`` as a dict of floats (ints where they are whole)."""
    out = {}
    for item in filter(None, (text or "").split(",")):
        key, _, value = item.partition("=")
        number = float(value)
        out[key.strip()] = int(number) if number.is_integer() and "." not in value else number
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, help="keep the recordings here (default: a temporary folder)")
    parser.add_argument("--only", default="square,random60,gps_outage", help="comma-separated standard recordings")
    parser.add_argument("--klt", help="KLT frontend options, KEY=VALUE,...")
    parser.add_argument("--variants", action="store_true", help="also fuse with other heading variances")
    args = parser.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="camera_error_by_turn_"))
    options = parse_options(args.klt)
    try:
        for name in args.only.split(","):
            seq = out / name
            if not (seq / "simulation.yaml").exists():
                make_standard(name, seq)
            rec = Recording(seq)
            vo = run_visual_odometry(rec, OdometryConfig(frontend_options=options))
            errors, _, chained = camera_errors(rec, vo.increments)
            used = [inc for inc in vo.increments if inc.ok]
            turns = np.array([inc.delta[2] for inc in used]) - errors[:, 2]
            print(f"{name} {options or 'default'}: true turn per increment [rad] | n | heading RMS [µrad] | mean along the turn [µrad] | lag 1")
            for lo, hi, n, rms, mean, lag in turn_bands(errors[:, 2], turns, chained):
                print(f"    {lo:g}-{hi:g} | {n} | {1e6 * rms:.1f} | {1e6 * mean:+.1f} | {lag:+.2f}")
            ate = ate_against(rec)
            fused = backends.run_backends(rec, vo, backend="all")
            print(f"    ATE [mm]: vo {ate(vo.track):.3f}, fused " + " / ".join(f"{ate(fused.trajectories[k]):.3f}" for k in FUSED),
                  flush=True)
            if args.variants:
                plain, cases = heading_variants(rec, options)
                for label, increments in cases.items():
                    result = backends.run_backends(rec, dataclasses.replace(plain, increments=increments), backend="all")
                    print(f"    {label:30s} " + " / ".join(f"{ate(result.trajectories[k]):.3f}" for k in FUSED), flush=True)
    finally:
        if args.out is None:
            shutil.rmtree(out, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
