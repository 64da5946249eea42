"""The IMU's mounting estimated from the data, against the ``T_BS`` of ``imu0/sensor.yaml``.

The backends use the gyro's rate about the body's up axis, ``ω_z = z_S · ω_S`` with ``z_S`` the third row
of ``R_BS`` (the body's z axis in the IMU frame), and the AHRS heading of ``R_WS R_BSᵀ``. A wrong ``R_BS``
(an IMU on its side, upside down, turned) feeds them a rate that has little to do with the turn.

Three independent estimates of the mounting come from the data:

* **the gyro's turn axis**: over the intervals ``[t_0, t_1]`` of the reference (the camera's increments,
  else the wheels' or the odometry's over 0.1 s) the gyro's angle about its three axes ``Θ_S``; the axis it
  turned about most is the principal eigenvector of ``Σ Θ_S Θ_Sᵀ``, its sign the one whose angle turns with
  the reference. (A free regression ``θ_ref = a · Θ_S`` is not used: the gyro's other two axes see only
  the platform's small roll and pitch, and any correlation of those with the reference's errors, a camera's
  yaw under tilt, turns ``a`` by tens of degrees on a planar drive.) The reference may be stamped late (a
  controller's odometry): the delay of the reference's rate behind the gyro's about that axis
  (:func:`fusion_vo.sensors.sync.rate_delay`) is removed and the axis found again. How well it fits is
  the fraction of the reference's turn that ``θ_ref = k (z · Θ_S) + c Δt`` explains beside a bias alone
  (least squares over every interval; ``k`` is the reference's turn per radian of the gyro's, a
  skid-steered base's odometry reports a fraction of it; ``c`` takes the gyro's bias), about the gyro's
  axis and about the stated ``z_S``;
* **gravity**: a ground robot's specific force averages to ``g`` along the body's up, so the mean of the
  accelerometer's samples points along ``z_S`` when its length is ``g`` (within 20 %; an accelerometer whose
  gravity was removed has none);
* **the heading of the axes about the vertical**: over windows of about half a second, the accelerometer's
  velocity change ``∫a_S dt = x_S Δv + y_S ∫v ω dt + c T`` against the reference's change of forward speed
  ``Δv`` and its centripetal ``∫ v ω dt`` (``c`` gravity and bias) gives the body's forward and left axes
  in the IMU frame; their components perpendicular to ``z_S`` give the angle of the forward axis about it,
  each with its standard error, combined by inverse variance. It is used when its standard error is below
  10°; otherwise the heading about the vertical is kept as ``T_BS`` states it (the smallest rotation that
  takes the stated up axis to the estimated one). It changes no yaw rate; an AHRS heading's constant offset
  is aligned away by the backends.

The rotation is assembled with scipy's ``Rotation.align_vectors`` (the up axis exactly, the forward axis as
close as it allows) and snapped to the nearest axis-aligned mounting (multiples of 90°) when within 5° of
it, as an IMU is usually mounted.

Decision (:func:`decide`): an estimate counts when it can be made (the reference turns at least
``min_turn`` in all and the gyro's best axis explains at least ``mounting_min_fit`` of its turn; gravity
has the right length). The stated mounting is contradicted when a counting estimate is further than
``mounting_tolerance_deg`` from the stated up axis, unless the gyro's (the axis the backends read) agrees
with it: gravity alone disagreeing then leaves the IMU as stated, with a warning. Contradicted and the
counting estimates agree within ``mounting_agreement_deg`` (or only one counts): the estimated mounting
replaces the stated one, and the sentence gives it as ``imu0/sensor.yaml`` ``T_BS`` data and as
``import-bag --static-tf``, ready to paste. Contradicted but they disagree: the IMU is left out (it is never
fused as stated). A gyro that turns exactly the other way from the reference while gravity agrees with the
stated axis points at the reference, not the IMU (an odometry or encoder with the wrong sign,
:mod:`fusion_vo.consistency.wheels`): the IMU is kept. No estimate at all: the IMU is used as stated, with a
warning.

On robot_localization's Husky log imported without its launch file's static transform (``T_BS`` the
identity), the odometry's yaw rate is 0.44 s behind the gyro, the gyro turns about an axis 0.8° from the IMU's
+y, which explains 92 % of the odometry's turn against 0 % for the stated +z, and gravity lies 1.4° from +y;
the accelerations put the body's forward axis along the IMU's -z (standard error 3.1°): the launch file's
transform. Fused with it, the tracks end 2.52-2.53 m RMS from the GPS fixes, as with the transform; as stated
20.4-20.7 m (``benchmarks/contradictions.py``, section 1).
"""

from __future__ import annotations

import itertools
import logging
import math
from dataclasses import dataclass

import numpy as np

from fusion_vo.consistency.config import ConsistencyConfig
from fusion_vo.consistency.finding import CORRECTED, KEPT, REFUSED, UNDECIDED, Finding
from fusion_vo.consistency.signals import Motion, explained, imu_axes
from fusion_vo.measurements import ImuData
from fusion_vo.sensors.sync import rate_delay

logger = logging.getLogger(__name__)

GRAVITY = 9.80665
#: the mean specific force counts as gravity when its length is within this fraction of ``GRAVITY``
GRAVITY_TOLERANCE = 0.2
#: the heading of the IMU's axes about the vertical is used when its standard error is below this [deg]
HEADING_SIGMA_DEG = 10.0
#: an estimated rotation within this of an axis-aligned one [deg] is taken to be it
SNAP_DEG = 5.0
#: windows of the accelerations [s]
ACCEL_WINDOW = 0.5


@dataclass
class MountingEstimate:
    """What the data say about the IMU's mounting (module docstring).

    ``stated_z``, ``gyro_z``, ``gravity_z``: the body's up in the IMU frame as stated, from the gyro's turn
    axis, from gravity (None when not estimated); ``gyro_fit``, ``stated_fit``: the fraction of the
    reference's turn explained about the best axis and the stated one; ``turn_scale``: the reference's turn
    per radian of the gyro's; ``delay``: the reference's delay behind the gyro [s] (0 when none found);
    ``heading_sigma_deg``: standard error of the axes' heading about the vertical from the accelerations
    (inf when not estimated); ``R_BS``: the estimated rotation (None without an up axis); ``why``: why an
    estimate from the gyro could not be made; ``gyro_bias``, ``gyro_bias_sigma``: the gyro's bias about its
    axis [rad/s] from the same fit, and its standard error (None, inf without it).
    """

    reference: str
    stated_z: np.ndarray
    gyro_z: np.ndarray | None = None
    gyro_fit: float = 0.0
    stated_fit: float = 0.0
    turn_scale: float = 0.0
    delay: float = 0.0
    gravity_z: np.ndarray | None = None
    gravity_norm: float = 0.0
    heading_sigma_deg: float = math.inf
    R_BS: np.ndarray | None = None
    why: str = ""
    gyro_bias: float | None = None
    gyro_bias_sigma: float = math.inf

    def as_dict(self) -> dict:
        def vec(v):
            return None if v is None else [round(float(x), 4) for x in v]

        return {"reference": self.reference, "stated_z": vec(self.stated_z), "gyro_z": vec(self.gyro_z),
                "gyro_fit": round(self.gyro_fit, 3), "stated_fit": round(self.stated_fit, 3),
                "turn_scale": round(self.turn_scale, 3), "delay_s": round(self.delay, 3),
                "gravity_z": vec(self.gravity_z), "gravity_norm": round(self.gravity_norm, 3),
                "heading_sigma_deg": None if not math.isfinite(self.heading_sigma_deg) else round(self.heading_sigma_deg, 1),
                "R_BS": None if self.R_BS is None else [vec(r) for r in self.R_BS]}


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Angle between two directions [deg]."""
    c = float(np.dot(a, b) / (np.linalg.norm(a) * np.linalg.norm(b)))
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))


def gravity_axis(imu: ImuData) -> tuple[np.ndarray | None, float]:
    """The mean specific force's direction in the IMU frame when its length is gravity's, and its length."""
    accel = np.asarray(imu.accel, dtype=np.float64)
    accel = accel[np.isfinite(accel).all(axis=1)]
    if not len(accel):
        return None, 0.0
    mean = accel.mean(axis=0)
    norm = float(np.linalg.norm(mean))
    if abs(norm - GRAVITY) > GRAVITY_TOLERANCE * GRAVITY:
        return None, norm
    return mean / norm, norm


def estimate(imu: ImuData, ref: Motion | None, config: ConsistencyConfig, max_gap: float,
             max_delay: float) -> MountingEstimate:
    """The three estimates of the module docstring against the reference motion ``ref``."""
    stated = np.asarray(imu.T_BS, dtype=np.float64)[:3, :3]
    est = MountingEstimate(reference=ref.name if ref is not None else "", stated_z=stated[2].copy())
    est.gravity_z, est.gravity_norm = gravity_axis(imu)
    if ref is None:
        est.why = "no other sensor measures the turn"
    else:
        _gyro_axis(imu, ref, config, max_gap, max_delay, est)
    up = est.gyro_z if est.gyro_z is not None and est.gyro_fit >= config.mounting_min_fit else None
    if est.gravity_z is not None and (up is None or angle_deg(up, est.gravity_z) <= config.mounting_agreement_deg):
        up = est.gravity_z  # the finer of the two when they agree: the drive's average up
    if up is None:
        return est
    forward, sigma = (None, math.inf) if ref is None else _forward_axis(imu, ref.shifted(est.delay), up, max_gap)
    est.heading_sigma_deg = sigma
    est.R_BS = rotation(up, forward if sigma < HEADING_SIGMA_DEG else None, stated)
    return est


def _gyro_axis(imu: ImuData, ref: Motion, config: ConsistencyConfig, max_gap: float, max_delay: float,
               est: MountingEstimate) -> None:
    axes = imu_axes(imu)
    if len(axes.t) < 3:
        est.why = "the IMU has too few samples"
        return
    for attempt in range(2):  # the second time with the reference on the gyro's clock
        shifted = ref.shifted(est.delay)
        g, ok = axes.between(shifted.t0, shifted.t1, max_gap)
        turn = float(np.abs(ref.turn[ok]).sum())
        if np.count_nonzero(ok) < 10 or turn < config.min_turn:
            est.why = (f"the {ref.name} {'turn' if ref.name == 'wheels' else 'turns'} {turn:.2f} rad in all where the "
                       f"IMU has samples, at least {config.min_turn:g} needed")
            return
        g, y, dt = g[ok], ref.turn[ok], shifted.dt[ok]
        axis = principal_axis(g)
        if float((g @ axis) @ y) < 0:
            axis = -axis
        if attempt:
            break
        rate_t, rates = _finite_rates(imu)
        delay = rate_delay(0.5 * (ref.t0 + ref.t1), ref.turn / ref.dt, rate_t, rates @ axis, max_delay=max_delay)
        if delay is None or abs(delay) < 0.5 * float(np.median(ref.dt)):
            break
        est.delay = delay
    base = dt * (float(dt @ y) / float(dt @ dt))
    for direction, name in ((axis, "gyro"), (est.stated_z, "stated")):
        X = np.column_stack([g @ direction, dt])
        b, *_ = np.linalg.lstsq(X, y, rcond=None)
        fit = explained(y, X @ b, base)
        if name == "gyro":
            est.gyro_z, est.gyro_fit, est.turn_scale = axis, fit, float(b[0])
            if b[0] > 0:  # θ_ref = k (θ + b_g Δt) + c Δt: the gyro's bias about the axis is -c / k
                res = y - X @ b
                cov = float(res @ res) / max(len(y) - 2, 1) * np.linalg.inv(X.T @ X)
                est.gyro_bias = -float(b[1] / b[0])
                est.gyro_bias_sigma = float(np.sqrt(max(cov[1, 1], 0.0))) / float(b[0])
        else:
            est.stated_fit = fit


def principal_axis(g: np.ndarray) -> np.ndarray:
    """The direction about which the gyro turned most: the principal eigenvector of ``Σ Θ Θᵀ`` over the
    intervals' angles ``Θ`` (M, 3)."""
    _, vectors = np.linalg.eigh(g.T @ g)
    return vectors[:, -1]


def _finite_rates(imu: ImuData) -> tuple[np.ndarray, np.ndarray]:
    t = np.asarray(imu.t, dtype=np.float64)
    g = np.asarray(imu.gyro, dtype=np.float64)
    ok = np.isfinite(t) & np.isfinite(g).all(axis=1)
    order = np.argsort(t[ok], kind="stable")
    return t[ok][order], g[ok][order]


def _forward_axis(imu: ImuData, ref: Motion, up: np.ndarray, max_gap: float) -> tuple[np.ndarray | None, float]:
    """The body's forward axis in the IMU frame from the accelerations (module docstring), perpendicular to
    ``up``, and the standard error of its angle about ``up`` [deg]."""
    accel = imu_axes(imu, accel=True)
    dt = ref.dt
    if len(accel.t) < 3 or len(ref) < 10 or not np.all(dt > 0):
        return None, math.inf
    mid = 0.5 * (ref.t0 + ref.t1)
    speed = ref.distance / dt
    turning = speed * ref.turn  # v ω dt of each interval
    cent = np.cumsum(turning) - 0.5 * turning  # ∫ v ω dt from the first interval's start to each middle
    step = max(1, int(round(ACCEL_WINDOW / float(np.median(dt)))))
    a_idx = np.arange(0, len(ref) - step, step)
    b_idx = a_idx + step
    contiguous = np.abs((mid[b_idx] - mid[a_idx]) - step * np.median(dt)) < 0.5 * step * np.median(dt)
    a_idx, b_idx = a_idx[contiguous], b_idx[contiguous]
    if len(a_idx) < 10:
        return None, math.inf
    dv = speed[b_idx] - speed[a_idx]
    c = cent[b_idx] - cent[a_idx]
    span = mid[b_idx] - mid[a_idx]
    f, ok = accel.between(mid[a_idx], mid[b_idx], max_gap)
    if np.count_nonzero(ok) < 10:
        return None, math.inf
    X = np.column_stack([dv, c, span])[ok]
    Y = f[ok]
    try:
        inv = np.linalg.inv(X.T @ X)
    except np.linalg.LinAlgError:
        return None, math.inf
    B = inv @ X.T @ Y
    res = Y - X @ B
    sigma_res = res.T @ res / max(len(Y) - 3, 1)
    u = _perpendicular(up)
    w = np.cross(up, u)
    angles, variances = [], []
    for row, offset in ((0, 0.0), (1, -0.5 * math.pi)):
        v = B[row]
        p = np.array([v @ u, v @ w])
        length = float(np.hypot(*p))
        if not length > 0:
            continue
        phi = math.atan2(p[1], p[0])
        normal = -math.sin(phi) * u + math.cos(phi) * w  # in the plane, across the projection
        var = float(inv[row, row] * (normal @ sigma_res @ normal)) / length**2
        angles.append(phi + offset)
        variances.append(var)
    if not angles:
        return None, math.inf
    weights = 1.0 / np.maximum(variances, 1e-12)
    phi = math.atan2(float(weights @ np.sin(angles)), float(weights @ np.cos(angles)))
    sigma = math.degrees(math.sqrt(1.0 / float(weights.sum())))
    return math.cos(phi) * u + math.sin(phi) * w, sigma


def _perpendicular(v: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to ``v`` (the IMU axis least aligned with it, made perpendicular)."""
    e = np.eye(3)[int(np.argmin(np.abs(v)))]
    p = e - (e @ v) * v
    return p / np.linalg.norm(p)


#: the 24 axis-aligned rotations
_AXIS_ALIGNED = [np.array(m, dtype=np.float64) for m in (
    np.stack([s0 * np.eye(3)[p[0]], s1 * np.eye(3)[p[1]], s2 * np.eye(3)[p[2]]])
    for p in itertools.permutations(range(3)) for s0 in (1, -1) for s1 in (1, -1) for s2 in (1, -1))
    if np.linalg.det(m) > 0]


def scipy_rotation():
    """scipy's ``Rotation``, loaded on first use (only when an IMU is checked; a live stream loads it when it is
    built, :class:`~fusion_vo.backends.streaming.StreamingFusion`, so that its first samples do not wait)."""
    from scipy.spatial.transform import Rotation

    return Rotation


def rotation(up: np.ndarray, forward: np.ndarray | None, stated: np.ndarray) -> np.ndarray:
    """``R_BS`` whose third row is ``up`` and whose first row is ``forward`` as far as it allows (scipy's
    ``align_vectors``, the up axis exactly), or, without ``forward``, the stated ``R_BS`` turned by the
    smallest rotation that takes its up axis to ``up``; snapped to an axis-aligned rotation within
    ``SNAP_DEG``."""
    Rotation = scipy_rotation()
    if forward is not None:
        r, _ = Rotation.align_vectors([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]], [up, forward], weights=[np.inf, 1.0])
        R = r.as_matrix()
    else:
        r, _ = Rotation.align_vectors([[0.0, 0.0, 1.0]], [stated @ up])
        R = r.as_matrix() @ stated
    for m in _AXIS_ALIGNED:
        if math.degrees(Rotation.from_matrix(m @ R.T).magnitude()) <= SNAP_DEG:
            return m.copy()
    return R


def decide(imu: ImuData, est: MountingEstimate, config: ConsistencyConfig) -> Finding:
    """The decision of the module docstring, with its sentence."""
    counted = {}
    if est.gyro_z is not None and est.gyro_fit >= config.mounting_min_fit:
        counted["gyro"] = est.gyro_z
    if est.gravity_z is not None:
        counted["gravity"] = est.gravity_z
    figures = est.as_dict()
    if not counted:
        why = est.why or f"the gyro's best axis explains {100 * est.gyro_fit:.0f} % of the {est.reference}'s turn"
        gravity = f"; the accelerometer's mean ({est.gravity_norm:.2f} m/s²) is not gravity"
        return Finding("mounting", "imu", UNDECIDED,
                       f"imu0/sensor.yaml: T_BS not checked against the data ({why}{gravity}); the IMU is used as "
                       "stated", figures)
    off = {k: angle_deg(v, est.stated_z) for k, v in counted.items()}
    if all(a <= config.mounting_tolerance_deg for a in off.values()):
        return Finding("mounting", "imu", KEPT, "", figures)
    if ("gyro" in off and off["gyro"] > 180.0 - config.mounting_tolerance_deg
            and off.get("gravity", 180.0) <= config.mounting_tolerance_deg):
        figures["reference_reversed"] = True  # the reference turns the other way: its sign is the liar
        return Finding("mounting", "imu", KEPT, "", figures)
    if off.get("gyro", 180.0) <= config.mounting_tolerance_deg:  # the axis the backends read is right
        return Finding("mounting", "imu", UNDECIDED,
                       f"imu0/sensor.yaml: the gyro turns about the up axis T_BS states, but gravity lies "
                       f"{off['gravity']:.0f}° from it; the IMU is used as stated (check the accelerometer's axes)",
                       figures)
    agree = len(counted) == 1 or angle_deg(counted["gyro"], counted["gravity"]) <= config.mounting_agreement_deg
    evidence = _evidence(est, off)
    if not agree or est.R_BS is None:
        return Finding("mounting", "imu", REFUSED,
                       f"imu0/sensor.yaml: T_BS contradicts the data ({evidence}), but the gyro's axis and gravity "
                       f"disagree by {angle_deg(counted['gyro'], counted['gravity']):.0f}°, so the data do not say how "
                       "the IMU is mounted: the IMU is left out of this run; set T_BS (or import-bag --static-tf) to "
                       "its true mounting", figures)
    T = np.array(imu.T_BS, dtype=np.float64)
    T[:3, :3] = est.R_BS
    heading = ("" if est.heading_sigma_deg < HEADING_SIGMA_DEG else
               "; its heading about the vertical is kept as stated (the accelerations do not fix it)")
    return Finding("mounting", "imu", CORRECTED,
                   f"imu0/sensor.yaml: T_BS contradicts the data ({evidence}); this run fuses the IMU with the "
                   f"mounting estimated from the data{heading}: to keep it, set T_BS data: {yaml_rows(T)} in "
                   f"imu0/sensor.yaml, or import the bag with --static-tf \"{static_tf(T)}\"", figures)


def _evidence(est: MountingEstimate, off: dict) -> str:
    up = est.R_BS[2] if est.R_BS is not None else est.gyro_z if est.gyro_z is not None else est.gravity_z
    parts = [f"the body's up is the IMU's {axis_name(up)}, {max(off.values()):.0f}° from the stated one"]
    if "gyro" in off:
        parts.append(f"the gyro's turn about it explains {100 * est.gyro_fit:.0f} % of the {est.reference}'s, "
                     f"{100 * max(est.stated_fit, 0.0):.0f} % about the stated axis")
    if "gravity" in off:
        parts.append(f"gravity lies {angle_deg(up, est.gravity_z):.0f}° from it")
    return "; ".join(parts)


def axis_name(v: np.ndarray) -> str:
    """``+y`` for a direction within 5° of an IMU axis, else its components."""
    i = int(np.argmax(np.abs(v)))
    if abs(v[i]) >= math.cos(math.radians(SNAP_DEG)):
        return f"{'+' if v[i] > 0 else '-'}{'xyz'[i]} axis"
    return "axis (" + ", ".join(f"{x:.2f}" for x in v) + ")"


def _number(x: float) -> str:
    x = round(float(x), 4)
    return "0.0" if x == 0 else f"{x:g}" if x != int(x) else f"{x:.1f}"


def yaml_rows(T: np.ndarray) -> str:
    """``T_BS``'s 16 numbers as the ``data:`` list of ``imu0/sensor.yaml``."""
    return "[" + ", ".join(_number(x) for x in np.asarray(T, dtype=np.float64).reshape(-1)) + "]"


def static_tf(T: np.ndarray, parent: str = "base_link", child: str = "imu_link") -> str:
    """``x y z yaw pitch roll parent child`` of ``T_BS`` (``static_transform_publisher``'s order,
    ``R = Rz(yaw) Ry(pitch) Rx(roll)``; the frame names are those of a usual bag: put the bag's own)."""
    yaw, pitch, roll = scipy_rotation().from_matrix(np.asarray(T, dtype=np.float64)[:3, :3]).as_euler("ZYX")
    x, y, z = np.asarray(T, dtype=np.float64)[:3, 3]
    return " ".join(_number(v) for v in (x, y, z, yaw, pitch, roll)) + f" {parent} {child}"
