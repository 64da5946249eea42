"""Strict CSV reading for the recording streams.

Every row must have the expected number of numeric columns (more fields than the stream has, a trailing
comma included, are an error unless the caller ignores further columns, as the ground truth does); the
first column is an integer timestamp in nanoseconds (an optional sign and decimal digits, nothing else:
no ``1.6e18``, ``...0.0`` or ``1_600...``) that increases strictly. Anything else is an
:class:`~fusion_vo.errors.InputError` naming the file and the 1-based line. Lines starting with ``#`` and
blank lines are skipped; a UTF-8 byte order mark at the start of the file (Excel writes one) is dropped.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fusion_vo.errors import InputError, check_file

#: an integer timestamp: an optional sign and ASCII decimal digits (``int()`` alone would also take
#: ``1_600``, surrounding spaces and other scripts' digits)
_INTEGER = re.compile(r"[+-]?[0-9]+")


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
               require_increasing: bool = True, allow_nan: bool = False, ignore_extra: bool = False) -> Table:
    """Read ``timestamp [ns], v1, v2, ...`` rows.

    Parameters
    ----------
    path : path of the CSV file.
    columns : number of value columns after the timestamp, or ``(min, max)``; a row with more than
        ``max`` is an error naming the line (unless ``ignore_extra``).
    what : name of the values, for error messages.
    require_increasing : raise on duplicate or decreasing timestamps.
    allow_nan : keep ``nan`` values (for streams whose reader skips and counts such rows) instead of
        raising; infinite values still raise.
    ignore_extra : ignore columns beyond ``max`` (where the layout says further columns are ignored: the
        ground truth) instead of raising.
    """
    path = check_file(path)
    lo, hi = (columns, columns) if isinstance(columns, int) else columns
    ts: list[int] = []
    rows: list[list[float]] = []
    lines: list[int] = []
    width = None
    try:
        fh = open(path, encoding="utf-8-sig")  # -sig: a leading byte order mark is dropped
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
                if n > hi and not ignore_extra:
                    trailing = " (a trailing comma?)" if not parts[-1].strip() else ""
                    raise InputError(f"expected a timestamp and {_count(lo, hi)} {what}, found {len(parts)} "
                                     f"fields{trailing}", path, lineno)
                n = min(n, hi)
                if width is None:
                    width = n
                elif n != width:
                    raise InputError(f"expected {width + 1} fields like the rows above, found {len(parts)}", path, lineno)
                t = _timestamp(parts[0], path, lineno)
                try:
                    if "_" in raw:  # (one test a row; float() alone would take Python's digit separators)
                        vals = [_float(p) for p in parts[1 : n + 1]]
                    else:
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
            raise _not_text(path) from None
    width = width if width is not None else lo
    values = np.array(rows, dtype=np.float64).reshape(len(rows), width)
    return Table(np.array(ts, dtype=np.int64), values, np.array(lines, dtype=np.int64))


def _not_text(path: Path) -> InputError:
    """The error for a file that is not UTF-8 text, naming the line of its first byte that is not (found
    only on this path: reading decodes in blocks, ahead of the line being parsed)."""
    try:
        data = path.read_bytes()
        data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        return InputError(f"not a text CSV file: byte 0x{data[exc.start]:02x} is not UTF-8 (save the file as UTF-8)",
                          path, line)
    except OSError:
        pass
    return InputError("not a text CSV file", path)


def check_magnitude(tab: Table, path: str | Path, columns: slice, limit: float, what: str) -> None:
    """An :class:`InputError` naming the line of the first row with a value in ``columns`` larger than
    ``limit`` in magnitude (a physical range: beyond it a value is a corrupt row or a unit mix-up); NaN passes."""
    block = np.abs(tab.values[:, columns])
    with np.errstate(invalid="ignore"):
        bad = np.flatnonzero((block > limit).any(axis=1))
    if len(bad):
        i = int(bad[0])
        value = tab.values[i, columns][int(np.nanargmax(block[i]))]
        raise InputError(f"{what} {value:g} is beyond ±{limit:g}: not a physical value", path, int(tab.lines[i]))


def unit_quaternions(q: np.ndarray, lines: np.ndarray, path: Path, what: str) -> np.ndarray:
    """``q`` (rows w, x, y, z) normalised; a row whose norm is more than 0.05 from 1 is an error naming its line."""
    norms = np.linalg.norm(q, axis=1)
    bad = np.flatnonzero(np.abs(norms - 1.0) > 0.05)
    if len(bad):
        raise InputError(f"{what} has norm {norms[bad[0]]:.3f}, not 1", path, int(lines[bad[0]]))
    return q / norms[:, None]


def read_frame_list(path: str | Path) -> tuple[np.ndarray, list[str], np.ndarray]:
    """Read ``cam0/data.csv``: ``timestamp [ns], filename`` rows; returns (t_ns, names, lines)."""
    path = check_file(path)
    ts: list[int] = []
    names: list[str] = []
    lines: list[int] = []
    try:
        with open(path, encoding="utf-8-sig") as fh:  # -sig: a leading byte order mark is dropped
            for lineno, raw in enumerate(fh, start=1):
                s = raw.strip()
                if not s or s.startswith("#"):
                    continue
                parts = [p.strip() for p in s.split(",")]
                if len(parts) < 2 or not parts[1]:
                    raise InputError("expected 'timestamp,filename'", path, lineno)
                if len(parts) > 2:
                    trailing = " (a trailing comma?)" if not parts[-1] else ""
                    raise InputError(f"expected 2 fields 'timestamp,filename', found {len(parts)}{trailing}",
                                     path, lineno)
                t = _timestamp(parts[0], path, lineno)
                if ts and t <= ts[-1]:
                    kind = "duplicate" if t == ts[-1] else "decreasing"
                    raise InputError(f"{kind} timestamp {t} (previous row has {ts[-1]}); timestamps must increase", path, lineno)
                ts.append(t)
                names.append(parts[1])
                lines.append(lineno)
    except UnicodeDecodeError:
        raise _not_text(path) from None
    except OSError as exc:
        raise InputError(f"cannot read file ({exc.strerror})", path) from None
    return np.array(ts, dtype=np.int64), names, np.array(lines, dtype=np.int64)


def _count(lo: int, hi: int) -> str:
    return str(lo) if lo == hi else f"{lo} to {hi}"


def _timestamp(text: str, path: Path, lineno: int) -> int:
    """The integer nanosecond timestamp of a field: an optional sign and decimal digits, in range."""
    s = text.strip()
    if not (s.isascii() and s.isdigit()) and not _INTEGER.fullmatch(s):  # (the first test is the fast path)
        raise InputError(f"timestamp {s!r} is not an integer number of nanoseconds (an optional sign and "
                         "decimal digits only)", path, lineno)
    return _check_range(int(s), path, lineno)


def _check_range(t: int, path: Path, lineno: int) -> int:
    if not 0 <= t < 2**63:
        raise InputError(f"timestamp {t} is outside the range of nanosecond timestamps (0 to 2^63)", path, lineno)
    return t


def _float(s: str) -> float:
    """``float(s)``, without Python's digit separators (``1_000``): not a number in a CSV file."""
    if "_" in s:
        raise ValueError(s)
    return float(s)


def _is_float(s: str) -> bool:
    try:
        _float(s)
        return True
    except ValueError:
        return False
