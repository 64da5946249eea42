"""Wheel encoders counting backwards, and an odometry twist with the wrong sign or in the wrong frame.

Encoder signs
-------------
One encoder wired the other way round turns the wheels' distance ``(d_r + d_l)/2`` into half their
difference and their turn ``(d_r - d_l)/b`` into twice the distance over the base: forward driving reads as
turning and turning as standing still. Over intervals of 0.1 s (the camera's increments when there is no
gyro) the wheels' turn under each of the four sign hypotheses ``(±left, ±right)`` is compared with the
reference turn ``θ_ref`` (the gyro's about the body's up axis, else the camera's):
``θ_ref ≈ k θ_wheels + c Δt`` with the base factor ``k`` held within ``[1/3, 3]`` (a skid-steered base turns
less than its wheels say; ``c`` is the gyro's bias). The mismatch of a hypothesis is its residual's norm over
``‖θ_ref‖ + max_h ‖θ_h‖`` (the same for all four): below 0.01 for the right signs on the generated drives,
0.2 to 0.4 for a wrong one. The stated signs are contradicted when their mismatch exceeds ``MISMATCH_BAD``
and another hypothesis's is below ``MISMATCH_GOOD`` and a third of the stated one's; that hypothesis is then used (its counts negated) and the sentence
names the column of ``wheel0/data.csv``. When neither the reference nor any hypothesis turns by
``min_turn`` in all, there is nothing to compare and the wheels are used as stated, with a warning.

Odometry twist
--------------
Its turn rate ``wz`` against the reference: ``θ_ref ≈ k ∫wz dt + c Δt`` with ``k`` free. A negative ``k``
with a good fit (at least ``mounting_min_fit`` of the reference's turn explained) is a sign error: ``wz`` is
negated (``k`` itself may be far from 1: robot_localization's Jackal reports about seven times its turn).

Its velocity ``(vx, vy)`` must be the robot's own, in the body frame (``child_frame_id`` of a
``nav_msgs/Odometry``): a wheeled robot drives along its x axis, so the sideways share
``Σ vy² / Σ (vx² + vy²)`` over the moving samples is small. When it is above ``SIDEWAYS_BAD`` two other
frames are tried: the velocity in the odometry (world) frame, turned back by the heading ``ψ = ∫ wz dt`` and
a constant angle, and the body frame with its axes turned by a constant angle (``vx`` and ``vy`` swapped or
negated); each constant angle is the principal axis of the turned velocities, its sign the one that drives
forward (against the camera's forward motion when there is one, else most of the way). The better one is
used when its sideways share is below ``SIDEWAYS_GOOD``; when none is, the robot may well move sideways (a
holonomic base) and the twist is used as stated, with a warning (the backends take only ``vx``).
"""

from __future__ import annotations

import dataclasses
import logging
import math

import numpy as np

from fusion_vo.consistency.config import ConsistencyConfig
from fusion_vo.consistency.finding import CORRECTED, KEPT, UNDECIDED, Finding
from fusion_vo.consistency.signals import Cumulative, Steps, explained, grid, robust_lstsq, span, twist_travel, wheel_travel
from fusion_vo.measurements import TwistData, WheelData

logger = logging.getLogger(__name__)

MISMATCH_BAD, MISMATCH_GOOD = 0.15, 0.05
SIDEWAYS_BAD, SIDEWAYS_GOOD = 0.3, 0.1
#: the base factor's range in the encoder hypotheses' fits
BASE_FACTOR = (1.0 / 3.0, 3.0)
#: samples slower than this [m/s] do not count in the sideways share
MOVING = 0.02

_HYPOTHESES = ((1, 1), (-1, 1), (1, -1), (-1, -1))


def _fit_bounded(y: np.ndarray, w: np.ndarray, dt: np.ndarray, bounds: tuple[float, float]) -> np.ndarray:
    """Residuals of ``y ≈ k w + c dt`` with ``k`` held within ``bounds``."""
    X = np.column_stack([w, dt])
    (k, c), *_ = np.linalg.lstsq(X, y, rcond=None)
    k_held = min(max(k, bounds[0]), bounds[1])
    if k_held != k:
        c = float(dt @ (y - k_held * w)) / float(dt @ dt)
    return y - k_held * w - c * dt


def check_encoder_signs(wheel: WheelData, reference: Cumulative | Steps, ref_name: str, config: ConsistencyConfig,
                        max_gap: float) -> tuple[Finding, WheelData]:
    """The encoder sign check of the module docstring; returns the finding and the wheels to fuse."""
    hyps = {h: wheel_travel(wheel, *h) for h in _HYPOTHESES}
    if isinstance(reference, Steps):
        t0, t1, y_all = reference.t0, reference.t1, reference.delta[:, 2]
        ok_ref = np.ones(len(t0), bool)
    else:
        t0, t1 = grid([span(reference), span(hyps[(1, 1)])])
        y_all, ok_ref = reference.between(t0, t1, max_gap)
        y_all = y_all[:, 0]
    turns, ok = {}, ok_ref.copy()
    for h, cum in hyps.items():
        values, ok_h = cum.between(t0, t1, max_gap)
        turns[h] = values[:, 1]
        ok &= ok_h
    figures = {"reference": ref_name}
    y = y_all[ok]
    dt = (t1 - t0)[ok]
    signal = max(float(np.abs(y).sum()), max(float(np.abs(w[ok]).sum()) for w in turns.values()))
    if np.count_nonzero(ok) < 10 or signal < config.min_turn:
        return (Finding("wheel sign", "wheel", UNDECIDED,
                        f"wheel0/data.csv: the encoders' signs not checked against the {ref_name} (neither turns "
                        f"{config.min_turn:g} rad in all); the wheels are used as stated", figures), wheel)
    norm = float(np.linalg.norm(y)) + max(float(np.linalg.norm(w[ok])) for w in turns.values())
    mismatch = {h: float(np.linalg.norm(_fit_bounded(y, turns[h][ok], dt, BASE_FACTOR))) / norm for h in _HYPOTHESES}
    best = min(mismatch, key=mismatch.get)
    figures["mismatch"] = {f"{'+' if h[0] > 0 else '-'}left {'+' if h[1] > 0 else '-'}right": round(m, 3)
                           for h, m in mismatch.items()}
    if (best == (1, 1) or mismatch[(1, 1)] <= MISMATCH_BAD or mismatch[best] >= MISMATCH_GOOD
            or mismatch[best] > mismatch[(1, 1)] / 3):
        return Finding("wheel sign", "wheel", KEPT, "", figures), wheel
    columns = [c for c, s in zip(("left", "right"), best) if s < 0]
    which = " and ".join(columns)
    subject = f"the {which} encoder counts" if len(columns) == 1 else "both encoders count"
    fixed = dataclasses.replace(wheel, left=best[0] * np.asarray(wheel.left, dtype=np.int64),
                                right=best[1] * np.asarray(wheel.right, dtype=np.int64))
    return (Finding("wheel sign", "wheel", CORRECTED,
                    f"wheel0/data.csv: {subject} backwards (negated, the wheels' turn follows the {ref_name}'s: "
                    f"mismatch {mismatch[best]:.2f}, as recorded {mismatch[(1, 1)]:.2f}); this run negates the {which} "
                    f"column{'s' if len(columns) > 1 else ''}: fix the encoder's direction or negate the column in the "
                    "file", figures),
            fixed)


def check_twist_sign(odom: TwistData, reference: Cumulative | Steps, ref_name: str, config: ConsistencyConfig,
                     max_gap: float) -> tuple[Finding, TwistData]:
    """The twist's ``wz`` sign against the reference turn (module docstring)."""
    cum = twist_travel(odom)
    if isinstance(reference, Steps):
        t0, t1, y = reference.t0, reference.t1, reference.delta[:, 2]
        ok = np.ones(len(t0), bool)
    else:
        t0, t1 = grid([span(reference), span(cum)])
        y, ok = reference.between(t0, t1, max_gap)
        y = y[:, 0]
    w, ok_w = cum.between(t0, t1, max_gap)
    ok &= ok_w
    figures = {"reference": ref_name}
    if np.count_nonzero(ok) < 10 or float(np.abs(y[ok]).sum()) < config.min_turn:
        return Finding("twist sign", "odom", KEPT, "", figures), odom  # nothing turns: nothing to say
    X = np.column_stack([w[ok, 2], (t1 - t0)[ok]])
    b, _, used = robust_lstsq(X, y[ok])
    base = X[used, 1] * (float(X[used, 1] @ y[ok][used]) / float(X[used, 1] @ X[used, 1]))
    fit = explained(y[ok][used], X[used] @ b, base)
    figures.update(turn_scale=round(float(b[0]), 3), fit=round(fit, 3))
    if b[0] >= 0 or fit < config.mounting_min_fit:
        return Finding("twist sign", "odom", KEPT, "", figures), odom
    return (Finding("twist sign", "odom", CORRECTED,
                    f"odom0/data.csv: the twist's wz turns the other way from the {ref_name} ({-b[0]:.2f} times its "
                    f"turn with the opposite sign, {100 * fit:.0f} % of it explained); this run negates wz: fix the "
                    "sign of the odometry's angular velocity", figures),
            dataclasses.replace(odom, wz=-np.asarray(odom.wz, dtype=np.float64)))


def _rotate(vx: np.ndarray, vy: np.ndarray, angle) -> tuple[np.ndarray, np.ndarray]:
    c, s = np.cos(angle), np.sin(angle)
    return c * vx - s * vy, s * vx + c * vy


def _principal(vx: np.ndarray, vy: np.ndarray) -> float:
    """The angle that turns the velocities' principal axis onto x (up to a half turn)."""
    return -0.5 * math.atan2(2.0 * float(vx @ vy), float(vx @ vx - vy @ vy))


def sideways(vx: np.ndarray, vy: np.ndarray) -> float:
    """``Σ vy² / Σ (vx² + vy²)`` of the moving samples (0 without any)."""
    moving = np.hypot(vx, vy) > MOVING
    total = float(vx[moving] @ vx[moving] + vy[moving] @ vy[moving])
    return float(vy[moving] @ vy[moving]) / total if total > 0 else 0.0


def check_twist_frame(odom: TwistData, camera: Steps | None, max_gap: float) -> tuple[Finding, TwistData]:
    """The twist's velocity frame (module docstring)."""
    vx = np.asarray(odom.vx, dtype=np.float64)
    vy = np.asarray(odom.vy, dtype=np.float64)
    ok = np.isfinite(vx) & np.isfinite(vy) & np.isfinite(odom.wz) & np.isfinite(odom.t)
    stated = sideways(vx[ok], vy[ok])
    figures = {"sideways_stated": round(stated, 3)}
    if stated <= SIDEWAYS_BAD:
        return Finding("twist frame", "odom", KEPT, "", figures), odom
    t = np.asarray(odom.t, dtype=np.float64)
    order = np.argsort(np.where(ok, t, np.inf), kind="stable")
    heading = np.zeros(len(t))
    seg = np.where(ok, odom.wz, 0.0)[order][:-1] * np.diff(np.where(ok, t, 0.0)[order])
    heading[order] = np.concatenate([[0.0], np.cumsum(np.where(np.isfinite(seg), seg, 0.0))])
    candidates = {}
    for name, (bx, by) in (("odometry frame", _rotate(vx, vy, -heading)), ("turned axes", (vx, vy))):
        alpha = _principal(bx[ok], by[ok])
        fx, fy = _rotate(bx, by, alpha)
        forward = _forward_sign(odom, fx, fy, camera, max_gap)
        if forward < 0:
            alpha += math.pi
            fx, fy = -fx, -fy
        candidates[name] = (sideways(fx[ok], fy[ok]), alpha, fx, fy)
    best = min(candidates, key=lambda k: candidates[k][0])
    share, alpha, fx, fy = candidates[best]
    figures.update({f"sideways_{k.replace(' ', '_')}": round(v[0], 3) for k, v in candidates.items()})
    if share >= SIDEWAYS_GOOD:
        return (Finding("twist frame", "odom", UNDECIDED,
                        f"odom0/data.csv: {100 * stated:.0f} % of the twist's velocity is sideways (vy) and neither the "
                        "odometry frame nor turned axes explain it; the twist is used as stated (the backends take only "
                        "vx: write vx, vy in the robot's frame)", figures), odom)
    if best == "odometry frame":
        what = ("its velocity turns with the robot's heading: vx, vy are in the odometry frame, not the robot's "
                "(child_frame_id)")
    else:
        deg = math.degrees(math.remainder(alpha, 2.0 * math.pi))
        what = (f"its x axis points {abs(deg):.0f}° {'left' if deg > 0 else 'right'} of the robot's forward axis "
                "(vx, vy swapped or negated)")
    return (Finding("twist frame", "odom", CORRECTED,
                    f"odom0/data.csv: {what} ({100 * stated:.0f} % of the velocity sideways as recorded, "
                    f"{100 * share:.1f} % in the robot's frame); this run turns vx, vy into the robot's frame: write "
                    "the columns vx, vy in the robot's own frame", figures),
            dataclasses.replace(odom, vx=np.where(ok, fx, odom.vx), vy=np.where(ok, fy, odom.vy)))


def _forward_sign(odom: TwistData, fx: np.ndarray, fy: np.ndarray, camera: Steps | None, max_gap: float) -> float:
    """Positive when the turned velocity's x drives the way the robot does: along the camera's forward motion
    when there is a camera, else forward for most of the distance."""
    if camera is not None:
        cum = twist_travel(TwistData(odom.t, fx, fy, odom.wz))
        d, ok = cum.between(camera.t0, camera.t1, max_gap)
        if np.count_nonzero(ok) >= 10:
            return float(d[ok, 0] @ camera.delta[ok, 0])
    t = np.asarray(odom.t, dtype=np.float64)
    dt = np.diff(t)
    good = np.isfinite(fx[:-1]) & np.isfinite(dt)
    return float(np.sum(fx[:-1][good] * dt[good]))
