"""The columns of a batch's results table (``results.csv``): what the command line's choices name.

Kept apart from :mod:`fusion_vo.batch.tasks`, which runs the pipeline, so that ``fusion-vo sweep --help``
lists the metrics without loading it.
"""

#: metric columns of the results table, taken from the run's ``metrics.json`` figures
METRICS = ("ate_m", "end_pct", "heading_deg", "rpe_1m_pct")
#: every column of the results table before the swept keys
COLUMNS = ("recording", "trajectory", "status", "error", *METRICS, "frames", "failed_frames", "seconds",
           "cached", "run_dir")
