"""A logger that stopped for a while: shift the later rows of a recording's streams.

Used to reproduce a pause in every stream (a robot's logger stopped, then resumed) on a generated
recording, by the fault tests and by ``benchmarks/run_speed.py pause``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterable

#: the streams of a generated recording that carry time stamps
STREAMS = ("cam0/data.csv", "imu0/data.csv", "wheel0/data.csv", "state_groundtruth_estimate0/data.csv")


def pause(recording: str | Path, after_s: float, seconds: float, streams: Iterable[str] = STREAMS) -> None:
    """Shift every row of ``streams`` later than ``after_s`` into its stream by ``seconds``, in place.

    Parameters
    ----------
    recording : the recording folder.
    after_s : where the pause starts, in seconds after each stream's first row.
    seconds : the pause's length.
    streams : CSV files (relative to ``recording``) whose first column is the time in nanoseconds.
    """
    shift = int(seconds * 1e9)
    for name in streams:
        path = Path(recording) / name
        lines = path.read_text().splitlines()
        t0 = int(lines[1].split(",", 1)[0])
        rows = [lines[0]]
        for line in lines[1:]:
            t, rest = line.split(",", 1)
            t = int(t)
            if t - t0 >= after_s * 1e9:
                t += shift
            rows.append(f"{t},{rest}")
        path.write_text("\n".join(rows) + "\n")
