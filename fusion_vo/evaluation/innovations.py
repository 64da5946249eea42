"""``innovations.csv`` of a run: every measurement a backend tested, and the NIS consistency table.

File
----
``innovations.csv`` holds one row per measurement block after the header
``backend,t,sensor,nis,dof,status``:

``backend``  ``ekf`` (the filter's pass, :attr:`fusion_vo.backends.result.FusionResult.innovations`), or
             ``gtsam`` / ``gtsam_online`` for the factor graph's residuals at its solution when the run
             computed them (``fusion.graph.residuals``; :mod:`fusion_vo.backends.residuals`)
``t``        time of the node [s, recording clock]
``sensor``   the measurement model (``camera``, ``wheel``, ``gyro``, ``ahrs``, ``still``, ``range``, ``gps``, ...)
``nis``      normalised innovation squared ``d² = yᵀ S⁻¹ y`` (the filter: ``y = z - h(x⁻)``,
             ``S = H P⁻ Hᵀ + R``; the graph: its residual at the solution against its covariance ``R - H P Hᵀ``)
``dof``      rows of the measurement (the degrees of freedom of its chi-square distribution)
``status``   ``used``, ``down-weighted`` (outside the gate: applied with its covariance inflated so that it
             sits on the gate) or ``rejected`` (beyond 25 times the gate)

NIS band
--------
With a right noise model a block's NIS is chi-square with ``dof`` degrees of freedom: its mean is ``dof``
and it falls inside the central band ``[χ²_dof((1-p)/2), χ²_dof((1+p)/2)]`` with probability ``p``
(:data:`BAND_PROBABILITY`, 95 %). The mean of ``n`` independent NIS values is ``χ²_{n·dof} / n``, whose band
is much narrower; a sensor whose mean NIS lies above its band has a stated noise that is too small (or
data that contradict the others), below it a noise that is too large.
"""

from __future__ import annotations

import functools
import io
import math
from pathlib import Path

import numpy as np

from fusion_vo.backends.result import INNOVATION_STATUSES, Innovations
from fusion_vo.errors import InputError
from fusion_vo.evaluation.io import read_rows, write_atomic

#: file name in a run folder
INNOVATIONS_CSV = "innovations.csv"

HEADER = "backend,t,sensor,nis,dof,status"

#: probability of the NIS band drawn and counted
BAND_PROBABILITY = 0.95


@functools.lru_cache(maxsize=256)
def band(dof: int, n: int = 1, probability: float = BAND_PROBABILITY) -> tuple[float, float]:
    """Central ``probability`` band of the mean of ``n`` independent NIS values of ``dof`` degrees of freedom."""
    from scipy.stats import chi2

    k = int(dof) * int(n)
    lo, hi = chi2.ppf([(1 - probability) / 2, (1 + probability) / 2], k)
    return float(lo) / n, float(hi) / n


def from_residuals(residuals: dict) -> Innovations:
    """The graph's per-sensor NIS at its solution (``FusionResult.residuals[backend]``: sensor ->
    ``(dof, rows (t, NIS))``) as one table (status ``used``)."""
    tables = []
    for sensor, (dof, rows) in residuals.items():
        rows = np.asarray(rows, dtype=np.float64).reshape(-1, 2)
        n = len(rows)
        tables.append(Innovations(rows[:, 0], np.full(n, sensor.split(" (")[0], dtype=object), rows[:, 1],
                                  np.full(n, int(dof), dtype=np.int64), np.full(n, "used", dtype=object)))
    return Innovations.concatenate(tables)


def write_innovations(path: str | Path, tables: dict[str, Innovations]) -> Path:
    """Write ``innovations.csv`` (module docstring), atomically; backends in the given order."""
    buf = io.StringIO()
    buf.write(HEADER + "\n")
    for backend, table in tables.items():
        for t, sensor, d2, dof, status in zip(table.t, table.sensor, table.d2, table.dof, table.status):
            buf.write(f"{backend},{t:.6f},{sensor},{d2:.6g},{int(dof)},{status}\n")
    return write_atomic(path, buf.getvalue())


def read_innovations(path: str | Path) -> dict[str, Innovations]:
    """Read ``innovations.csv`` back: backend -> :class:`Innovations` (rows in file order).

    Raises
    ------
    InputError
        Naming the file and line: a missing or different header, a row without six fields, a time or NIS
        that is not a finite number (NIS at least 0), a dof that is not a positive integer, an unknown status.
    """
    path = Path(path)
    rows: dict[str, list] = {}
    for number, text in read_rows(path, HEADER):
        fields = text.split(",")
        if len(fields) != 6:
            raise InputError(f"expected 6 fields ({HEADER}), got {len(fields)}", path, number)
        backend, t, sensor, nis, dof, status = (f.strip() for f in fields)
        try:
            t_value, nis_value = float(t), float(nis)
        except ValueError:
            raise InputError(f"t and nis must be numbers, got {t!r} and {nis!r}", path, number) from None
        if not (math.isfinite(t_value) and math.isfinite(nis_value) and nis_value >= 0):
            raise InputError(f"t must be finite and nis a finite number >= 0, got {t} and {nis}", path, number)
        if not dof.isdigit() or int(dof) < 1:
            raise InputError(f"dof must be a positive integer, got {dof!r}", path, number)
        if status not in INNOVATION_STATUSES:
            raise InputError(f"unknown status {status!r} (expected one of {', '.join(INNOVATION_STATUSES)})",
                             path, number)
        if not backend or not sensor:
            raise InputError("backend and sensor must not be empty", path, number)
        rows.setdefault(backend, []).append((t_value, sensor, nis_value, int(dof), status))
    out = {}
    for backend, items in rows.items():
        t, sensor, d2, dof, status = zip(*items)
        out[backend] = Innovations(np.array(t), np.array(sensor, dtype=object), np.array(d2),
                                   np.array(dof, dtype=np.int64), np.array(status, dtype=object))
    return out


def groups(tables: dict[str, Innovations]) -> list[tuple[str, str, int, np.ndarray]]:
    """``(backend, sensor, dof, row indices)`` of every backend, sensor and measurement size, in first
    appearance order (a wheel block whose yaw row the monitor dropped has 2 rows instead of 3: its own group)."""
    out = []
    for backend, table in tables.items():
        keys: dict[tuple[str, int], list[int]] = {}
        for i, (sensor, dof) in enumerate(zip(table.sensor, table.dof)):
            keys.setdefault((str(sensor), int(dof)), []).append(i)
        out += [(backend, sensor, dof, np.asarray(idx)) for (sensor, dof), idx in keys.items()]
    return out


NIS_HEADERS = ["backend", "sensor", "rows (dof)", "blocks", "used", "down-weighted", "rejected", "mean NIS",
               "band of the mean", "median NIS", "in band [%]", "above band [%]"]


def nis_table(tables: dict[str, Innovations]) -> list[list[str]]:
    """One row per backend, sensor and measurement size (:data:`NIS_HEADERS`): how many blocks, what the gate
    did, the mean NIS with the 95 % band of a mean of that many, the median, and the share of single NIS
    values inside and above their own 95 % band."""
    rows = []
    for backend, sensor, dof, idx in groups(tables):
        table = tables[backend]
        d2 = table.d2[idx]
        status = table.status[idx]
        lo, hi = band(dof)
        mlo, mhi = band(dof, len(d2))
        rows.append([backend, sensor, str(dof), str(len(d2))]
                    + [str(int(np.count_nonzero(status == s))) for s in INNOVATION_STATUSES]
                    + [f"{np.mean(d2):.3g}", f"{mlo:.3g} to {mhi:.3g}", f"{np.median(d2):.3g}",
                       f"{100.0 * np.mean((d2 >= lo) & (d2 <= hi)):.1f}", f"{100.0 * np.mean(d2 > hi):.1f}"])
    return rows
