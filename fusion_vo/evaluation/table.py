"""Metrics as a table: the key columns, their formatting and a terminal rendering with rich."""

from __future__ import annotations

import math
from dataclasses import dataclass

from rich import box
from rich.table import Table


@dataclass(frozen=True)
class Column:
    """One figure shown in tables: its key in ``metrics.json``, header and number format."""

    key: str
    header: str
    fmt: str = "{:.3f}"

    def format(self, figures: dict) -> str:
        """The formatted value, or an en dash where the figure is missing or not a number."""
        value = figures.get(self.key)
        if value is None or (isinstance(value, float) and not math.isfinite(value)):
            return "\u2013"
        return self.fmt.format(value)


#: position and heading columns
POSE_COLUMNS = (
    Column("ate_m", "ATE [m]"),
    Column("ate_anchored_m", "ATE anch. [m]"),
    Column("rpe_1m_pct", "RPE 1 m [%]", "{:.2f}"),
    Column("drift_pct", "drift [%]", "{:.2f}"),
    Column("end_m", "end [m]"),
    Column("end_pct", "end [%]", "{:.2f}"),
    Column("heading_deg", "heading [deg]", "{:.2f}"),
)

#: velocity columns
VELOCITY_COLUMNS = (
    Column("vx_rmse_m_s", "vx RMSE [m/s]", "{:.4f}"),
    Column("vy_rmse_m_s", "vy RMSE [m/s]", "{:.4f}"),
    Column("yaw_rate_rmse_deg_s", "yaw rate RMSE [deg/s]", "{:.2f}"),
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
    table = Table(title=title, box=box.SIMPLE_HEAD)
    table.add_column(first_header, style="bold")
    for column in columns:
        table.add_column(column.header, justify="right")
    for row in metrics_rows(metrics, columns):
        table.add_row(*row)
    return table


def legs_table(name: str, legs: list[dict]) -> Table:
    """Per-leg table of one trajectory (thesis table 5.2): positions in metres, errors in %."""
    table = Table(title=f"Legs of {name}", box=box.SIMPLE_HEAD)
    for header in ("leg", "start (x, y) [m]", "end (x, y) [m]", "actual [m]", "estimated [m]",
                   "error [%]", "rel. error [%]"):
        table.add_column(header, justify="right")
    for leg in legs:
        table.add_row(str(leg["leg"]), "({:.3f}, {:.3f})".format(*leg["start"]),
                      "({:.3f}, {:.3f})".format(*leg["end"]), f"{leg['actual_m']:.3f}",
                      f"{leg['estimated_m']:.3f}", f"{leg['error_pct']:.2f}",
                      f"{leg['relative_error_pct']:.2f}")
    return table
