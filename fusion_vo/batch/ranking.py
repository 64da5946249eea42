"""Ranking the parameter sets of a sweep by a metric of its results table."""

from __future__ import annotations

from fusion_vo.batch.columns import COLUMNS


def best_sets(frame, metric: str = "ate_m", trajectory: str | None = None):
    """Parameter sets ranked by the mean of ``metric`` over the recordings (best first).

    A set where any recording failed, or lacks the figure, ranks after every complete set.

    Returns
    -------
    (pandas.DataFrame, str)
        Columns ``parameter_set``, the swept keys, ``mean``, ``recordings``, ``failed``; and the
        trajectory used.
    """
    import pandas as pd

    ok = frame[frame["status"] == "ok"]
    if trajectory is None:
        names = list(dict.fromkeys(ok["trajectory"]))
        trajectory = "vo" if "vo" in names else (names[0] if names else "")
    keys = [c for c in frame.columns[len(COLUMNS) + 1:]]
    sets = frame.drop_duplicates("parameter_set")[["parameter_set", *keys]].set_index("parameter_set")
    n_rec = frame["recording"].nunique()
    chosen = ok[ok["trajectory"] == trajectory]
    stats = chosen.groupby("parameter_set")[metric].agg(["mean", "count"])
    failed = frame[frame["status"] != "ok"].groupby("parameter_set")["recording"].nunique()
    table = sets.join(stats, how="left").join(failed.rename("failed"), how="left")
    table["failed"] = table["failed"].fillna(0).astype(int)
    table["count"] = table["count"].fillna(0).astype(int)
    complete = (table["count"] == n_rec) & table["mean"].notna()
    table["_order"] = ~complete
    table = table.sort_values(["_order", "mean"], na_position="last").drop(columns="_order")
    table = table.rename(columns={"count": "recordings"}).reset_index()
    return pd.DataFrame(table), trajectory


def describe_set(frame, name: str) -> str:
    """``key=value, ...`` of one parameter set."""
    keys = [c for c in frame.columns[len(COLUMNS) + 1:]]
    row = frame[frame["parameter_set"] == name].iloc[0]
    return ", ".join(f"{k}={row[k]}" for k in keys)
