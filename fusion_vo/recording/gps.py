"""``gps0/``: GNSS fixes of a recording, read into local East-North-Up at the datum.

Layout (``datasets/README.md``)::

    gps0/data.csv     #timestamp [ns],latitude [deg],longitude [deg],altitude [m],e [m],n [m],u [m]
                      [,status [],covariance_type [],cov_ee [m^2],cov_en [m^2],cov_nn [m^2]]
    gps0/sensor.yaml  T_BS (antenna in the body frame), horizontal_sigma_m, datum {latitude, longitude,
                      altitude}, rate_hz; every key optional

The ``e, n, u`` columns are recomputed from latitude, longitude and altitude at the datum (with pymap3d on
the WGS-84 ellipsoid), so a configured datum moves the whole stream. ``status`` and
``covariance_type`` are those of ``sensor_msgs/NavSatFix``; ``cov_ee, cov_en, cov_nn`` the east-north
block of its ``position_covariance``.

Latitude, longitude and altitude outside their ranges (90, 180 degrees, :data:`MAX_ALTITUDE_M`) and a
covariance beyond :data:`MAX_SIGMA_M` squared are errors naming the line. Skipped and counted (with a
note), never fatal: fixes with ``status < 0`` (no fix), a NaN in latitude,
longitude, altitude or a given covariance, and a given covariance that is zero or not positive
definite. A fix with ``covariance_type`` 0 (unknown) uses ``horizontal_sigma_m``.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pymap3d

from fusion_vo.errors import InputError
from fusion_vo.config.sensor_files import GpsFile
from fusion_vo.measurements import GpsData
from fusion_vo.recording.csvio import check_magnitude, read_table

log = logging.getLogger(__name__)

#: standard deviation [m] of a fix without a covariance when sensor.yaml gives none (single-point GNSS)
DEFAULT_HORIZONTAL_SIGMA = 2.5
#: the physical ranges of a fix: its altitude [m] (the deepest mine to far above any aircraft) and its
#: standard deviations [m] (``horizontal_sigma_m``, the square root of a covariance)
MAX_ALTITUDE_M = 1e5
MAX_SIGMA_M = 1e6
HEADER = ("#timestamp [ns],latitude [deg],longitude [deg],altitude [m],e [m],n [m],u [m],"
          "status [],covariance_type [],cov_ee [m^2],cov_en [m^2],cov_nn [m^2]")


def geodetic_to_enu(lat_deg, lon_deg, alt_m, datum) -> np.ndarray:
    """East, north, up [m] of WGS-84 positions relative to ``datum = (lat, lon, alt)``, shape (N, 3)."""
    e, n, u = pymap3d.geodetic2enu(np.asarray(lat_deg, float), np.asarray(lon_deg, float),
                                   np.asarray(alt_m, float), float(datum[0]), float(datum[1]), float(datum[2]))
    return np.column_stack([np.ravel(e), np.ravel(n), np.ravel(u)])


def enu_to_geodetic(enu, datum) -> np.ndarray:
    """Latitude, longitude [deg], altitude [m] of local ENU positions at ``datum``, shape (N, 3)."""
    enu = np.asarray(enu, dtype=np.float64).reshape(-1, 3)
    lat, lon, alt = pymap3d.enu2geodetic(enu[:, 0], enu[:, 1], enu[:, 2], float(datum[0]), float(datum[1]),
                                         float(datum[2]))
    return np.column_stack([np.ravel(lat), np.ravel(lon), np.ravel(alt)])


def read_gps(folder: str | Path) -> GpsData:
    """Read ``gps0/data.csv`` and ``gps0/sensor.yaml`` (module docstring).

    Raises
    ------
    InputError
        For a malformed file or key, or when no fix is usable.
    """
    folder = Path(folder)
    path = folder / "data.csv"
    tab = read_table(path, (6, 11), "GPS values", allow_nan=True)
    width = tab.values.shape[1]
    if len(tab) and width not in (6, 11):
        raise InputError("expected 6 GPS columns (latitude, longitude, altitude, e, n, u) or 11 (plus status, "
                         "covariance_type, cov_ee, cov_en, cov_nn)", path, int(tab.lines[0]))
    meta, notes = gps_settings(folder / "sensor.yaml")
    v = tab.values
    n = len(tab)
    geo = v[:, 0:3]
    status = v[:, 6].astype(np.int64) if width == 11 and n else np.zeros(n, dtype=np.int64)
    cov_type = v[:, 7] if width == 11 and n else np.zeros(n)
    cov = np.tile(np.eye(2) * meta["sigma"] ** 2, (n, 1, 1))
    if width == 11 and n:
        given = cov_type > 0
        cov[given] = np.stack([np.column_stack([v[given, 8], v[given, 9]]),
                               np.column_stack([v[given, 9], v[given, 10]])], axis=1)
    skipped = {}
    no_fix = status < 0
    nan = ~no_fix & (np.isnan(geo).any(axis=1) | (np.isnan(cov).any(axis=(1, 2))))
    with np.errstate(invalid="ignore"):
        det = cov[:, 0, 0] * cov[:, 1, 1] - cov[:, 0, 1] ** 2
        bad_cov = ~no_fix & ~nan & ((cov[:, 0, 0] <= 0) | (cov[:, 1, 1] <= 0) | (det <= 0))
    out_of_range = ~no_fix & ~nan & ((np.abs(geo[:, 0]) > 90) | (np.abs(geo[:, 1]) > 180))
    if np.any(out_of_range):
        i = int(np.flatnonzero(out_of_range)[0])
        raise InputError(f"latitude {geo[i, 0]} / longitude {geo[i, 1]} out of range", path, int(tab.lines[i]))
    check_magnitude(tab, path, slice(2, 3), MAX_ALTITUDE_M, "altitude [m]")
    if width == 11:
        check_magnitude(tab, path, slice(8, 11), MAX_SIGMA_M**2, "covariance [m^2]")
    for reason, mask in (("no fix", no_fix), ("NaN", nan), ("zero covariance", bad_cov)):
        if np.any(mask):
            skipped[reason] = int(mask.sum())
            first = int(tab.lines[np.flatnonzero(mask)[0]])
            notes.append(f"{path}: {int(mask.sum())} GPS fixes skipped ({reason}; first on line {first})")
    keep = ~(no_fix | nan | bad_cov)
    if not np.any(keep):
        raise InputError("no usable GPS fix (every row has no fix, a NaN or a zero covariance)" if n else
                         "no GPS fixes", path)
    datum = meta["datum"] if meta["datum"] is not None else tuple(float(x) for x in geo[keep][0])
    if meta["datum"] is None:
        notes.append(f"GPS datum (ENU origin) at the first fix: {datum[0]:.8f}, {datum[1]:.8f}, {datum[2]:.2f} m")
    enu = geodetic_to_enu(geo[keep, 0], geo[keep, 1], geo[keep, 2], datum)
    for note in notes:
        log.info("%s", note)
    return GpsData(t=tab.t[keep], enu=enu, covariance=cov[keep], geodetic=geo[keep].copy(), status=status[keep],
                   datum=datum, lever_arm=meta["lever_arm"], horizontal_sigma=meta["sigma"], skipped=skipped,
                   notes=notes)


def gps_settings(path: Path) -> tuple[dict, list[str]]:
    """``lever_arm``, ``sigma`` (for fixes without a covariance) and ``datum`` (or None: the first fix) of
    ``gps0/sensor.yaml`` (:class:`~fusion_vo.config.sensor_files.GpsFile`), or the documented defaults, with notes
    of the defaults taken."""
    if not path.is_file():
        note = (f"{path} not found: antenna at the body origin, horizontal sigma {DEFAULT_HORIZONTAL_SIGMA} m "
                "for fixes without a covariance, datum at the first fix")
        return {"lever_arm": np.zeros(3), "sigma": DEFAULT_HORIZONTAL_SIGMA, "datum": None}, [note]
    gps = GpsFile.read(path)
    lever = gps.pose(np.eye(4))[:3, 3].copy()
    sigma = DEFAULT_HORIZONTAL_SIGMA if gps.horizontal_sigma_m is None else gps.horizontal_sigma_m
    notes = [] if gps.horizontal_sigma_m is not None else [
        f"{path}: no horizontal_sigma_m, fixes without a covariance get {sigma} m"]
    datum = None if gps.datum is None else (gps.datum.latitude, gps.datum.longitude, gps.datum.altitude)
    return {"lever_arm": lever, "sigma": sigma, "datum": datum}, notes


def format_rows(t_ns, geodetic, enu, status, cov_type, cov_en) -> list[str]:
    """Rows of ``gps0/data.csv`` (the writer's side of :func:`read_gps`): ``cov_en`` is (N, 3) ee, en, nn."""
    rows = []
    for t, g, e, s, ct, c in zip(t_ns, geodetic, enu, status, cov_type, cov_en):
        rows.append(f"{int(t)},{g[0]:.10f},{g[1]:.10f},{g[2]:.4f},{e[0]:.4f},{e[1]:.4f},{e[2]:.4f},"
                    f"{int(s)},{int(ct)},{c[0]:.6g},{c[1]:.6g},{c[2]:.6g}")
    return rows


_sensor_yaml = gps_settings  # older name
