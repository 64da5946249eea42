"""Write a recording folder in the layout of ``datasets/README.md`` (the one writer; the reader is
:mod:`fusion_vo.recording.reader`).

:class:`RecordingWriter` is used by ``fusion-vo simulate`` and ``fusion-vo import-bag``. Its guarantees:

* The folder appears complete or not at all: everything is written into a hidden staging folder beside
  the target and moved into place in one rename when the writer commits. An error or an interrupt
  (Ctrl-C, SIGTERM) removes the staging folder and leaves the target as it was.
* It never deletes what fusion-vo did not write: an existing target is replaced only when it is empty or
  holds the marker file ``.fusion-vo-recording`` that the writer leaves in every recording it makes;
  anything else needs ``force``. The current folder, a folder above it, a folder holding an input of
  the command and a folder inside an input are never replaced, even with ``force``.
* Every stream it writes reads back with :class:`~fusion_vo.recording.Recording`: integer nanosecond
  timestamps that increase strictly, finite numbers, frame names relative to ``cam0/data/``.
* Files and folders follow the umask, like any file the user creates.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Iterable, Sequence

import cv2
import numpy as np
import yaml

from fusion_vo.outputs import OutputFolder, check_replaceable, make_folder, write_atomic

#: marker file of a recording written by fusion-vo (its presence allows replacing the folder)
MARKER = ".fusion-vo-recording"


def check_target(out: str | Path, force: bool = False, inputs: Iterable[str | Path] = ()) -> None:
    """Raise :class:`~fusion_vo.errors.InputError` unless :class:`RecordingWriter` may write ``out``.

    A command calls it before its work, so that a bad target is reported at once.
    """
    check_replaceable(out, MARKER, force, inputs, "recording folder")


class RecordingWriter:
    """A recording folder being written; use as a context manager and call :meth:`commit` at the end.

    Parameters
    ----------
    out : the recording folder to create (or replace, see the module's rules).
    force : replace a non-empty folder that fusion-vo did not write.
    inputs : paths the command reads (the output may not hold them).
    source : one line saying what wrote the recording, stored in the marker file.

    Attributes
    ----------
    root : Path
        The folder to write into while the writer is open (a staging folder named like ``out``).
    """

    def __init__(self, out: str | Path, force: bool = False, inputs: Iterable[str | Path] = (), source: str = ""):
        self.out = Path(out)
        self._folder = OutputFolder(self.out, MARKER, force=force, inputs=inputs, what="recording folder",
                                    marker_text=f"recording written by fusion-vo{': ' + source if source else ''}\n")

    def __enter__(self) -> "RecordingWriter":
        self._folder.__enter__()
        return self

    def __exit__(self, exc_type, exc, tb):
        return self._folder.__exit__(exc_type, exc, tb)

    @property
    def root(self) -> Path:
        assert self._folder.path is not None, "the writer is not open"
        return self._folder.path

    def commit(self) -> Path:
        """Move the finished recording into place; returns its final path."""
        return self._folder.commit()

    # ------------------------------------------------------------------ streams
    def csv(self, relpath: str, header: str, t_ns: np.ndarray, rows, fmt: str | Sequence[str]) -> Path:
        """Write a stream ``relpath`` (e.g. ``imu0/data.csv``); see :func:`write_csv`."""
        return write_csv(self.root / relpath, header, t_ns, rows, fmt)

    def lines(self, relpath: str, header: str, rows: Sequence[str]) -> Path:
        """Write a stream of rows already formatted (``timestamp,...``); see :func:`write_lines`."""
        return write_lines(self.root / relpath, header, rows)

    def yaml(self, relpath: str, data: dict, comments: Sequence[str] = ()) -> Path:
        """Write a ``sensor.yaml`` (or any YAML file) ``relpath``; see :func:`write_yaml`."""
        return write_yaml(self.root / relpath, data, comments)

    def image(self, name: str, image: np.ndarray, params: Sequence[int] = ()) -> str:
        """Write ``cam0/data/NAME`` (PNG); returns ``name`` for the frame list."""
        write_image(self.root / "cam0" / "data" / name, image, params)
        return name

    def frame_list(self, t_ns: np.ndarray, names: Sequence[str]) -> Path:
        """Write ``cam0/data.csv``: one row ``timestamp,filename`` per frame."""
        for name in names:
            if "," in name or Path(name).is_absolute() or ".." in Path(name).parts:
                raise ValueError(f"frame name {name!r} must be a plain name inside cam0/data/")
        return self.csv("cam0/data.csv", "#timestamp [ns],filename", np.asarray(t_ns, dtype=np.int64),
                        [(n,) for n in names], "%s")


def write_csv(path: Path, header: str, t_ns, rows, fmt: str | Sequence[str]) -> Path:
    """Write ``timestamp,v1,v2,...`` rows (``fmt``: one %-format for all values or one per column).

    Raises
    ------
    ValueError
        If the timestamps are not integers that increase strictly, or a number is not finite: the writer
        never writes a file its reader would reject.
    """
    t = np.asarray(t_ns)
    if len(t) and not np.issubdtype(t.dtype, np.integer):
        raise ValueError(f"{path.name}: timestamps must be integer nanoseconds")
    t = t.astype(np.int64)
    if len(t) > 1 and np.any(np.diff(t) <= 0):
        i = int(np.flatnonzero(np.diff(t) <= 0)[0])
        raise ValueError(f"{path.name}: timestamp {t[i + 1]} does not follow {t[i]}; timestamps must increase")
    lines = [header]
    for ti, row in zip(t, rows):
        row = list(row)
        fmts = [fmt] * len(row) if isinstance(fmt, str) else list(fmt)
        for v in row:
            if isinstance(v, (float, np.floating)) and not math.isfinite(v):
                raise ValueError(f"{path.name}: non-finite value at timestamp {ti}")
        lines.append(f"{int(ti)}," + ",".join(f % v for f, v in zip(fmts, row)))
    make_folder(path.parent)
    return write_atomic(path, "\n".join(lines) + "\n")


def write_lines(path: Path, header: str, rows: Sequence[str]) -> Path:
    """Write rows formatted by the stream's own module (``timestamp,...`` each), under ``header``.

    Raises
    ------
    ValueError
        If a row's timestamp is not an integer or the timestamps do not increase strictly.
    """
    previous = None
    for row in rows:
        try:
            t = int(row.split(",", 1)[0])
        except ValueError:
            raise ValueError(f"{path.name}: row {row!r} does not start with an integer timestamp") from None
        if previous is not None and t <= previous:
            raise ValueError(f"{path.name}: timestamp {t} does not follow {previous}; timestamps must increase")
        previous = t
    make_folder(path.parent)
    return write_atomic(path, "\n".join([header, *rows]) + "\n")


def write_yaml(path: Path, data: dict, comments: Sequence[str] = ()) -> Path:
    """Write a YAML mapping, with ``# comment`` lines on top."""
    head = "".join(f"# {c}\n" for c in comments)
    make_folder(path.parent)
    return write_atomic(path, head + yaml.safe_dump(data, sort_keys=False, default_flow_style=None))


def write_image(path: Path, image: np.ndarray, params: Sequence[int] = ()) -> Path:
    """Encode an image (format from the extension) and write it; works for any path the OS accepts."""
    ok, buf = cv2.imencode(path.suffix or ".png", image, list(params))
    if not ok:
        raise ValueError(f"cannot encode {path.name}")
    make_folder(path.parent)
    path.write_bytes(buf.tobytes())  # inside the staging folder: it appears only when the recording does
    return path
