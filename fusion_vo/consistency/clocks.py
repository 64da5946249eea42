"""A stream on a shifted clock: the yaw rates of the camera, the wheels and the gyro against each other.

Every stream that measures the turn gives a yaw rate: the camera's increments, the encoders' turn
``(d_r - d_l)/b`` per sample interval, the gyro about the body's up axis (``T_BS``, after the mounting check),
an odometry twist's ``wz`` (checked here only without a gyro: against the gyro, ``fusion.sync_odometry``
estimates and removes its delay, :func:`fusion_vo.sensors.wheel.synchronise_twist`). For each pair the
delay of one behind the other is the shift that maximises the normalised cross-correlation of their rates
(:func:`fusion_vo.sensors.sync.rate_delay`, the same estimate as the odometry's, searched within
``fusion.max_odom_delay`` and at most a twelfth of the streams' common span; none when the peak correlation
is below 0.8: a drive that does not turn has nothing to align). A delay counts when it is longer than the
sample period of both streams and than ``MIN_SHIFT``, and when it explains the rates markedly better than no
shift: the variance left unexplained, ``1 - r²`` of the correlation ``r``, at least ``UNEXPLAINED_RATIO``
times smaller than without it. (A drive whose turns are slow and smooth has a broad correlation peak: on a
generated drive of sinusoidal turn rates, a camera and wheels on one clock peak 0.11 s apart with
``1 - r²`` 0.171 against 0.173 unshifted; a wheel stream 0.3 s late on a generated random drive has 0.0002
against 0.157.)

Which stream is off: with two streams, the one that is not the reference (the camera, whose frames are
the estimate's nodes, else the gyro, which stamps its samples as it takes them); with three, the one whose
delays behind both others count and agree while the other two agree with each other, else each stream whose
delay behind the reference counts. That stream's timestamps are moved back by its delay and the sentence
names its ``data.csv``. When no pair can be compared the streams are used as they are, with a warning.
"""

from __future__ import annotations

import dataclasses
import logging

import numpy as np

from fusion_vo.consistency.finding import CORRECTED, KEPT, UNDECIDED, Finding
from fusion_vo.consistency.signals import body_turn, camera_steps, twist_travel, wheel_travel
from fusion_vo.sensors.sync import rate_correlation, rate_delay

logger = logging.getLogger(__name__)

#: the shortest clock offset corrected [s]
MIN_SHIFT = 0.02
#: a delay counts when it leaves at most this fraction of the rates' variance unexplained that no shift leaves
UNEXPLAINED_RATIO = 2.0
#: the files of the streams
FILES = {"camera": "cam0/data.csv", "imu": "imu0/data.csv", "wheel": "wheel0/data.csv", "odom": "odom0/data.csv"}
WORDS = {"camera": "camera's", "imu": "gyro's", "wheel": "wheels'", "odom": "odometry's"}


def _rates(streams) -> dict[str, tuple[np.ndarray, np.ndarray, float]]:
    """Stream -> (times, yaw rates, sample period) of the streams that measure the turn."""
    out = {}
    steps = camera_steps(streams.visual)
    if steps is not None and len(steps) >= 10:
        t, r = steps.rates()
        out["camera"] = (t, r, float(np.median(steps.dt)))
    if streams.imu is not None and len(streams.imu) >= 10:
        body = body_turn(streams.imu)
        out["imu"] = (*body.rates(), body.period)
    if streams.wheel is not None and len(streams.wheel) >= 10:
        cum = wheel_travel(streams.wheel)
        out["wheel"] = (*cum.rates(1), cum.period)
    elif streams.odom is not None and len(streams.odom) >= 10 and "imu" not in out:
        cum = twist_travel(streams.odom)
        out["odom"] = (*cum.rates(2), cum.period)
    return out


def check_clocks(streams, max_delay: float):
    """The clock check of the module docstring: ``(findings, streams with the shifted stream moved back)``."""
    rates = _rates(streams)
    names = [n for n in ("camera", "imu", "wheel", "odom") if n in rates]
    if len(names) < 2:
        return [], streams
    delays: dict[tuple[str, str], float | None] = {}
    unexplained: dict[tuple[str, str], tuple[float, float]] = {}
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            ta, ra, _ = rates[a]
            tb, rb, _ = rates[b]
            common = min(ta[-1], tb[-1]) - max(ta[0], tb[0]) if len(ta) and len(tb) else 0.0
            search = min(max_delay, common / 12.0)
            d = rate_delay(ta, ra, tb, rb, max_delay=search) if search > 0 else None
            if d is not None:
                c0, cd = rate_correlation(ta, ra, tb, rb, (0.0, d), margin=search)
                unexplained[(a, b)] = (1.0 - c0**2, 1.0 - cd**2)
            delays[(a, b)] = d

    def delay(a: str, b: str) -> float | None:
        d = delays.get((a, b))
        if d is None and (b, a) in delays and delays[(b, a)] is not None:
            return -delays[(b, a)]
        return d

    def counts(a: str, b: str) -> bool:
        d = delay(a, b)
        u0, ud = unexplained.get((a, b)) or unexplained.get((b, a)) or (0.0, 0.0)
        return (d is not None and abs(d) > max(MIN_SHIFT, rates[a][2], rates[b][2])
                and u0 >= UNEXPLAINED_RATIO * ud)

    figures = {f"{a} behind {b}": None if d is None else round(d, 4) for (a, b), d in delays.items()}
    if all(d is None for d in delays.values()):
        sentence = (f"the clocks of {', '.join(FILES[n] for n in names)} not checked against each other (their yaw "
                    "rates do not correlate: too little turning); the streams are used as stamped")
        return [Finding("clock", "all", UNDECIDED, sentence, figures)], streams
    shifts: dict[str, tuple[float, list[str]]] = {}
    ref = names[0]
    if len(names) == 3:
        x, y = names[1], names[2]
        if counts(x, ref) and counts(y, ref) and not counts(x, y) and delay(x, y) is not None:
            shifts[ref] = (-0.5 * (delay(x, ref) + delay(y, ref)), [x, y])
        else:
            for s, other in ((x, y), (y, x)):
                if counts(s, ref):
                    agree = [ref] + ([other] if counts(s, other) else [])
                    shifts[s] = (delay(s, ref), agree)
    elif counts(names[1], ref):
        shifts[names[1]] = (delay(names[1], ref), [ref])
    findings = [] if shifts else [Finding("clock", "all", KEPT, "", figures)]
    for s, (d, against) in shifts.items():
        streams = _shift(streams, s, d)
        others = " and the ".join(WORDS[o] for o in against)
        findings.append(Finding("clock", s, CORRECTED,
                                f"{FILES[s]}: its timestamps are {abs(d):.3f} s {'behind' if d > 0 else 'ahead of'} the "
                                f"{others} (their yaw rates agree best shifted so); this run moves them "
                                f"{'back' if d > 0 else 'forward'} by {abs(d):.3f} s: correct the timestamps (first "
                                f"column) of {FILES[s]}", {**figures, "shift_s": round(d, 4)}))
    return findings, streams


def _shift(streams, name: str, d: float):
    """``streams`` with stream ``name``'s timestamps moved back by ``d`` seconds."""
    if name == "camera":
        return streams.replace(visual=[dataclasses.replace(v, t0=v.t0 - d, t1=v.t1 - d)
                                                    for v in streams.visual])
    data = getattr(streams, name)
    return streams.replace(**{name: dataclasses.replace(data, t=np.asarray(data.t, dtype=np.float64) - d)})


__all__ = ["check_clocks", "MIN_SHIFT"]
