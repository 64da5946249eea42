"""Metrics as a table: the key columns, their formatting and a terminal rendering with rich."""

from __future__ import annotations

import math
from dataclasses import dataclass

from rich import box
from rich.table import Table


@dataclass(frozen=True)
class Column:
    """One figure shown in tables: its key in ``metrics.json``, headers and number format.

    ``header`` is used in reports, the narrower ``short`` on the terminal.
    """

    key: str
    header: str
    short: str
    fmt: str = "{:.3f}"

    def format(self, figures: dict) -> str:
        """The formatted value, or an en dash where the figure is missing or not a number."""
        value = figures.get(self.key)
        if value is None or (isinstance(value, float) and not math.isfinite(value)):
            return "\u2013"
        return self.fmt.format(value)


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


def metrics_rows(metrics: dict[str, dict], columns: tuple[Column, ...] = KEY_COLUMNS) -> list[list[str]]:
    """Rows ``[name, value, ...]`` of ``columns`` for each trajectory in ``metrics``."""
    return [[name] + [c.format(figures) for c in columns] for name, figures in metrics.items()]


def metrics_table(metrics: dict[str, dict], title: str = "Trajectory errors",
                  first_header: str = "trajectory", columns: tuple[Column, ...] = KEY_COLUMNS) -> Table:
    """A rich table of ``columns``, one row per trajectory (or per run and trajectory).

    Parameters
    ----------
    metrics : dict
        Row label -> figures (as in ``metrics.json``).
    """
    table = Table(title=title, box=box.SIMPLE_HEAD, caption="ATE0: anchored at the start; velocity "
                  "errors are RMSE" if columns is VELOCITY_COLUMNS else "ATE0: anchored at the start")
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
