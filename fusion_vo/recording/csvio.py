"""Strict CSV reading for the recording streams.

Every row must have the expected number of numeric columns; the first column is an integer timestamp in
nanoseconds that increases strictly. Anything else is an :class:`~fusion_vo.errors.InputError` naming the
file and the 1-based line. Lines starting with ``#`` and blank lines are skipped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fusion_vo.errors import InputError, check_file


@dataclass
class Table:
    """Rows of a numeric CSV file: ``t_ns`` (N,) int64, ``values`` (N, C) float64, ``lines`` (N,) int."""

    t_ns: np.ndarray
    values: np.ndarray
    lines: np.ndarray

    @property
    def t(self) -> np.ndarray:
        """Timestamps in seconds."""
        return self.t_ns.astype(np.float64) * 1e-9

    def __len__(self) -> int:
        return len(self.t_ns)


def read_table(path: str | Path, columns: int | tuple[int, int], what: str = "values",
               require_increasing: bool = True, allow_nan: bool = False) -> Table:
    """Read ``timestamp [ns], v1, v2, ...`` rows.

    Parameters
    ----------
    path : path of the CSV file.
    columns : number of value columns after the timestamp, or ``(min, max)``; extra columns beyond
        ``max`` are ignored.
    what : name of the values, for error messages.
    require_increasing : raise on duplicate or decreasing timestamps.
    allow_nan : keep ``nan`` values (for streams whose reader skips and counts such rows) instead of
        raising; infinite values still raise.
    """
    path = check_file(path)
    lo, hi = (columns, columns) if isinstance(columns, int) else columns
    ts: list[int] = []
    rows: list[list[float]] = []
    lines: list[int] = []
    width = None
    try:
        fh = open(path, encoding="utf-8")
    except OSError as exc:
        raise InputError(f"cannot read file ({exc.strerror})", path) from None
    with fh:
        try:
            for lineno, raw in enumerate(fh, start=1):
                s = raw.strip()
                if not s or s.startswith("#"):
                    continue
                parts = s.split(",")
                n = len(parts) - 1
                if n < lo:
                    raise InputError(f"expected a timestamp and {lo} {what}, found {len(parts)} fields", path, lineno)
                n = min(n, hi)
                if width is None:
                    width = n
                elif n != width:
                    raise InputError(f"expected {width + 1} fields like the rows above, found {len(parts)}", path, lineno)
                try:
                    t = int(parts[0])
                except ValueError:
                    try:  # tolerate '1.6e18'-style timestamps if they are integral
                        tf = float(parts[0])
                        if not math.isfinite(tf) or tf != int(tf):
                            raise ValueError
                        t = int(tf)
                    except ValueError:
                        raise InputError(f"timestamp '{parts[0].strip()}' is not an integer number of nanoseconds", path, lineno) from None
                _check_range(t, path, lineno)
                try:
                    vals = [float(p) for p in parts[1 : n + 1]]
                except ValueError:
                    bad = next(p for p in parts[1 : n + 1] if not _is_float(p))
                    raise InputError(f"'{bad.strip()}' is not a number", path, lineno) from None
                if not all(math.isfinite(v) or (allow_nan and math.isnan(v)) for v in vals):
                    raise InputError("NaN or infinite value", path, lineno)
                if require_increasing and ts and t <= ts[-1]:
                    kind = "duplicate" if t == ts[-1] else "decreasing"
                    raise InputError(f"{kind} timestamp {t} (previous row has {ts[-1]}); timestamps must increase", path, lineno)
                ts.append(t)
                rows.append(vals)
                lines.append(lineno)
        except UnicodeDecodeError:
            raise InputError("not a text CSV file", path) from None
    width = width if width is not None else lo
    values = np.array(rows, dtype=np.float64).reshape(len(rows), width)
    return Table(np.array(ts, dtype=np.int64), values, np.array(lines, dtype=np.int64))


def read_frame_list(path: str | Path) -> tuple[np.ndarray, list[str], np.ndarray]:
    """Read ``cam0/data.csv``: ``timestamp [ns], filename`` rows; returns (t_ns, names, lines)."""
    path = check_file(path)
    ts: list[int] = []
    names: list[str] = []
    lines: list[int] = []
    try:
        with open(path, encoding="utf-8") as fh:
            for lineno, raw in enumerate(fh, start=1):
                s = raw.strip()
                if not s or s.startswith("#"):
                    continue
                parts = [p.strip() for p in s.split(",")]
                if len(parts) < 2 or not parts[1]:
                    raise InputError("expected 'timestamp,filename'", path, lineno)
                try:
                    t = int(parts[0])
                except ValueError:
                    raise InputError(f"timestamp '{parts[0]}' is not an integer number of nanoseconds", path, lineno) from None
                _check_range(t, path, lineno)
                if ts and t <= ts[-1]:
                    kind = "duplicate" if t == ts[-1] else "decreasing"
                    raise InputError(f"{kind} timestamp {t} (previous row has {ts[-1]}); timestamps must increase", path, lineno)
                ts.append(t)
                names.append(parts[1])
                lines.append(lineno)
    except UnicodeDecodeError:
        raise InputError("not a text CSV file", path) from None
    except OSError as exc:
        raise InputError(f"cannot read file ({exc.strerror})", path) from None
    return np.array(ts, dtype=np.int64), names, np.array(lines, dtype=np.int64)


def _check_range(t: int, path: Path, lineno: int) -> int:
    if not 0 <= t < 2**63:
        raise InputError(f"timestamp {t} is outside the range of nanosecond timestamps (0 to 2^63)", path, lineno)
    return t


def _is_float(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False
