"""A self-contained HTML report of one run.

The page is the jinja2 template ``templates/report.html.j2`` (autoescaped); this module turns a
:class:`ReportContent` (gathered by :mod:`fusion_vo.evaluation.run_report`) into the template's context.
The report is a single file: styles inline, figures embedded as base64 PNG data URIs, no scripts and no
external resources, so it opens from disk in any browser and can be mailed or archived as is. It holds no
clock time, so the same run folder always gives the same page.
"""

from __future__ import annotations

import base64
import functools
import logging
import math
from dataclasses import dataclass, field
from pathlib import Path

import jinja2
import yaml

from fusion_vo.evaluation.innovations import BAND_PROBABILITY, NIS_HEADERS
from fusion_vo.evaluation.io import write_atomic
from fusion_vo.evaluation.table import KEY_COLUMNS, readable_units

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


@dataclass
class ReportContent:
    """Everything a report shows; a section whose field is empty is left out (or replaced by its sentence).

    Attributes
    ----------
    title, subtitle : str
        Heading (from the recording) and the line under it (which run).
    config : dict
        The run's configuration (folded away at the end of the page).
    notes : list of str
        The run's notes (``summary.json``).
    absent : list of str
        A sentence for each optional file the run folder lacks (its section is left out).
    verdict : list of str
        The plain-words verdict (:mod:`fusion_vo.evaluation.verdict`).
    accuracy_line : str or None
        Why there is no accuracy section (no ground truth, no evo, not asked for).
    metrics : dict
        Trajectory -> figures against ground truth (``metrics.json``).
    sections : list
        Further accuracy tables ``(heading, headers, rows, notes)`` (errors against GPS fixes).
    figures : list
        ``(section, caption, PNG path)`` in order; sections ``accuracy``, ``tracks``, ``influence``, ``nis``,
        ``frontend``.
    influence, calibration, dropped, pauses : tuple or None
        ``(headers, rows)`` of those tables (:mod:`fusion_vo.evaluation.run_tables`).
    influence_reference : str
        The fused track the influence is measured against.
    nis : list or None
        Rows of the NIS table (:data:`~fusion_vo.evaluation.innovations.NIS_HEADERS`).
    graph_nis_line : str or None
        Why the factor graph's NIS is not shown.
    gated : tuple or None
        ``(headers, rows, spans left out)`` of the EKF's gated spans.
    counts : dict or None
        Measurements per backend and sensor (``summary.json``'s ``fusion.counts``).
    frontend : dict or None
        Summary of the visual frontend (frame counts per status, mean inliers).
    span : tuple
        First and last node [s, recording clock].
    """

    title: str
    subtitle: str = ""
    config: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    absent: list = field(default_factory=list)
    verdict: list = field(default_factory=list)
    accuracy_line: str | None = None
    metrics: dict = field(default_factory=dict)
    sections: list = field(default_factory=list)
    figures: list = field(default_factory=list)
    influence: tuple | None = None
    influence_reference: str = ""
    calibration: tuple | None = None
    dropped: tuple | None = None
    pauses: tuple | None = None
    nis: list | None = None
    graph_nis_line: str | None = None
    gated: tuple | None = None
    counts: dict | None = None
    frontend: dict | None = None
    span: tuple = (math.nan, math.nan)

    def figure(self, section: str, caption: str, path: str | Path) -> None:
        """Add a figure (a PNG written into the run folder) to ``section``."""
        self.figures.append((section, caption, Path(path)))


def _accuracy_context(metrics: dict[str, dict]) -> dict:
    columns = readable_units(metrics, KEY_COLUMNS)
    return {
        "metric_headers": ["trajectory"] + [c.header for c in columns],
        "metric_rows": [[name] + [c.format(figures) for c in columns] for name, figures in metrics.items()],
        "drift_rows": [[name, _number(d["length_m"], "{:g}"), str(d["segments"]), _number(d["trans_pct"], "{:.2f}"),
                        _number(d["rot_deg_per_m"], "{:.2f}")]
                       for name, figures in metrics.items() for d in figures.get("drift", [])],
        "heading_rows": [[name, _number(f.get("heading_deg"), "{:.2f}"), _number(f.get("revolutions"), "{:.2f}"),
                          _number(f.get("heading_per_rev_deg"), "{:.2f}"),
                          _number(f.get("heading_per_rev_pct"), "{:.3f}")] for name, f in metrics.items()
                         if "heading_deg" in f],
        "leg_rows": [[name, str(leg["leg"]), "({:.3f}, {:.3f})".format(*leg["start"]),
                      "({:.3f}, {:.3f})".format(*leg["end"]), _number(leg["actual_m"]), _number(leg["estimated_m"]),
                      _number(leg["error_pct"], "{:.2f}"), _number(leg["relative_error_pct"], "{:.2f}")]
                     for name, figures in metrics.items() for leg in figures.get("legs", [])],
    }


def render_report(content: ReportContent) -> str:
    """The HTML text of a report (template ``templates/report.html.j2``), the figures read from their files."""
    count_headers, counts_table = count_rows(content.counts)
    figures: dict[str, list] = {}
    for section, caption, path in content.figures:
        data = base64.b64encode(Path(path).read_bytes()).decode("ascii")
        figures.setdefault(section, []).append({"caption": caption, "data": data})
    context = {
        "c": content,
        "sequence": (content.config or {}).get("sequence"),
        "figures": figures,
        "count_headers": count_headers,
        "count_rows": counts_table,
        "nis_headers": NIS_HEADERS,
        "band_percent": f"{100 * BAND_PROBABILITY:.0f}",
        "frontend": [[k, str(v)] for k, v in (content.frontend or {}).items()],
        "config_yaml": yaml.safe_dump(content.config, sort_keys=False) if content.config else "(none)",
        **_accuracy_context(content.metrics),
    }
    return _environment().get_template("report.html.j2").render(**context)


def write_report(path: str | Path, content: ReportContent) -> Path:
    """Render a report with its figures embedded and write it atomically to ``path``."""
    text = render_report(content)
    logger.debug("wrote %s", path)
    return write_atomic(path, text)
