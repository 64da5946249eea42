"""Terminal tables of metrics."""

from __future__ import annotations

COLUMNS = [("ate_m", "ATE [m]", "{:.4f}"), ("end_pct", "end [%]", "{:.3f}"),
           ("heading_deg", "heading [deg]", "{:.3f}"), ("rpe_1m_pct", "RPE/1 m [%]", "{:.3f}")]


def print_metrics(metrics: dict) -> None:
    """Print ``{trajectory: {key: value}}`` as a table (rich when available)."""
    try:
        from fusion_vo.evaluation import print_table  # the evaluation package's own, richer table

        print_table(metrics)
        return
    except ImportError:
        pass
    header = f"{'trajectory':<14}" + "".join(f"{title:>16}" for _, title, _ in COLUMNS)
    print(header)
    for name, m in metrics.items():
        cells = []
        for key, _, fmt in COLUMNS:
            v = m.get(key) if isinstance(m, dict) else None
            cells.append(f"{fmt.format(v) if isinstance(v, (int, float)) else '-':>16}")
        print(f"{name:<14}" + "".join(cells))
