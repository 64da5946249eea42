"""A self-contained HTML report of one run.

The report is a single file: styles inline, figures embedded as base64 PNG data URIs, no scripts and no
external resources, so it opens from disk in any browser and can be mailed or archived as is.
"""

from __future__ import annotations

import base64
import html
import logging
import math
from datetime import datetime, timezone
from pathlib import Path

import yaml

from fusion_vo.evaluation.io import write_atomic
from fusion_vo.evaluation.table import KEY_COLUMNS

logger = logging.getLogger(__name__)

_STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1000px; color: #222; }
h1 { font-size: 1.6em; } h2 { font-size: 1.25em; border-bottom: 1px solid #ccc; padding-bottom: .2em; }
table { border-collapse: collapse; margin: .5em 0 1.5em; font-size: .9em; }
th, td { border: 1px solid #ccc; padding: .25em .6em; text-align: right; }
th { background: #f3f3f3; } td:first-child, th:first-child { text-align: left; }
pre { background: #f7f7f7; padding: .8em; overflow-x: auto; font-size: .85em; }
figure { margin: 1em 0; } figure img { max-width: 100%; border: 1px solid #eee; }
figcaption { color: #555; font-size: .9em; }
"""


def _table(headers: list[str], rows: list[list[str]]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in headers)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in row) + "</tr>"
                   for row in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _number(value, fmt: str = "{:.3f}") -> str:
    """The formatted value, or an en dash where the figure is missing or not a number."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "\u2013"
    return fmt.format(value)


def _image(title: str, png: bytes) -> str:
    data = base64.b64encode(png).decode("ascii")
    return (f'<figure><img alt="{html.escape(title)}" src="data:image/png;base64,{data}">'
            f"<figcaption>{html.escape(title)}</figcaption></figure>")


def render_report(title: str, config: dict, metrics: dict[str, dict], images: dict[str, bytes],
                  frontend: dict | None = None, sections: list | None = None) -> str:
    """Build the HTML text of a report.

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
    sections : list, optional
        Further tables ``(heading, headers, rows, notes)``, shown before the figures (the errors against
        GPS fixes of a recording without ground truth).

    Returns
    -------
    str
        A complete HTML document.
    """
    parts = [f"<h1>{html.escape(title)}</h1>",
             f"<p>Generated {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC.</p>"]
    if metrics or not sections:
        parts.append("<h2>Errors against ground truth</h2>")
        rows = [[name] + [c.format(figures) for c in KEY_COLUMNS] for name, figures in metrics.items()]
        parts.append(_table(["trajectory"] + [c.header for c in KEY_COLUMNS], rows))

    drift_rows = [[name, _number(d["length_m"], "{:g}"), str(d["segments"]), _number(d["trans_pct"], "{:.2f}"),
                   _number(d["rot_deg_per_m"], "{:.2f}")]
                  for name, figures in metrics.items() for d in figures.get("drift", [])]
    if drift_rows:
        parts.append("<h2>Drift over segments (KITTI style)</h2>")
        parts.append(_table(["trajectory", "length [m]", "segments", "translation [%]", "rotation [deg/m]"],
                            drift_rows))

    heading_rows = [[name, _number(f.get("heading_deg"), "{:.2f}"), _number(f.get("revolutions"), "{:.2f}"),
                     _number(f.get("heading_per_rev_deg"), "{:.2f}"), _number(f.get("heading_per_rev_pct"), "{:.3f}")]
                    for name, f in metrics.items()]
    if heading_rows:
        parts.append("<h2>Heading</h2>")
        parts.append(_table(["trajectory", "error at end [deg]", "revolutions", "per revolution [deg]",
                             "per revolution [%]"], heading_rows))

    leg_rows = [[name, str(leg["leg"]), "({:.3f}, {:.3f})".format(*leg["start"]),
                 "({:.3f}, {:.3f})".format(*leg["end"]), _number(leg["actual_m"]), _number(leg["estimated_m"]),
                 _number(leg["error_pct"], "{:.2f}"), _number(leg["relative_error_pct"], "{:.2f}")]
                for name, figures in metrics.items() for leg in figures.get("legs", [])]
    if leg_rows:
        parts.append("<h2>Legs between turns</h2>")
        parts.append(_table(["trajectory", "leg", "start (x, y) [m]", "end (x, y) [m]", "actual [m]",
                             "estimated [m]", "length error [%]", "relative error [%]"], leg_rows))

    if frontend:
        parts.append("<h2>Visual frontend</h2>")
        parts.append(_table(["figure", "value"], [[k, str(v)] for k, v in frontend.items()]))

    for heading, headers, rows, notes in sections or []:
        parts.append(f"<h2>{html.escape(heading)}</h2>")
        parts.append(_table(headers, rows))
        parts.extend(f"<p>{html.escape(note)}</p>" for note in notes)

    if images:
        parts.append("<h2>Figures</h2>")
        parts.extend(_image(caption, png) for caption, png in images.items())

    parts.append("<h2>Configuration</h2>")
    parts.append(f"<pre>{html.escape(yaml.safe_dump(config, sort_keys=False) if config else '(none)')}</pre>")
    body = "\n".join(parts)
    return (f'<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
            f"<title>{html.escape(title)}</title>\n<style>{_STYLE}</style>\n</head>\n<body>\n{body}\n"
            f"</body>\n</html>\n")


def write_report(path: str | Path, title: str, config: dict, metrics: dict[str, dict],
                 images: dict[str, str | Path], frontend: dict | None = None, sections: list | None = None) -> Path:
    """Render a report with the given PNG files embedded and write it atomically to ``path``."""
    pngs = {caption: Path(p).read_bytes() for caption, p in images.items()}
    text = render_report(title, config, metrics, pngs, frontend, sections)
    logger.debug("wrote %s", path)
    return write_atomic(path, text)
