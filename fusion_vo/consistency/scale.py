"""The camera's and the wheels' distances against each other and against both their priors.

The backends estimate the camera's scale ``k_v`` (its height) and the wheels' ``k_r`` (their radius) around
1 with prior standard deviations ``σ_v`` (``height_sigma / height`` of ``cam0/sensor.yaml``, else
``fusion.visual_scale_sigma``) and ``σ_r`` (``radius_sigma / radius`` of ``wheel0/sensor.yaml``, else
``fusion.wheel_scale_sigma``): :func:`fusion_vo.backends.timeline.scale_priors`. Only their ratio is
measured. A gross error in one of them (a focal length or height off by a factor, a radius given as a
diameter) is far outside both priors, and the backends then share it out by the priors' variances: with
the camera height stated to 0.1 mm the wheels take most of it, and every fused track inherits the camera's
wrong distances.

Ratio. Over the camera's increments on straight stretches (turn rate below ``STRAIGHT_RATE``) where both
move (faster than ``MOVING``), grouped into windows of about ``WINDOW`` seconds, each window's ratio is the
camera's distance over the wheels' (encoder travel, or the odometry's ``vx`` held between samples); the
estimate ``ρ`` is the median of the windows' ratios, its standard error ``σ_ρ`` 1.4826 times their median
absolute deviation (in logarithm) over ``√n``. At least ``MIN_WINDOWS`` windows and ``MIN_DISTANCE`` metres
are needed, else the check says it cannot decide and both are fused as stated.

Decision. The ratio contradicts the priors when ``|ln ρ| > scale_sigmas · √(σ_v² + σ_r² + σ_ρ²)`` and
``|ρ - 1| > scale_min_ratio``. A calibration error is in every window, turning or not; when a quarter of the
windows in which both move, turns included (at least ``MIN_WINDOWS``), are nearer 1 than ``ρ`` and their own
median does not contradict the priors, the ratio changed during the recording instead (a wheel that slipped for a
while, a camera that lost its scale): both are used as stated, the finding says so, and the speed check of
:mod:`fusion_vo.backends.monitor` drops the wheels' speed where the two disagree (the wheels are its suspect: slip
is the common cause of a passing disagreement, as a wrong focal length or height is of a lasting one). Otherwise
which one is wrong is asked of a third sensor, the accelerometer: over
windows of half a second, each one's change of forward speed against the accelerometer's velocity change
along the body's x axis (``R_BS`` of the IMU after the mounting check; an intercept per second takes its bias
and any gravity from a tilt), ``Δv = s ∫a_x dt + c T``. The sensor whose slope ``s`` is near 1 has the right
scale, when both slopes are known to within ``ARBITER_SIGMA`` and one is at least three times closer to 1
(in logarithm) than the other. Without an accelerometer, or when it cannot tell, the camera is the one taken
to be wrong: its scale rests on a focal length, a height and a floor model, any of them easily wrong by a
factor (``--focal-length`` is a guess when the lens is uncalibrated), the wheels' on one radius; the sentence
says the data could not tell.

What is done with the wrong one. The camera: its translation is left out (standard deviation ``LEFT_OUT``, no
correlation with its heading) and its heading kept; the wheels then carry the distance and the camera still
straightens the heading. A wrong focal length is not only a scale: the increments are the camera's motion
conjugated by its mounting (:mod:`fusion_vo.geometry.ground`), so a camera ahead of the axle reads a turn in
place as a translation of ``(ρ - 1)`` times its lever arm's arc, and the lens model estimated under the wrong
focal length bends the rest. Leaving the translation out needs no model of how the focal length bent the
increments; releasing the camera's scale prior alone would leave the lever arm's and the lens model's errors
in them (docs/consistency.md, "A wrong focal length"; ``python benchmarks/contradictions.py --full``). The
wheels: their radii (or the twist's velocity) are multiplied by ``ρ``, the ``radius_sigma`` of
``wheel0/sensor.yaml`` is dropped and their scale prior widened to ``released_scale_sigma``, so the camera
sets the scale and the backends start from the measured ratio. Both replace the prior of the scale they give
up by ``released_scale_sigma``.
"""

from __future__ import annotations

import dataclasses
import logging
import math

import numpy as np

from fusion_vo.backends.timeline import scale_priors
from fusion_vo.consistency.config import ConsistencyConfig
from fusion_vo.consistency.finding import CORRECTED, KEPT, UNDECIDED, Finding
from fusion_vo.consistency.signals import Steps, camera_steps, imu_axes, twist_travel, wheel_travel

logger = logging.getLogger(__name__)

STRAIGHT_RATE = 0.15  # [rad/s]
MOVING = 0.02  # [m/s]
WINDOW = 1.0  # [s]
MIN_WINDOWS = 3
MIN_DISTANCE = 0.1  # [m]
ARBITER_WINDOW = 0.5  # [s]
ARBITER_SIGMA = 0.15  # standard error of a slope's logarithm
LEFT_OUT = 100.0  # [m] standard deviation of a translation left out


def _wheel_distance(streams):
    if streams.wheel is not None:
        return wheel_travel(streams.wheel), "wheel0/sensor.yaml", "wheels'"
    if streams.odom is not None:
        return twist_travel(streams.odom), "odom0", "odometry's"
    return None, "", ""


@dataclasses.dataclass
class ScaleRatio:
    """The camera's distance over the wheels' on straight stretches (module docstring): ``rho`` the median over the
    windows, ``sigma`` its standard error in logarithm (NaN without enough windows), ``distance`` the wheels' [m];
    per window its ratio and its span ``(t0, t1)`` [s]."""

    rho: float
    sigma: float
    distance: float
    ratios: np.ndarray
    spans: np.ndarray

    @property
    def windows(self) -> int:
        return len(self.ratios)


def ratio(steps: Steps, wheel_d: np.ndarray, ok: np.ndarray, straight_rate: float = STRAIGHT_RATE) -> ScaleRatio:
    """The distance ratio of the camera's ``steps`` to the wheels' travel over them (module docstring), over the
    steps turning slower than ``straight_rate`` [rad/s]."""
    cam_d = np.hypot(steps.delta[:, 0], steps.delta[:, 1])
    dt = steps.dt
    use = (ok & (np.abs(steps.delta[:, 2]) < straight_rate * dt) & (cam_d > MOVING * dt)
           & (np.abs(wheel_d) > MOVING * dt))
    idx = np.flatnonzero(use)
    ratios, spans, distance = [], [], 0.0
    start, c_sum, w_sum, time = None, 0.0, 0.0, 0.0
    for i in idx:
        if start is not None and i != start[1] + 1:  # a gap: the window ends
            start, c_sum, w_sum, time = None, 0.0, 0.0, 0.0
        start = (i if start is None else start[0], i)
        c_sum += cam_d[i]
        w_sum += abs(wheel_d[i])
        time += dt[i]
        if time >= WINDOW:
            ratios.append(c_sum / w_sum)
            spans.append((float(steps.t0[start[0]]), float(steps.t1[i])))
            distance += w_sum
            start, c_sum, w_sum, time = None, 0.0, 0.0, 0.0
    found = np.array(ratios, dtype=np.float64), np.array(spans, dtype=np.float64).reshape(-1, 2)
    if len(ratios) < MIN_WINDOWS or distance < MIN_DISTANCE:
        return ScaleRatio(math.nan, math.nan, distance, *found)
    return ScaleRatio(*median_ratio(found[0]), distance, *found)


def median_ratio(ratios: np.ndarray) -> tuple[float, float]:
    """The median of ``ratios`` and its standard error in logarithm: 1.4826 times their median absolute deviation in
    logarithm over ``√n`` (module docstring)."""
    logs = np.log(ratios)
    centre = float(np.median(logs))
    return math.exp(centre), 1.4826 * float(np.median(np.abs(logs - centre))) / math.sqrt(len(logs))


def contradicts(rho: float, sigma: float, s_v: float, s_w: float, cc: ConsistencyConfig) -> bool:
    """Whether the ratio ``rho`` (standard error ``sigma`` in logarithm) contradicts the priors ``s_v``, ``s_w``."""
    return (abs(math.log(rho)) > cc.scale_sigmas * math.sqrt(s_v**2 + s_w**2 + sigma**2)
            and abs(rho - 1.0) > cc.scale_min_ratio)


def agreeing(rho: float, moving: ScaleRatio, s_v: float, s_w: float, cc: ConsistencyConfig) -> np.ndarray | None:
    """The windows of ``moving`` (all the windows in which both move, turns included) in which the two agree with
    their priors while the straight windows' median ``rho`` contradicts them: those nearer 1 than ``rho`` (in
    logarithm), when they are at least :data:`MIN_WINDOWS` and a quarter of all and their own median ratio does not
    contradict the priors; else None. Such a ratio changed during the recording (a wheel that slipped, a camera that
    lost its scale for a while): no calibration error, and the speed check's to find. A scale error is in every
    window, turning or not."""
    if not moving.windows:
        return None
    near = np.abs(np.log(moving.ratios)) < 0.5 * abs(math.log(rho))
    n = int(np.count_nonzero(near))
    if n < MIN_WINDOWS or n < 0.25 * moving.windows:
        return None
    return None if contradicts(*median_ratio(moving.ratios[near]), s_v, s_w, cc) else near


def arbiter(streams, steps: Steps, wheel_cum, max_gap: float) -> tuple[float, float, float, float] | None:
    """Slopes of the camera's and the wheels' speed changes against the accelerometer's, with the standard
    errors of their logarithms: ``(s_camera, σ_camera, s_wheels, σ_wheels)``, or None without an
    accelerometer or enough accelerations."""
    imu = streams.imu
    if imu is None or len(imu) < 10 or len(steps) < 20:
        return None
    accel = imu_axes(imu, accel=True)
    forward = np.asarray(imu.T_BS, dtype=np.float64)[0, :3]
    dt = steps.dt
    mid = 0.5 * (steps.t0 + steps.t1)
    v_cam = np.hypot(steps.delta[:, 0], steps.delta[:, 1]) * np.sign(steps.delta[:, 0]) / dt
    wd, ok = wheel_cum.between(steps.t0, steps.t1, max_gap)
    v_wheel = wd[:, 0] / dt
    n = max(1, int(round(ARBITER_WINDOW / float(np.median(dt)))))
    a = np.arange(0, len(steps) - n, n)
    b = a + n
    f, ok_f = accel.between(mid[a], mid[b], max_gap)
    keep = ok_f & ok[a] & ok[b] & (np.abs((mid[b] - mid[a]) - n * np.median(dt)) < 0.5 * n * np.median(dt))
    if np.count_nonzero(keep) < 10:
        return None
    integral = f[keep] @ forward
    span = (mid[b] - mid[a])[keep]
    out = []
    for v in (v_cam, v_wheel):
        dv = (v[b] - v[a])[keep]
        X = np.column_stack([integral, span])
        try:
            inv = np.linalg.inv(X.T @ X)
        except np.linalg.LinAlgError:
            return None
        coef = inv @ X.T @ dv
        res = dv - X @ coef
        s2 = float(res @ res) / max(len(dv) - 2, 1)
        slope, se = float(coef[0]), math.sqrt(max(s2 * inv[0, 0], 0.0))
        if not slope > 0:
            return None
        out += [slope, se / slope]
    return tuple(out)


def check_scale(streams, config, max_gap: float):
    """The scale check of the module docstring: ``(finding or None, streams, config)`` with the wrong sensor's
    distances corrected and its scale prior released."""
    cc: ConsistencyConfig = config.consistency
    steps = camera_steps(streams.visual)
    wheel_cum, wheel_file, wheel_word = _wheel_distance(streams)
    if steps is None or wheel_cum is None or len(wheel_cum.t) < 2:
        return None, streams, config
    wd, ok = wheel_cum.between(steps.t0, steps.t1, max_gap)
    found = ratio(steps, wd[:, 0], ok)
    rho, sigma_rho, windows, distance = found.rho, found.sigma, found.windows, found.distance
    figures = {"ratio": None if math.isnan(rho) else round(rho, 4), "windows": windows,
               "straight_distance_m": round(distance, 3)}
    if math.isnan(rho):
        return (Finding("scale", "camera", UNDECIDED,
                        f"cam0/sensor.yaml and {wheel_file}: the camera's and the {wheel_word} scales not checked "
                        f"against each other ({windows} straight windows over {distance:.2f} m; at least {MIN_WINDOWS} "
                        f"over {MIN_DISTANCE:g} m needed); both are used as stated", figures), streams, config)
    priors = scale_priors(config, streams.camera_height, streams.camera_height_sigma, None,
                          None if streams.wheel is None else streams.wheel.config)
    s_v, s_w = priors.visual_scale_sigma, priors.wheel_scale_sigma
    log_rho = abs(math.log(rho))
    figures.update(ratio_sigma=round(sigma_rho, 4), camera_prior=s_v, wheel_prior=s_w)
    if not contradicts(rho, sigma_rho, s_v, s_w, cc):
        return Finding("scale", "camera", KEPT, "", figures), streams, config
    moving = ratio(steps, wd[:, 0], ok, straight_rate=np.inf)
    near = agreeing(rho, moving, s_v, s_w, cc)
    if near is not None:
        off = moving.spans[~near]
        figures.update(moving_windows=moving.windows, agreeing_windows=int(np.count_nonzero(near)))
        where = f" (the others from t={off[0, 0]:.2f} to {off[-1, 1]:.2f})" if len(off) else ""
        then = (f"the speed check drops the {wheel_word} speed where the two disagree" if config.monitor else
                "fusion.monitor is off, so nothing is dropped where they disagree")
        return (Finding("scale", "camera", UNDECIDED,
                        f"cam0/sensor.yaml and {wheel_file}: the camera's distances are {rho:.3f} times the {wheel_word} "
                        f"over {distance:.2f} m of straight driving, but agree with the stated scales in "
                        f"{int(np.count_nonzero(near))} of the {moving.windows} windows in which both move{where}: their "
                        f"ratio changed during the recording, which no calibration explains; both are used as stated, "
                        f"and {then}", figures), streams, config)
    slopes = arbiter(streams, steps, wheel_cum, max_gap)
    wrong, said = "camera", "the data cannot tell which (no accelerometer to ask), so the camera's scale is given up"
    if slopes is not None:
        s_c, e_c, s_r, e_r = slopes
        figures.update(accel_slope_camera=round(s_c, 3), accel_slope_wheels=round(s_r, 3))
        lc, lr = abs(math.log(s_c)), abs(math.log(s_r))
        if max(e_c, e_r) < ARBITER_SIGMA and (lr <= lc / 3 or lc <= lr / 3):
            wrong = "camera" if lc > lr else "wheels"
            said = (f"the accelerometer sides with the {'wheels' if wrong == 'camera' else 'camera'} (speed changes "
                    f"{s_c:.2f} times its own for the camera, {s_r:.2f} for the {wheel_word[:-1]})")
        else:
            said = (f"the accelerometer cannot tell which (speed changes {s_c:.2f} and {s_r:.2f} times its own), so "
                    "the camera's scale is given up")
    released = cc.released_scale_sigma
    if wrong == "camera":
        streams = _without_translation(streams)
        config = config.model_copy(update={"visual_scale_sigma": max(released, config.visual_scale_sigma)})
        fix = ("the camera's scale is wrong: check the focal length (cam0/sensor.yaml intrinsics, or --focal-length "
               "with --uncalibrated) and the camera height (cam0/sensor.yaml T_BS)")
        done = (f"this run leaves the camera's translation out (its heading is kept) and lets the {wheel_word} set "
                "the distances")
    else:
        streams = _scaled_wheels(streams, rho)
        config = config.model_copy(update={"wheel_scale_sigma": max(released, config.wheel_scale_sigma)})
        fix = ("the wheels' scale is wrong: check wheel_radius_left, wheel_radius_right and ticks_per_revolution in "
               "wheel0/sensor.yaml" if streams.wheel is not None else "the odometry's speeds (odom0/data.csv vx) are wrong")
        done = f"this run multiplies the {wheel_word} distances by {rho:.3f} and lets the camera set the scale"
    figures["wrong"] = wrong
    sentence = (f"cam0/sensor.yaml and {wheel_file}: the camera's distances are {rho:.3f} times the {wheel_word} over "
                f"{distance:.2f} m of straight driving, {log_rho / s_v:.0f} times the camera's stated scale uncertainty "
                f"({s_v:.2g}) and {log_rho / s_w:.0f} times the {wheel_word} ({s_w:.2g}); {said}: {fix}; {done}")
    return Finding("scale", wrong, CORRECTED, sentence, figures), streams, config


def _without_translation(streams):
    """The camera's increments with their translation left out (standard deviation ``LEFT_OUT`` each way, no
    correlation with the heading) and their heading as measured; its height priors dropped."""

    def heading_only(v):
        if not v.ok:
            return v
        cov = np.asarray(v.covariance, dtype=np.float64)
        out = np.diag([LEFT_OUT**2, LEFT_OUT**2, cov[2, 2]])
        frame = None
        if v.frame_covariance is not None:
            frame = np.zeros((3, 3))
            frame[2, 2] = np.asarray(v.frame_covariance, dtype=np.float64)[2, 2]
        return dataclasses.replace(v, covariance=out, frame_covariance=frame)

    return streams.replace(visual=[heading_only(v) for v in streams.visual], camera_height_sigma=None,
                               range_height_sigma=None)


def _scaled_wheels(streams, factor: float):
    """The wheels' radii (or the twist's velocity) times ``factor``, their radius prior dropped."""
    if streams.wheel is not None:
        cfg = dataclasses.replace(streams.wheel.config, wheel_radius_left=streams.wheel.config.wheel_radius_left * factor,
                                  wheel_radius_right=streams.wheel.config.wheel_radius_right * factor, radius_sigma=None)
        return streams.replace(wheel=dataclasses.replace(streams.wheel, config=cfg))
    odom = streams.odom
    return streams.replace(odom=dataclasses.replace(odom, vx=np.asarray(odom.vx) * factor,
                                                                 vy=np.asarray(odom.vy) * factor))
