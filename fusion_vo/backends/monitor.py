"""Per-component consistency of the heading sources and the speeds: a stream that lies is caught before fusion.

The heading sources measure how much the robot turned over a window of ``W`` seconds
(``FusionConfig.monitor_window``). Each is declared by its sensor's module as a
:class:`~fusion_vo.sensors.registry.HeadingSource` (its change per node interval, its variance, what a window
adds, how it is dropped, its role: suspect, absolute, biased), and a sensor registered outside the library is
judged the same way. The built-in ones:

* the wheels' yaw component ``θ_w = (d_r - d_l) / b`` (a twist's ``ω`` integrated; :mod:`~fusion_vo.sensors.wheel`);
* the gyro's integrated angle ``Θ`` minus its bias ``b̂ W`` (``b̂`` the median of the gyro's rate where
  the wheels stand still, else its rate against the AHRS heading's, the camera's or the wheels' from
  :func:`reference_bias`, else 0; :func:`bias_of`, :mod:`~fusion_vo.sensors.imu`);
* the AHRS heading's change ``ψ(t_1) - ψ(t_0)`` (:mod:`~fusion_vo.sensors.imu`);
* the camera's summed heading increments (:mod:`~fusion_vo.sensors.visual`).

Each has a variance over the window from its noise model (the wheels' includes the relative error of
the track width, ``sqrt(yaw_scale² + base_sigma²)`` of the turn, so a skid-steered base that turns
1.5 times what its twist says is *not* a liar; the gyro's includes the bias' uncertainty
``monitor_bias_sigma · W``; the AHRS's its white noise and its offset walk). Windows of ``W``, ``5 W`` and
``15 W`` are checked, so a fast lie (a wrong yaw rate) and a slow drift (an AHRS heading straying by a
degree a second, a gyro bias step) are both seen. In each window a source's normalised innovation
squared against the inverse-variance mean of the others, ``NIS = (θ_s - θ̄)² / (σ_s² + σ̄²)``, is
tested against the chi-square quantile of ``monitor_probability`` (1 degree of freedom); of the
sources above it, the one whose removal leaves the others most consistent (their chi-square about
their own mean within its quantile) is dropped in that window, so one liar cannot condemn two honest
streams. With two sources only, the suspect one (the wheels' yaw) is the one dropped when they disagree (a
twist's yaw rate from a nominal track width is the usual liar; a gyro is not), and nothing else can be
judged. An absolute heading (the AHRS, a compass) is dropped per span too, but after a span in which it
disagreed it is trusted again only where its absolute heading still agrees with the heading carried
from where it was last trusted (:func:`_readmit_absolute`): an offset it picked up meanwhile does not
show in its heading changes.

The check runs on a whole recording (:func:`fusion_vo.backends.batch.fuse`); streaming use
(:class:`~fusion_vo.backends.streaming.StreamingFusion`) runs it causally over a sliding window
(:mod:`fusion_vo.backends.live_monitor`), the speed check below included.

Speeds
------
:func:`check_speed_sources` does the same for the distance travelled over each window: the wheels'
``(d_l + d_r) / 2`` against the camera's summed forward increments (each declared by its sensor as a
:class:`~fusion_vo.sensors.registry.DistanceSource`; the suspect one, the wheels', against the first other). Their ratio ``ρ`` is a
calibration the backends estimate (camera height against wheel radius), not a lie, so the check
uses the median ``ρ₀`` of the ratios over the shortest windows and tests
``NIS = (D_w - ρ₀ D_c)² / (σ_w² + ρ₀² σ_c² + (monitor_scale_sigma · D_w)²)`` in each window
(``monitor_scale_sigma``: how much the ratio may wander, tyres and ground; default 2 %). A window
above the quantile is a disagreement: a wheel that slips or is scaled wrong, or a camera scale gone
wrong (a frontend's bad scale, a height the configuration no longer describes). With the camera
and the wheels as the only speed sources nothing tells which of the two is wrong; the wheels' speed
is the one dropped there (slip and tyre changes are the common cause; the camera keeps the
translation), and the note gives the ratio in the span beside ``ρ₀`` so the reader can tell which
stream moved. A scale change lasting more than half the recording becomes ``ρ₀`` itself, and the rest
of the recording is then reported as the disagreement.

Only the inconsistent *component* is dropped, for as long as it disagrees (it comes back after a
window whose NIS is below the 90 % quantile, 2.7, so a liar is not trusted again because one window
happened to be quiet; a component found inconsistent over more than ``monitor_whole_fraction`` of
the time it was checked is dropped for the whole recording, since its quiet windows are no evidence
that it is right there): the wheels' speed
stays in use while their yaw rate is dropped (``WheelGrid.yaw_ok``), a dropped gyro or AHRS
span clears ``gyro_ok`` / ``ahrs_ok`` there; in a span where the camera's heading is dropped, each
visual increment is tested on its own against the other sources and removed if it fails (an increment
is one estimate; its translation is expressed in its wrong heading). Each drop becomes an
:class:`Episode` (sensor, component, start, end, largest NIS), a plain note and an entry of
``summary.json``; it never makes the run fail.
"""

from __future__ import annotations

import functools
import logging
from dataclasses import dataclass
from typing import Any

import numpy as np

from fusion_vo.backends.config import FusionConfig
from fusion_vo.sensors import registry

logger = logging.getLogger(__name__)


@dataclass
class Episode:
    """A span in which one component of one stream contradicted the others and was dropped."""

    sensor: str
    component: str
    start: float
    end: float
    max_nis: float
    against: str
    detail: str = ""

    def as_dict(self) -> dict:
        out = dict(self.__dict__)
        if not out["detail"]:
            del out["detail"]
        return out

    def note(self, t0: float, t1: float | None = None) -> str:
        """The episode in plain words; ``t0`` and ``t1`` are the first and last node of the recording.

        A span that covers the whole recording (``t1`` given) is said to be one: the component was not used
        at all. Otherwise the span is given on the recording clock and in seconds from ``t0``."""
        what = f"{self.sensor} {self.component} inconsistent with {self.against}"
        nis = f"NIS up to {self.max_nis:.0f}{self.detail}"
        if t1 is not None and self.start <= t0 + 1e-6 and self.end >= t1 - 1e-6:
            return (f"{what} over the whole recording (t={self.start:.2f} to {self.end:.2f}, "
                    f"{self.end - self.start:.1f} s), {nis}: not used at all")
        return (f"{what} from t={self.start:.2f} ({self.start - t0:.1f} s in) to t={self.end:.2f} "
                f"({self.end - t0:.1f} s in), {nis}: not used in these {self.end - self.start:.1f} s")


@functools.lru_cache(maxsize=64)
def _chi2_ppf(probability: float, dof: int) -> float:
    """Chi-square quantile (cached: the check asks for the same few many times)."""
    from scipy.stats import chi2  # on first use: a camera-only run does not load scipy.stats

    return float(chi2.ppf(probability, dof))


def windows(T: np.ndarray, length: float) -> list[tuple[int, int]]:
    """Consecutive runs of node intervals ``[a, b)`` about ``length`` seconds long."""
    K = len(T) - 1
    out = []
    a = 0
    while a < K:
        b = int(np.searchsorted(T, T[a] + length - 1e-9))
        b = min(max(b, a + 1), K)
        out.append((a, b))
        a = b
    if len(out) > 1 and T[out[-1][1]] - T[out[-1][0]] < 0.5 * length:
        out[-2] = (out[-2][0], out[-1][1])
        out.pop()
    return out


def bias_of(iv, changes: dict, key: str, still: np.ndarray | None, chunk: float) -> float:
    """The bias [rad/s] of the biased source ``key`` for the check: its median rate at rest (``still``), else its
    rate against the reference sources' heading changes in their order (the AHRS's, the camera's, the wheels'; the
    first with ten intervals beside it; :func:`reference_bias`, chunks of ``chunk`` seconds), else 0 (a constant bias
    is the backends' to estimate, not a lie). ``changes``: key -> ``(sensor, source, (ok, angle, var))``."""
    ok_b, angle_b = changes[key][2][0], changes[key][2][1]
    dt = iv.dt
    rate = np.where(ok_b, angle_b / np.maximum(dt, 1e-9), np.nan)
    if still is not None and np.count_nonzero(still & ok_b) >= 10:
        return float(np.median(rate[still & ok_b]))
    refs = sorted((h.reference, k) for k, (_, h, _) in changes.items() if k != key and h.reference is not None)
    for _, k in refs:
        ok = changes[k][2][0] & ok_b
        if np.count_nonzero(ok) >= 10:
            return reference_bias(iv.t, angle_b - changes[k][2][1], ok, chunk)
    return 0.0


def reference_bias(T: np.ndarray, diff: np.ndarray, ok: np.ndarray, chunk: float) -> float:
    """A gyro's bias [rad/s] from its angle less a reference's heading change per node interval, ``diff``
    (used where ``ok``): the least-squares slope of the summed ``diff`` against the time summed where
    ``ok``, in chunks of about ``chunk`` seconds, and the median of the chunks' slopes.

    The summed difference is the bias times the time plus the reference's heading error, which an AHRS
    has white (its heading changes telescope) and a camera or wheels as a slow walk; the slope of a
    chunk averages it over the chunk. A median of per-interval rate differences would not: an AHRS's
    heading noise ``σ_ψ`` over an interval ``dt`` is a rate error of ``√2 σ_ψ / dt`` (0.57 rad/s for
    0.02 rad at 20 Hz), and the median of 2400 of them has a standard error of about 0.015 rad/s, ten
    times ``monitor_bias_sigma`` (``docs/decisions/0023-monitor-removes-the-gyro-bias-first.md``). The median over
    the chunks keeps a reference that lies in a minority of them (a drifting AHRS) from moving the bias.
    """
    dt = np.diff(T)
    slopes = []
    for a, b in windows(T, chunk):
        sel = ok[a:b]
        if np.count_nonzero(sel) < max(3, 0.5 * (b - a)):
            continue
        x = np.cumsum(np.where(sel, dt[a:b], 0.0))[sel]
        y = np.cumsum(np.where(sel, diff[a:b], 0.0))[sel]
        x = x - x.mean()
        if not np.dot(x, x) > 0:
            continue
        slopes.append(float(np.dot(x, y - y.mean()) / np.dot(x, x)))
    if slopes:
        return float(np.median(slopes))
    return float(np.sum(diff[ok]) / np.sum(dt[ok]))


def heading_changes(iv, config: FusionConfig) -> dict:
    """Every registered heading source's raw changes on the grid ``iv`` (:attr:`HeadingSource.change
    <fusion_vo.sensors.registry.HeadingSource.change>`), in their ``rank`` order: key -> ``(sensor name, source,
    (ok, angle, var))``; the sources without data left out."""
    out = {}
    for sensor, h in sorted(registry.heading_sources(), key=lambda pair: pair[1].rank):
        rows = h.change(iv, config)
        if rows is not None:
            out[h.key] = (sensor.name, h, rows)
    return out


def check_heading_sources(iv, config: FusionConfig, gyro_bias: float | None = None) -> list[Episode]:
    """Find and drop the inconsistent heading components of ``iv`` (in place); returns the episodes.

    The components are the registered heading sources (:class:`~fusion_vo.sensors.registry.HeadingSource`: the
    gyro, the wheels' yaw, the AHRS and the camera's heading). ``gyro_bias`` [rad/s] replaces the bias the check
    estimates for a biased source (:func:`bias_of`).
    """
    cfg = config
    if not cfg.monitor or iv.n_steps < 2:
        return []
    T, dt = iv.t, iv.dt
    threshold = _chi2_ppf(cfg.monitor_probability, 1)
    release = _chi2_ppf(0.9, 1)
    changes = heading_changes(iv, cfg)
    still = next((h.at_rest(iv, cfg) for _, h, _ in changes.values() if h.at_rest is not None), None)
    sources: dict[str, list] = {}  # key -> [ok, angle, var] per interval, as judged
    for key, (_, h, (ok, angle, var)) in changes.items():
        if h.biased:
            bias = (bias_of(iv, changes, key, still, _BIAS_CHUNK * cfg.monitor_window) if gyro_bias is None
                    else float(gyro_bias))
            angle = angle - bias * dt
        sources[key] = [ok, angle, var]
    found = {key: (ok, angle) for key, (ok, angle, _) in sources.items()}
    for key, (_, h, _) in changes.items():
        if h.variance is not None:
            sources[key][2] = h.variance(iv, cfg, sources[key][1], found)
    if len(sources) < 2:
        return []
    extra = {key: h.window(iv, cfg) for key, (_, h, _) in changes.items() if h.window is not None}
    suspects = {key for key, (_, h, _) in changes.items() if h.suspect}
    names = list(sources)
    bad = {s: np.zeros(len(dt), bool) for s in names}
    peak = {s: np.zeros(len(dt)) for s in names}
    against = {s: np.full(len(dt), "", dtype=object) for s in names}
    for scale in _SCALES:
        dropped: set[str] = set()  # hysteresis state at this scale
        for a, b in windows(T, cfg.monitor_window * scale):
            theta, var = _window_sums(sources, a, b, float(T[b] - T[a]), extra)
            liar, liar_nis, liar_others = _find_liar(theta, var, threshold, cfg.monitor_probability, suspects)
            for s in names:
                if s == liar:
                    dropped.add(s)
                    nis, others = liar_nis, liar_others
                elif s in dropped:
                    # hysteresis: a dropped component comes back only once it agrees well again
                    n = _window_nis(s, theta, var)
                    if n is None or n <= release:
                        dropped.discard(s)
                        continue
                    nis, others = n, [o for o in theta if o != s]
                else:
                    continue
                bad[s][a:b] = True
                peak[s][a:b] = np.maximum(peak[s][a:b], nis)
                against[s][a:b] = ", ".join(others)
    for key, (_, h, _) in changes.items():
        if h.absolute and bad[key].any():
            _readmit_absolute(iv, key, h, bad, peak[key], against[key], sources, changes, extra[key], cfg, release)
    episodes: list[Episode] = []
    for s in names:
        sensor, h = changes[s][0], changes[s][1]
        checked = np.count_nonzero(sources[s][0])
        # an absolute heading's quiet runs after a drop are judged on its heading (_readmit_absolute) instead
        fraction = 1.0 if h.absolute else cfg.monitor_whole_fraction
        if checked and np.count_nonzero(bad[s]) > fraction * checked:
            # a stream that contradicts the others most of the time is not trusted in its quiet windows either
            who = next(x for x in against[s] if x)
            bad[s][:] = True
            episodes.append(Episode(sensor, h.component, float(T[0]), float(T[-1]), float(peak[s].max()), who))
            continue
        k = 0
        while k < len(dt):
            if not bad[s][k]:
                k += 1
                continue
            j = k
            while j < len(dt) and bad[s][j]:
                j += 1
            episodes.append(Episode(sensor, h.component, float(T[k]), float(T[j]), float(peak[s][k:j].max()),
                                    str(against[s][k])))
            k = j
    episodes.sort(key=lambda e: e.start)
    for s in names:
        def agrees(a: int, b: int, s=s) -> bool:  # one stretch of the source against the others
            theta, var = _window_sums(sources, a, b, float(T[b] - T[a]), extra)
            nis = _window_nis(s, theta, var)
            return nis is None or nis <= threshold

        changes[s][1].drop(iv, bad[s], agrees)
    for ep in episodes:
        logger.info("monitor: %s", ep.note(T[0]))
    return episodes


def _readmit_absolute(iv, key: str, source, bad: dict, peak: np.ndarray, against: np.ndarray, sources: dict,
                      changes: dict, window, cfg: FusionConfig, release: float) -> None:
    """After a span in which the absolute heading ``key`` (the AHRS) was dropped, keep it again only where its
    *absolute* heading still agrees (in place on ``bad[key]`` and its ``peak`` and ``against`` per interval).

    The windowed check compares heading *changes*: an AHRS whose offset moved during a dropped span
    (a magnetic disturbance, a heading-dependent error) agrees again in changes afterwards while its
    heading stays wrong by the offset it picked up. Each later run of intervals the windowed check
    kept is compared, through its mean offset against the relative heading (the relative sources' by rank where
    usable and not dropped: the bias-corrected gyro, else the wheels', else the camera's, summed since it was
    last trusted; a dropout of the absolute heading itself does not matter),
    with the offset at the end of the last trusted run (at first, its first sample, which sets
    the heading offset); the variance is its ``window`` over the gap (the AHRS's noise and offset
    walk) plus the relative heading's noise and ``monitor_bias_sigma`` over the gap. A run is kept only
    below the 90 % quantile (``release``, as a dropped component's comeback elsewhere), and becomes
    the new anchor; otherwise it is dropped too (an AHRS that has departed from the true heading can
    agree again in its heading *changes* while its heading stays off).
    """
    heading_ok, heading = source.heading(iv)
    T = iv.t
    bad_a = bad[key]
    ok_a = sources[key][0]
    K = len(bad_a)
    ref = np.zeros(K)
    ref_var = np.full(K, np.inf)
    relative = [k for k in sources if not changes[k][1].absolute]  # by rank
    for name in reversed(relative):  # the better ranked take precedence; a span dropped from one is not used
        ok, ang, var = sources[name]
        use = ok & ~bad[name]
        ref = np.where(use, ang, ref)
        ref_var = np.where(use, var, ref_var)
    # a node's offset: the absolute heading (the recording's heading offset removed) minus the
    # relative heading summed from the start; a dropout of the absolute heading does not break it
    rel = np.concatenate([[0.0], np.cumsum(ref)])
    rel_var = np.concatenate([[0.0], np.cumsum(np.where(np.isfinite(ref_var), ref_var, 0.0))])
    offset = heading - rel
    runs = _runs(ok_a & ~bad_a)
    if not runs:
        return
    # the heading offset is set from its first samples: its offset is known there
    start = int(np.argmax(heading_ok))
    anchor = (start, start)
    for a, b in runs:
        if a == start:
            anchor = (a, b)
            continue
        if not np.isfinite(ref_var[anchor[1]:a]).all():
            # no relative heading over part of the gap: the offset cannot be carried over
            bad_a[a:b] = True
            continue
        gap = float(T[a] - T[anchor[1]])
        diff = float(np.mean(np.angle(np.exp(1j * (offset[a:b + 1] - offset[anchor[1]])))))
        var = window(gap, {}) + float(rel_var[a] - rel_var[anchor[1]]) + (cfg.monitor_bias_sigma * gap) ** 2
        nis = diff**2 / var
        if nis <= release:
            anchor = (a, b)
            continue
        bad_a[a:b] = True
        peak[a:b] = np.maximum(peak[a:b], nis)
        against[a:b] = ", ".join(relative) + " (absolute heading)"


def _window_sums(sources: dict, a: int, b: int, span: float, extra: dict):
    """Each source's heading change over intervals ``[a, b)`` and its variance (sources that cover it), with what
    the sources' ``window`` adds over ``span`` seconds (``extra``)."""
    theta, var = {}, {}
    for s, (ok, ang, v) in sources.items():
        if ok[a:b].all():
            theta[s] = float(ang[a:b].sum())
            var[s] = float(v[a:b].sum())
    for s, add in extra.items():
        if s in theta:
            var[s] += add(span, theta)
    return theta, var


def _find_liar(theta: dict, var: dict, threshold: float, probability: float, suspects=frozenset()):
    """The one source to drop in a window, its NIS and the sources it contradicts, or ``(None, 0, [])``.

    With two sources, only a suspect (the wheels' yaw) is ever dropped. With more, each source whose NIS against
    the others' mean exceeds ``threshold`` is a candidate; the one whose removal leaves the others most
    consistent (smallest chi-square about their mean, which must itself pass) is dropped.
    """
    present = list(theta)
    if len(present) == 2:
        suspect = next((s for s in present if s in suspects), None)
        if suspect is None:
            return None, 0.0, []
        other = [s for s in present if s != suspect][0]
        nis = (theta[suspect] - theta[other]) ** 2 / (var[suspect] + var[other])
        return (suspect, nis, [other]) if nis > threshold else (None, 0.0, [])
    if len(present) < 2:
        return None, 0.0, []
    best = (None, 0.0, [], np.inf)
    for s in present:
        nis = _window_nis(s, theta, var)
        if nis is None or nis <= threshold:
            continue
        others = [o for o in present if o != s]
        w = [1.0 / max(var[o], 1e-12) for o in others]
        w_sum = sum(w)
        mean = sum(wi * theta[o] for wi, o in zip(w, others)) / w_sum
        rest = sum(wi * (theta[o] - mean) ** 2 for wi, o in zip(w, others))
        if rest <= _chi2_ppf(probability, len(others) - 1) and rest < best[3]:
            best = (s, nis, others, rest)
    return best[:3]


def _window_nis(s: str, theta: dict, var: dict) -> float | None:
    """NIS of source ``s`` against the inverse-variance mean of the others in one window (None: absent)."""
    if s not in theta or len(theta) < 2:
        return None
    w_sum = weighted = 0.0
    for o, value in theta.items():  # plain floats: a handful of sources per window
        if o != s:
            w = 1.0 / max(var[o], 1e-12)
            w_sum += w
            weighted += w * value
    return (theta[s] - weighted / w_sum) ** 2 / (var[s] + 1.0 / w_sum)


@dataclass
class SpeedPair:
    """The two distance sources the speed check compares on a grid: the suspect (the wheels') and the first other
    one (the camera's), with their rows per node interval (:attr:`DistanceSource.change
    <fusion_vo.sensors.registry.DistanceSource.change>`): distance ``d`` [m] and variance ``v`` [m²], ``both`` where
    the two measure it."""

    sensor: str
    source: Any
    reference: Any
    both: np.ndarray
    d_s: np.ndarray
    v_s: np.ndarray
    d_r: np.ndarray
    v_r: np.ndarray

    @property
    def key(self) -> str:
        """The name of the suspect's component in the monitor's decisions (``"wheel speed"``)."""
        return f"{self.source.key} {self.source.component}"

    def sums(self, a: int, b: int):
        """``(D_s, σ_s², D_r, σ_r²)`` over the intervals ``[a, b)``, or None unless both measure all of them."""
        if not self.both[a:b].all():
            return None
        return self.d_s[a:b].sum(), self.v_s[a:b].sum(), self.d_r[a:b].sum(), self.v_r[a:b].sum()

    def ratio(self, a: int, b: int) -> float | None:
        """``D_s / D_r`` over ``[a, b)`` when the reference moved clearly there (ten of its sigmas), else None."""
        w = self.sums(a, b)
        if w is None or not abs(w[2]) > 10 * np.sqrt(w[3]) + 1e-6:
            return None
        return float(w[0] / w[2])


def speed_pair(iv, config: FusionConfig) -> SpeedPair | None:
    """The registered distance sources of the grid ``iv`` the speed check compares, or None without a suspect and
    another source with data. A source whose rows do not cover the grid's intervals is left out (a sensor that keeps
    its measurements outside a registered container, which the live monitor's window cannot assemble)."""
    found = [(sensor.name, d, rows) for sensor, d in sorted(registry.distance_sources(), key=lambda p: p[1].rank)
             if (rows := d.change(iv, config)) is not None and len(rows[0]) == iv.n_steps]
    suspect = next((f for f in found if f[1].suspect), None)
    other = next((f for f in found if not f[1].suspect), None)
    if suspect is None or other is None:
        return None
    (sensor, source, (s_ok, d_s, v_s)), (_, reference, (r_ok, d_r, v_r)) = suspect, other
    return SpeedPair(sensor, source, reference, s_ok & r_ok, d_s, v_s, d_r, v_r)


def speed_disagreement(pair: SpeedPair, T: np.ndarray, rho: float, config: FusionConfig) -> tuple[np.ndarray, np.ndarray]:
    """Where the suspect's distance disagrees with ``rho`` times the reference's (module docstring): per node interval
    of the grid ``T``, whether it does and the largest NIS of a window that found it."""
    cfg = config
    K = len(T) - 1
    threshold = _chi2_ppf(cfg.monitor_probability, 1)
    release = _chi2_ppf(0.9, 1)

    def window_nis(a: int, b: int) -> float | None:
        w = pair.sums(a, b)
        if w is None:
            return None
        return (w[0] - rho * w[2]) ** 2 / (w[1] + rho**2 * w[3] + (cfg.monitor_scale_sigma * w[0]) ** 2)

    base = windows(T, cfg.monitor_window)
    bad = np.zeros(K, bool)
    peak = np.zeros(K)
    for scale in _SCALES:
        dropped = False
        for a, b in windows(T, cfg.monitor_window * scale):
            nis = window_nis(a, b)
            if nis is None:
                continue
            if nis > threshold or (dropped and nis > release):
                dropped = True
                # a long window is narrowed to its short windows that disagree too (all of it for a slow drift)
                parts = [(c, d) for c, d in base if a <= c and d <= b and (window_nis(c, d) or 0.0) > threshold]
                for c, d in parts or [(a, b)]:
                    bad[c:d] = True
                    peak[c:d] = np.maximum(peak[c:d], nis)
            else:
                dropped = False
    return bad, peak


def check_speed_sources(iv, config: FusionConfig) -> list[Episode]:
    """Find the spans where a suspect distance source (the wheels') and the first other one (the camera's) disagree;
    drop the suspect's distance there (:attr:`DistanceSource.drop <fusion_vo.sensors.registry.DistanceSource.drop>`,
    in place) and return the episodes (see the module docstring)."""
    cfg = config
    if not cfg.monitor or iv.n_steps < 2:
        return []
    pair = speed_pair(iv, cfg)
    if pair is None:
        return []
    T = iv.t
    # the ratio of the recording: median over the shortest windows in which the reference moved clearly
    ratios = [r for a, b in windows(T, cfg.monitor_window) if (r := pair.ratio(a, b)) is not None]
    if not ratios:
        return []
    rho = float(np.median(ratios))
    bad, peak = speed_disagreement(pair, T, rho, cfg)
    source, reference = pair.source, pair.reference
    episodes = []
    for a, b in _runs(bad):
        sel = pair.both[a:b]
        d_s, d_r = pair.d_s[a:b][sel].sum(), pair.d_r[a:b][sel].sum()
        span_rho = float(d_s / d_r) if abs(d_r) > 0 else float("nan")
        episodes.append(Episode(pair.sensor, source.component, float(T[a]), float(T[b]), float(peak[a:b].max()),
                                reference.key, f" ({source.key}/{reference.key} distance ratio {span_rho:.3f} there, "
                                f"{rho:.3f} over the recording; with no third speed source either may be the wrong one)"))
    source.drop(iv, bad)
    for ep in episodes:
        logger.info("monitor: %s", ep.note(T[0]))
    return episodes


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``[a, b)`` index runs where ``mask`` is True."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist()))


_BIAS_CHUNK = 5  # the gyro bias' chunks (reference_bias) in units of monitor_window
_SCALES = (1, 5, 15)  # window lengths in units of monitor_window: fast lies and slow drifts

__all__ = ["Episode", "SpeedPair", "check_heading_sources", "check_speed_sources", "speed_disagreement",
           "speed_pair"]
