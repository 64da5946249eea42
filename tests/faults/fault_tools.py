"""Helpers of the fault-injection tests: run the command in-process, snapshot folders, check errors."""

from __future__ import annotations

import os
from pathlib import Path

from fusion_vo.cli.main import main
from fusion_vo.simulation import simulate

#: a 160 x 120 camera over 5 cm of straight drive: 33 frames, most of which the KLT frontend tracks
SMALL = {"width": 160, "height": 120, "fu": 200.0, "fv": 200.0, "cu": 79.5, "cv": 59.5, "supersample": 1,
         "length": 0.05, "gt_rate": 50.0, "imu_rate": 100.0}


def make_pristine(path: Path) -> Path:
    """The unbroken recording of the fault tests (straight drive, seed 4, :data:`SMALL`), written to ``path``."""
    return simulate(path, profile="straight", seed=4, **SMALL)


def snapshot(root: Path, skip: Path | None = None) -> dict[str, tuple]:
    """Every path under ``root`` (except under ``skip``) with its type, size, mode and modification time."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        here = Path(dirpath)
        if skip is not None and (here == skip or skip in here.parents):
            dirnames[:] = []
            continue
        for name in dirnames + filenames:
            p = here / name
            if skip is not None and p == skip:
                continue
            st = os.lstat(p)
            out[str(p.relative_to(root))] = (st.st_mode, st.st_size if not p.is_dir() else 0, st.st_mtime_ns)
    return out


def cli(capsys, *args: str) -> tuple[int, str, str]:
    """Run ``fusion-vo ARGS`` in this process; returns (status, stdout, stderr). A traceback fails the test.

    A usage error (argparse exits) gives its exit status like any other error."""
    try:
        status = main([str(a) for a in args])
    except SystemExit as exc:
        status = exc.code
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    return status, captured.out, captured.err


def assert_error(status: int, err: str, *fragments: str) -> None:
    """Exit status 2 and a single line of error that contains every fragment."""
    assert status == 2, err
    lines = [ln for ln in err.splitlines() if ln.startswith("fusion-vo")]
    assert len(lines) == 1, err
    for f in fragments:
        assert f in lines[0], f"{f!r} not in {lines[0]!r}"
