"""Metrics as a table: the key columns, their formatting and a terminal rendering with rich."""

from __future__ import annotations

import math
from dataclasses import dataclass

from rich import box
from rich.table import Table


@dataclass(frozen=True)
class Column:
    """One figure shown in tables: its key in ``metrics.json``, headers and number format.

    ``header`` is used in reports, the narrower ``short`` on the terminal. ``scale`` multiplies the value
    of ``metrics.json`` (always in SI units) before formatting, for a column shown in other units.
    """

    key: str
    header: str
    short: str
    fmt: str = "{:.3f}"
    scale: float = 1.0

    def format(self, figures: dict) -> str:
        """The formatted value, or an en dash where the figure is missing or not a number."""
        value = figures.get(self.key)
        if value is None or (isinstance(value, float) and not math.isfinite(value)):
            return "\u2013"
        return self.fmt.format(value * self.scale)

    def in_millimetres(self) -> Column:
        """The same figure in millimetres (``m`` -> ``mm``, ``m/s`` -> ``mm/s``), three decimals."""
        unit = "m/s" if self.key.endswith("_m_s") else "m"
        return Column(self.key, self.header.replace(f"[{unit}]", f"[m{unit}]"),
                      self.short.replace(f" {unit}", f" m{unit}"), "{:.3f}", self.scale * 1000.0)


#: position and heading columns
POSE_COLUMNS = (
    Column("ate_m", "ATE [m]", "ATE m", "{:.4f}"),
    Column("ate_anchored_m", "ATE anch. [m]", "ATE0 m", "{:.4f}"),
    Column("rpe_1m_pct", "RPE 1 m [%]", "RPE1m %", "{:.2f}"),
    Column("drift_pct", "drift [%]", "drift %", "{:.2f}"),
    Column("end_m", "end [m]", "end m", "{:.4f}"),
    Column("end_pct", "end [%]", "end %", "{:.2f}"),
    Column("heading_deg", "heading [deg]", "head. deg", "{:.2f}"),
)

#: velocity columns
VELOCITY_COLUMNS = (
    Column("vx_rmse_m_s", "vx RMSE [m/s]", "vx m/s", "{:.4f}"),
    Column("vy_rmse_m_s", "vy RMSE [m/s]", "vy m/s", "{:.4f}"),
    Column("yaw_rate_rmse_deg_s", "yaw rate RMSE [deg/s]", "yaw rate deg/s", "{:.2f}"),
)

#: columns of every metrics table (report, comparison)
KEY_COLUMNS = POSE_COLUMNS + VELOCITY_COLUMNS

#: a later run's distance from the same trajectory of the first run (``fusion-vo compare``)
DIFFERENCE_COLUMNS = (
    Column("diff_rms_m", "RMS [m]", "RMS m", "{:.4f}"),
    Column("diff_max_m", "largest [m]", "max m", "{:.4f}"),
    Column("diff_end_m", "at the end [m]", "end m", "{:.4f}"),
)


def metrics_rows(metrics: dict[str, dict], columns: tuple[Column, ...] = KEY_COLUMNS) -> list[list[str]]:
    """Rows ``[name, value, ...]`` of ``columns`` for each trajectory in ``metrics``."""
    return [[name] + [c.format(figures) for c in columns] for name, figures in metrics.items()]


#: a length or speed column with a value below this [m, m/s] is shown in millimetres
MILLIMETRES_BELOW = 0.01


def readable_units(metrics: dict[str, dict], columns: tuple[Column, ...]) -> tuple[Column, ...]:
    """``columns`` with each metre or metre-per-second column in millimetres where a value is below 1 cm.

    At four decimals in metres, errors of tens of micrometres (a clean generated drive) all print as
    0.0001 and the tracks cannot be told apart; in millimetres they keep at least two significant digits
    down to 10 µm.
    """
    out = []
    for column in columns:
        if column.scale == 1.0 and (column.key.endswith("_m") or column.key.endswith("_m_s")):
            values = [figures.get(column.key) for figures in metrics.values()]
            values = [abs(v) for v in values if isinstance(v, (int, float)) and math.isfinite(v)]
            if values and min(values) < MILLIMETRES_BELOW:
                column = column.in_millimetres()
        out.append(column)
    return tuple(out)


def metrics_table(metrics: dict[str, dict], title: str = "Trajectory errors",
                  first_header: str = "trajectory", columns: tuple[Column, ...] = KEY_COLUMNS) -> Table:
    """A rich table of ``columns``, one row per trajectory (or per run and trajectory).

    Parameters
    ----------
    metrics : dict
        Row label -> figures (as in ``metrics.json``).
    """
    caption = ("ATE0: anchored at the start; velocity errors are RMSE" if columns is VELOCITY_COLUMNS
               else "horizontal distance at the first run's times" if columns is DIFFERENCE_COLUMNS
               else "ATE0: anchored at the start")
    columns = readable_units(metrics, columns)
    table = Table(title=title, box=box.SIMPLE_HEAD, caption=caption)
    table.add_column(first_header, style="bold", no_wrap=True)
    for column in columns:
        table.add_column(column.short, justify="right")
    for row in metrics_rows(metrics, columns):
        table.add_row(*row)
    return table


def legs_table(metrics: dict[str, dict]) -> Table | None:
    """The legs between turns (thesis table 5.2): one row per leg, the length error [%] of each trajectory.

    Returns ``None`` when no trajectory has legs.
    """
    names = [name for name, figures in metrics.items() if figures.get("legs")]
    if not names:
        return None
    legs: dict[int, dict] = {}
    for name in names:
        for leg in metrics[name]["legs"]:
            legs.setdefault(leg["leg"], {"leg": leg, "errors": {}})["errors"][name] = leg["error_pct"]
    table = Table(title="Legs between turns: length error [%]", box=box.SIMPLE_HEAD,
                  caption="start and end of each leg are in metrics.json and the report")
    for header in ("leg", "length m"):
        table.add_column(header, justify="right", no_wrap=True)
    for name in names:  # "ekf_smoothed" -> "ekf\nsmoothed": narrow columns that are never cut
        table.add_column(name.replace("_", "\n"), justify="right", no_wrap=True)
    for number in sorted(legs):
        leg, errors = legs[number]["leg"], legs[number]["errors"]
        cells = [str(number), f"{leg['actual_m']:.3f}"]
        cells += ["\u2013" if errors.get(n) is None else f"{errors[n]:.2f}" for n in names]
        table.add_row(*cells)
    return table
