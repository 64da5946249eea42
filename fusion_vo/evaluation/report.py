"""A self-contained HTML report of one run.

The page is the jinja2 template ``templates/report.html.j2`` (autoescaped); this module only gathers
what it shows: the run's notes, the errors against ground truth, the measurements per sensor, the
visual frontend's summary, the figures and the configuration. The report is a single file: styles
inline, figures embedded as base64 PNG data URIs, no scripts and no external resources, so it opens from disk in any browser and can be mailed or archived as is.
"""

from __future__ import annotations

import base64
import functools
import logging
import math
from datetime import datetime, timezone
from pathlib import Path

import jinja2
import yaml

from fusion_vo.evaluation.io import write_atomic
from fusion_vo.evaluation.table import KEY_COLUMNS

logger = logging.getLogger(__name__)

_TEMPLATES = Path(__file__).with_name("templates")


@functools.cache
def _environment() -> jinja2.Environment:
    return jinja2.Environment(loader=jinja2.FileSystemLoader(_TEMPLATES), autoescape=True,
                              undefined=jinja2.StrictUndefined, keep_trailing_newline=True)


def _number(value, fmt: str = "{:.3f}") -> str:
    """The formatted value, or an en dash where the figure is missing or not a number."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "\u2013"
    return fmt.format(value)


def count_rows(counts: dict | None) -> tuple[list[str], list[list]]:
    """Headers and rows of the per-sensor table from ``summary.json``'s ``fusion.counts``
    (backend -> sensor -> outcome -> number)."""
    counts = counts or {}
    outcomes: list[str] = []
    for sensors in counts.values():
        for outcome_counts in (sensors or {}).values():
            outcomes += [k for k in outcome_counts if k not in outcomes]
    rows = [[backend, sensor] + [outcome_counts.get(k, "\u2013") for k in outcomes]
            for backend, sensors in counts.items() for sensor, outcome_counts in (sensors or {}).items()]
    return ["backend", "sensor"] + outcomes, rows


def render_report(title: str, config: dict, metrics: dict[str, dict], images: dict[str, bytes],
                  frontend: dict | None = None, notes: list[str] | None = None,
                  counts: dict | None = None, sections: list | None = None) -> str:
    """Build the HTML text of a report from the template ``templates/report.html.j2``.

    Parameters
    ----------
    title : str
        Heading of the page.
    config : dict
        Configuration of the run (shown as YAML).
    metrics : dict
        Trajectory name -> figures, as in ``metrics.json``.
    images : dict
        Caption -> PNG bytes, shown in this order.
    frontend : dict, optional
        Summary of the visual frontend (frame counts per status, mean inliers).
    notes : list of str, optional
        The run's notes (``summary.json``): camera loss, skipped frames, self-calibration, ...
    counts : dict, optional
        Measurements per backend and sensor (``summary.json``'s ``fusion.counts``).
    sections : list, optional
        Further tables ``(heading, headers, rows, notes)``, shown before the figures (e.g. errors against
        another reference); the table of errors against ground truth is then shown only with ``metrics``.

    Returns
    -------
    str
        A complete HTML document.
    """
    count_headers, counts_table = count_rows(counts)
    context = {
        "title": title,
        "generated": f"{datetime.now(timezone.utc):%Y-%m-%d %H:%M}",
        "sequence": (config or {}).get("sequence"),
        "notes": list(notes or []),
        "show_metrics": bool(metrics) or not sections,
        "sections": [{"heading": h, "headers": hs, "rows": rows, "notes": list(ns)} for h, hs, rows, ns in sections or []],
        "metric_headers": ["trajectory"] + [c.header for c in KEY_COLUMNS],
        "metric_rows": [[name] + [c.format(figures) for c in KEY_COLUMNS] for name, figures in metrics.items()],
        "drift_rows": [[name, _number(d["length_m"], "{:g}"), str(d["segments"]), _number(d["trans_pct"], "{:.2f}"),
                        _number(d["rot_deg_per_m"], "{:.2f}")]
                       for name, figures in metrics.items() for d in figures.get("drift", [])],
        "heading_rows": [[name, _number(f.get("heading_deg"), "{:.2f}"), _number(f.get("revolutions"), "{:.2f}"),
                          _number(f.get("heading_per_rev_deg"), "{:.2f}"),
                          _number(f.get("heading_per_rev_pct"), "{:.3f}")] for name, f in metrics.items()],
        "leg_rows": [[name, str(leg["leg"]), "({:.3f}, {:.3f})".format(*leg["start"]),
                      "({:.3f}, {:.3f})".format(*leg["end"]), _number(leg["actual_m"]), _number(leg["estimated_m"]),
                      _number(leg["error_pct"], "{:.2f}"), _number(leg["relative_error_pct"], "{:.2f}")]
                     for name, figures in metrics.items() for leg in figures.get("legs", [])],
        "count_headers": count_headers,
        "count_rows": counts_table,
        "frontend": [[k, str(v)] for k, v in (frontend or {}).items()],
        "images": [{"caption": caption, "data": base64.b64encode(png).decode("ascii")}
                   for caption, png in images.items()],
        "config_yaml": yaml.safe_dump(config, sort_keys=False) if config else "(none)",
    }
    return _environment().get_template("report.html.j2").render(**context)


def write_report(path: str | Path, title: str, config: dict, metrics: dict[str, dict],
                 images: dict[str, str | Path], frontend: dict | None = None, notes: list[str] | None = None,
                 counts: dict | None = None, sections: list | None = None) -> Path:
    """Render a report with the given PNG files embedded and write it atomically to ``path``."""
    pngs = {caption: Path(p).read_bytes() for caption, p in images.items()}
    text = render_report(title, config, metrics, pngs, frontend, notes, counts, sections)
    logger.debug("wrote %s", path)
    return write_atomic(path, text)
