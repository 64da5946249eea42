"""Absolute readings of the pose (GPS fixes): the one place every backend applies them.

An absolute reading (``Readings.absolute``, :class:`~fusion_vo.sensors.readings.Absolute`) is a node reading of
the ``pose`` argument of its model, ``z = h(x) + n`` (the antenna's position: ``h(x) = p + R(ψ) l``,
:class:`~fusion_vo.sensors.gps.AntennaModel`). It is applied on its own, after the node's other readings:

* gate: with the innovation ``r = z - h(x̂)`` and ``S = H P Hᵀ + Σ`` (``P`` the predicted pose's covariance; ``S = Σ``
  when there is none), a reading with ``d² = rᵀ S⁻¹ r`` above ``noise.gate_chi2`` is rejected
  (:meth:`~fusion_vo.sensors.gps.GpsModel.check`, which also floors ``Σ`` at ``noise.min_sigma``);
* robust weight: an accepted reading's information is scaled by ``w(d)`` of ``noise.kernel`` (Huber ``k/d`` beyond
  ``k``, Cauchy ``1 / (1 + (d/k)²)``; :mod:`fusion_vo.robust`): the EKF divides ``Σ`` by it, the graph wraps the
  factor in GTSAM's ``mEstimator`` of the same kernel;
* re-acquisition: after ``reacquire`` seconds in which every reading was rejected one is applied anyway (the EKF
  first widens its position covariance by the squared innovation), so an estimate that drifted while the readings
  were wrong, or absent, comes back;
* an outage of :data:`OUTAGE_NOTE_S` or more is reported with the drift the first reading after it measures.

:class:`EkfFixes` does this for a batch EKF run, :class:`GraphFixes` for the factor graph (gated against its node's
predicted pose and, with iSAM2, the online marginal covariance of the previous node), the functions
:func:`ekf_update`, :func:`ekf_reacquire`, :func:`outage_note` and :class:`Reacquire` for the streaming EKF, and
:func:`graph_gate` for the streaming iSAM2 (:class:`~fusion_vo.backends.online_graph.OnlineGraph`). The outage
notes are the EKF's (batch and streaming).
"""

from __future__ import annotations

import numpy as np

from fusion_vo.measurements import SensorCount
from fusion_vo.sensors.gps import GpsModel
from fusion_vo.sensors.readings import Readings

#: a gap between absolute readings at least this long [s] is reported with the drift the next one measures
OUTAGE_NOTE_S = 2.0


def ekf_update(ekf, model: GpsModel, z, covariance, t: float | None = None, sensor: str = "gps") -> bool:
    """Apply one reading to the EKF through ``model`` (gate, robust weight); returns whether it was accepted."""
    chk = model.check(ekf.x[:3], z, covariance, ekf.P[:3, :3], t)
    ekf.record(sensor, chk.d2, 2, "rejected" if not chk.accepted else "down-weighted" if chk.weight < 1.0 else "used")
    if not chk.accepted:
        return False
    ekf.update_pose(chk.residual, chk.H, chk.R)
    return True


def ekf_reacquire(ekf, model: GpsModel, z, covariance, t: float | None = None, sensor: str = "gps") -> bool:
    """Apply a reading that failed the gate after widening the EKF's position covariance by the squared
    innovation; the rejection just counted becomes a use."""
    model.n_rejected -= 1
    if model.rejected_t:
        model.rejected_t.pop()
    r = np.asarray(z, dtype=np.float64)[:2] - model.predict(ekf.x[:3])
    ekf.P[:2, :2] += np.eye(2) * float(r @ r)
    return ekf_update(ekf, model, z, covariance, t, sensor)


class Reacquire:
    """Readings through the gate, and after ``after`` seconds of rejections one applied anyway; ``times`` holds when
    that happened."""

    def __init__(self, after: float):
        self.after = after
        self.last_ok: float | None = None
        self.times: list[float] = []

    def apply(self, ekf, model: GpsModel, z, covariance, t: float, sensor: str = "gps") -> bool:
        """Apply a reading at ``t`` to the EKF (:func:`ekf_update`), re-acquiring when due (:meth:`due`)."""
        accepted = ekf_update(ekf, model, z, covariance, t, sensor)
        if not self.due(t, accepted):
            return accepted
        return ekf_reacquire(ekf, model, z, covariance, t, sensor)

    def due(self, t: float, accepted: bool) -> bool:
        """Whether a reading at ``t``, ``accepted`` or not by the gate, is to be applied anyway: a rejected one
        ``after`` seconds or more after the last reading applied (or the first reading, when none was), so with
        ``after`` 0 every reading is applied."""
        if accepted:
            self.last_ok = t
            return False
        if self.last_ok is None:
            self.last_ok = t
        if t - self.last_ok < self.after:
            return False
        self.times.append(t)
        self.last_ok = t
        return True


def outage_note(ekf, model: GpsModel, z, covariance, t_last: float, t: float, t0: float, sensor: str = "gps") -> str:
    """The note of the first reading ``z`` (``covariance``) at ``t`` after none since ``t_last`` (``t0``: the first
    node), before it is applied: how far the EKF's estimate drifted meanwhile (its antenna from the reading), beside
    the position sigma the filter states and the reading's own (floored as the gate floors it; one reading's
    distance holds its own error too)."""
    drift = float(np.linalg.norm(np.asarray(z, dtype=np.float64)[:2] - model.predict(ekf.x[:3])))
    sigma = float(np.sqrt(np.trace(ekf.P[:2, :2])))
    own = float(np.sqrt(np.trace(model.covariance(covariance))))
    return (f"ekf: {sensor} outage from {t_last - t0:.2f} to {t - t0:.2f} s in: drift {drift:.3f} m at its end "
            f"(position sigma {sigma:.3f} m; the fix's own {own:.3f} m)")


def reacquired_text(times: list[float], t0: float) -> str:
    """The part of a run's GPS note that says when fixes were applied anyway (:class:`Reacquire`), or ``""``."""
    if not times:
        return ""
    return (f"; {len(times)} times a fix was applied anyway after rejections for gps_reacquire seconds "
            f"(the estimate re-acquired the fixes; first at {times[0] - t0:.2f} s in)")


def note(backend: str, r: Readings, model: GpsModel, t0: float, reacquired: list | None = None) -> str:
    """``"<backend>: gps N fixes used, M rejected by the gate (at ...)"`` plus the readings skipped on reading."""
    text = f"{backend}: {r.sensor} {model.n_used} fixes used, {model.n_rejected} rejected by the gate"
    if model.rejected_t:
        when = sorted(model.rejected_t)
        text += f" (t={when[0]:.2f} to {when[-1]:.2f}, {when[0] - t0:.2f} to {when[-1] - t0:.2f} s in)"
    text += reacquired_text(reacquired or [], t0)
    skipped = sum(r.absolute.skipped.values())
    if skipped:
        text += f"; {skipped} skipped on reading ({', '.join(f'{n} {k}' for k, n in r.absolute.skipped.items() if n)})"
    return text


def checker(r: Readings) -> GpsModel:
    """The gate and robust weight of ``r``'s absolute readings (lever arm and policy)."""
    return GpsModel(np.asarray(r.params["lever_arm"], dtype=np.float64), r.absolute.noise)


class EkfFixes:
    """One sensor's absolute readings, applied by a batch EKF run at their nodes after each step's update.

    Parameters
    ----------
    r : Readings
        The absolute readings (at grid nodes).
    t : ndarray (K+1,)
        The node times.
    """

    def __init__(self, r: Readings, t: np.ndarray):
        self.r = r
        self.t = t
        self.at = {int(n): j for j, n in enumerate(r.i0)}
        self.model = checker(r)
        self.reacquire = Reacquire(r.absolute.reacquire)
        self.notes: list[str] = []
        self.last: float | None = None

    def node(self, ekf, k: int) -> None:
        j = self.at.get(k)
        if j is None:
            return
        t, z, cov = float(self.t[k]), self.r.z[j], self.r.cov[j]
        if k > 0 and self.last is not None and t - self.last >= OUTAGE_NOTE_S:
            # the first reading after an outage measures how far the estimate drifted without them
            self.notes.append(outage_note(ekf, self.model, z, cov, self.last, t, float(self.t[0]), self.r.sensor))
        self.last = t
        self.reacquire.apply(ekf, self.model, z, cov, t, self.r.sensor)

    def finish(self, ekf, result) -> None:
        ekf.counts[self.r.sensor] = SensorCount(used=self.model.n_used, gated=self.model.n_rejected)
        result.notes.append(note("ekf", self.r, self.model, float(self.t[0]), self.reacquire.times))
        result.notes.extend(self.notes)


def graph_gate(model: GpsModel, reacquire: Reacquire, pose, z, covariance, pose_cov, t: float) -> str | None:
    """Whether the factor graph adds a reading at ``t`` against its predicted ``pose`` (covariance ``pose_cov``, or
    None): ``"used"`` when it passes ``model``'s gate, ``"reacquired"`` when it fails it after ``reacquire.after``
    seconds of rejections (then counted as a use, not a rejection), else None."""
    chk = model.check(pose, z, covariance, pose_cov, t)
    if not reacquire.due(t, chk.accepted):
        return "used" if chk.accepted else None
    model.n_rejected -= 1  # applied after all: a use, not a rejection
    model.rejected_t.pop()
    model.n_used += 1
    return "reacquired"


class GraphFixes:
    """One sensor's absolute readings in the factor graph: each gated against its node's predicted pose (and the
    online marginal covariance of the previous node when iSAM2 runs) and added inside the readings' own robust
    kernel, as a factor of their model (:func:`fusion_vo.backends.graph_adapter.absolute_factor`)."""

    def __init__(self, builder, r: Readings):
        self.builder = builder
        self.r = r
        self.at = {int(g): j for j, g in enumerate(r.i0)}
        self.model = checker(r)
        self.reacquire = Reacquire(r.absolute.reacquire)

    def add(self, nf, n: int, pose_cov, factor) -> None:
        """Gate the reading at node ``n`` against its predicted pose; add ``factor(key, z, covariance)`` when
        accepted."""
        builder, model, r = self.builder, self.model, self.r
        g = int(builder.grid[n])
        j = self.at.get(g)
        if j is None:
            return
        key = builder.key(n)
        guess = nf.values[key]
        t = float(builder.iv.t[g])
        if not graph_gate(model, self.reacquire, np.array([guess.x(), guess.y(), guess.theta()]), r.z[j], r.cov[j],
                          pose_cov, t):
            builder.counts.setdefault(r.sensor, SensorCount()).gated += 1
            return
        nf.factors.append(factor(key, r.z[j], model.covariance(r.cov[j])))
        nf.sensors.append(r.sensor)

    def finish(self, result) -> None:
        result.notes.append(note("gtsam", self.r, self.model, float(self.builder.iv.t[0]), self.reacquire.times))
