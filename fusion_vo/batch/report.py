"""``report.html`` of a batch or a sweep: one table and one plot per metric, in a single self-contained file.

A batch shows each metric per recording (bars, one per trajectory; a box plot per trajectory beyond
:data:`MAX_BARS` recordings). A sweep shows each metric against each swept key (the mean over the
recordings, per trajectory) and names the best parameter set.
"""

from __future__ import annotations

import base64
import logging
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from fusion_vo.batch.grid import Grid
from fusion_vo.batch.ranking import best_sets, describe_set
from fusion_vo.batch.columns import METRICS
from fusion_vo.evaluation.io import write_atomic
from fusion_vo.evaluation.plots import colour_of, figure_png, label_of
from fusion_vo.evaluation.report import _environment, _number

log = logging.getLogger(__name__)

#: headers of the metric columns
METRIC_LABELS = {"ate_m": "ATE [m]", "end_pct": "end-point error [%]", "heading_deg": "heading error [deg]",
                 "rpe_1m_pct": "RPE over 1 m [%]"}
#: recordings beyond which the per-recording bars become box plots
MAX_BARS = 30
#: rows beyond which the report shows a summary per trajectory instead of every row
MAX_ROWS = 2000


def _figure(n: int, width: float = 8.0, height: float = 3.2):
    fig = Figure(figsize=(width, height * n), dpi=90, layout="constrained")
    FigureCanvasAgg(fig)
    return fig, fig.subplots(n, 1, squeeze=False)[:, 0]


def _metric_per_recording(frame, metric: str) -> bytes | None:
    ok = frame[(frame["status"] == "ok") & frame[metric].notna()]
    if ok.empty:
        return None
    recordings = list(dict.fromkeys(frame["recording"]))
    trajectories = list(dict.fromkeys(ok["trajectory"]))
    fig, (ax,) = _figure(1)
    if len(recordings) <= MAX_BARS:
        width = 0.8 / max(len(trajectories), 1)
        x = np.arange(len(recordings))
        for k, name in enumerate(trajectories):
            values = ok[ok["trajectory"] == name].set_index("recording")[metric].reindex(recordings)
            ax.bar(x + (k - (len(trajectories) - 1) / 2) * width, values.to_numpy(dtype=float), width,
                   color=colour_of(name), label=label_of(name))
        failed = set(frame[frame["status"] != "ok"]["recording"])
        for i, name in enumerate(recordings):
            if name in failed:
                ax.text(i, 0.02, "failed", transform=ax.get_xaxis_transform(), ha="center", color="tab:red")
        ax.set_xlim(-0.5, len(recordings) - 0.5)
        ax.set_xticks(x, recordings, rotation=30 if len(recordings) > 6 else 0, ha="right" if len(recordings) > 6 else "center")
        ax.legend(fontsize="small", ncols=min(len(trajectories), 4))
    else:
        data = [ok[ok["trajectory"] == name][metric].to_numpy(dtype=float) for name in trajectories]
        ax.boxplot(data, tick_labels=[label_of(n) for n in trajectories])
        ax.set_xlabel(f"trajectory ({len(recordings)} recordings)")
    ax.set_ylabel(METRIC_LABELS[metric])
    _scale(ax, ok[metric])
    ax.grid(True, axis="y", alpha=0.3)
    return figure_png(fig)


def _scale(ax, values) -> None:
    """A logarithmic axis when the figures span more than a factor of 30 (visual against wheel errors)."""
    positive = values[values > 0]
    if len(positive) == len(values) and len(values) and positive.max() > 30 * positive.min():
        ax.set_yscale("log")


def _metric_against_keys(frame, metric: str, keys: list[str]) -> bytes | None:
    ok = frame[(frame["status"] == "ok") & frame[metric].notna()]
    if ok.empty:
        return None
    trajectories = list(dict.fromkeys(ok["trajectory"]))
    fig, axes = _figure(len(keys), height=2.8)
    for ax, key in zip(axes, keys):
        means = ok.groupby(["trajectory", key], sort=True)[metric].mean().reset_index()
        values = list(dict.fromkeys(frame[key]))
        numeric = all(isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool) for v in values)
        order = sorted(values) if numeric else values
        for name in trajectories:
            part = means[means["trajectory"] == name]
            if numeric:
                part = part.sort_values(key)
                x = part[key].to_numpy(dtype=float)
            else:
                x = np.array([order.index(v) for v in part[key]], dtype=float)
            ax.plot(x, part[metric].to_numpy(dtype=float), marker="o", color=colour_of(name), label=label_of(name),
                    ls="-" if numeric else "none")
        if not numeric:
            ax.set_xticks(range(len(order)), [str(v) for v in order])
        ax.set_xlabel(key)
        ax.set_ylabel(METRIC_LABELS[metric])
        _scale(ax, ok[metric])
        ax.grid(True, alpha=0.3)
    axes[0].set_title(f"{METRIC_LABELS[metric]}: mean over the recordings, per value of each swept key")
    axes[0].legend(fontsize="small", ncols=min(len(trajectories), 4))
    return figure_png(fig)


def _rows_table(frame, keys: list[str]) -> tuple[list[str], list[list]]:
    headers = ["recording", *(["set", *keys] if keys else []), "trajectory", "status", *METRIC_LABELS.values(),
               "frames", "failed frames", "seconds", "error"]
    rows = []
    for r in frame.to_dict("records"):
        rows.append([r["recording"], *([r["parameter_set"], *[r[k] for k in keys]] if keys else []), r["trajectory"],
                     r["status"] + (" (cached)" if r["cached"] else ""),
                     _number(r["ate_m"], "{:.4f}"), _number(r["end_pct"], "{:.3f}"),
                     _number(r["heading_deg"], "{:.3f}"), _number(r["rpe_1m_pct"], "{:.3f}"),
                     str(r["frames"]), str(r["failed_frames"]), _number(r["seconds"], "{:.1f}"), r["error"]])
    return headers, rows


def _summary_table(frame) -> tuple[list[str], list[list]]:
    ok = frame[frame["status"] == "ok"]
    rows = []
    for name, part in ok.groupby("trajectory", sort=False):
        rows.append([name, str(len(part))] + [f"{_number(part[m].median(), '{:.4f}')} / {_number(part[m].max(), '{:.4f}')}"
                                              for m in METRICS])
    return ["trajectory", "recordings", *(f"{METRIC_LABELS[m]} median / max" for m in METRICS)], rows


def render(frame, title: str, grid: Grid | None = None, rank: tuple[str, str | None] = ("ate_m", None)) -> str:
    """The HTML text of the report, from the template ``fusion_vo/evaluation/templates/batch.html.j2``."""

    keys = grid.keys if grid else []
    tasks = frame.drop_duplicates(["recording", "parameter_set"] if keys else ["recording"])
    context: dict = {"title": title, "generated": f"{datetime.now(timezone.utc):%Y-%m-%d %H:%M}",
                     "n_tasks": len(tasks), "n_failed": int((tasks["status"] != "ok").sum()),
                     "n_cached": int(tasks["cached"].sum()), "sweep": bool(keys), "best": None}
    if keys:
        ranked, trajectory = best_sets(frame, *rank)
        if len(ranked) and ranked["recordings"].iloc[0] > 0 and not np.isnan(ranked["mean"].iloc[0]):
            best = ranked["parameter_set"].iloc[0]
            context["best"] = {"set": best, "description": describe_set(frame, best),
                               "metric": METRIC_LABELS[rank[0]], "trajectory": label_of(trajectory),
                               "mean": _number(ranked["mean"].iloc[0], "{:.5g}"),
                               "recordings": ranked["recordings"].iloc[0]}
        context["ranked_metric"] = METRIC_LABELS[rank[0]]
        context["ranked_trajectory"] = label_of(trajectory)
        context["ranked_headers"] = ["set", *keys, "mean", "recordings", "failed"]
        context["ranked_rows"] = [[r["parameter_set"], *[str(r[k]) for k in keys], _number(r["mean"], "{:.5g}"),
                                   str(r["recordings"]), str(r["failed"])] for r in ranked.to_dict("records")]
    failures = tasks[tasks["status"] != "ok"]
    context["failure_headers"] = ["recording", *(["set"] if keys else []), "error"]
    context["failure_rows"] = [[r["recording"], *([r["parameter_set"]] if keys else []), r["error"]]
                               for r in failures.to_dict("records")]
    if len(frame) <= MAX_ROWS:
        context["summary_note"] = None
        context["result_headers"], context["result_rows"] = _rows_table(frame, keys)
    else:
        context["summary_note"] = f"{len(frame)} rows: the table below summarises them per trajectory."
        context["result_headers"], context["result_rows"] = _summary_table(frame)
    figures = []
    for metric in METRICS:
        png = _metric_against_keys(frame, metric, keys) if keys else _metric_per_recording(frame, metric)
        figures.append({"caption": METRIC_LABELS[metric],
                        "data": base64.b64encode(png).decode("ascii") if png else None})
    context["figures"] = figures
    return _environment().get_template("batch.html.j2").render(**context)


def write_report(frame, path: str | Path, title: str, grid: Grid | None = None,
                 rank: tuple[str, str | None] = ("ate_m", None)) -> Path:
    """Render the report and write it atomically to ``path``."""
    return write_atomic(path, render(frame, title, grid, rank))
