"""Shared pieces of the example scripts: command-line options, output folder, plain tables.

Every example takes ``--out DIR`` (where generated recordings and outputs go; a temporary folder that is
removed at the end if omitted), ``--quick`` (shorter recordings and fewer variants, for a smoke test)
and ``--seed N`` (the simulator's seed; the same seed gives the same recordings and figures). Examples
built on a standard generated recording (``datasets/generated.md``) regenerate exactly that recording
unless ``--seed`` or ``--quick`` changes it.

Tables are printed as plain text: a title line, a header line, a rule of dashes and one line per row,
columns separated by at least two spaces (cells never contain two spaces in a row), so that they can be
pasted into a README or split back into cells by a program.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import shutil
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

from fusion_vo.evaluation.metrics import planar_trajectory
from fusion_vo.geometry import se2
from fusion_vo.measurements import PoseData
from fusion_vo.simulation import simulate
from fusion_vo.simulation.standard import STANDARD

FRONTENDS = ("klt", "features")

#: simulator options of the lighting variants of thesis table 5.1: even light; a saturated specular
#: highlight fixed in the image (a lamp's reflection on a glossy floor); a quarter of the exposure with
#: three times the sensor noise
LIGHTING = {
    "good light": {},
    "spotlights": {"highlight_radius": 40.0},
    "dark": {"gain": 0.25, "noise": 3.0},
}


#: simulator option of ``--realistic``: the independent camera (:mod:`fusion_vo.simulation.realistic`), a
#: four-term barrel lens whose ``sensor.yaml`` holds the fitted three-term model, defocus, motion blur,
#: noise and auto-exposure, over the same floor photograph
REALISTIC = {"lens": "polynomial", "checker_size": 0.0, "defocus": 1.0}

#: the lighting variants through the independent camera: "dark" is a quarter of the brightness with three
#: times the read noise and no auto-exposure to undo it; the independent renderer has no specular
#: highlight, so "spotlights" has no counterpart (None)
REALISTIC_LIGHTING = {
    "good light": {},
    "spotlights": None,
    "dark": {"brightness": 42.5, "auto_exposure": 0.0, "read_noise": 4.5},
}


def realistic_options(light: str, texture: str = "gravel") -> dict | None:
    """Simulator options of ``--realistic`` for a lighting variant and floor photograph (None: no counterpart).

    As the realistic standard recordings, the frames are exposed for 4 ms with motion blur.
    """
    lighting = REALISTIC_LIGHTING[light]
    if lighting is None:
        return None
    return {"realistic": {**REALISTIC, "texture": texture, **lighting}, "exposure_time": 0.004, "blur_samples": 3}


def example_parser(description: str) -> argparse.ArgumentParser:
    """An argument parser with the options every example shares (``--out``, ``--quick``, ``--seed``,
    ``--realistic``)."""
    parser = argparse.ArgumentParser(description=description,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=None, metavar="DIR",
                        help="folder for the generated recordings and outputs (default: a temporary folder, "
                             "removed at the end)")
    parser.add_argument("--quick", action="store_true",
                        help="shorter recordings and fewer variants (a fast smoke run)")
    parser.add_argument("--seed", type=int, default=None, metavar="N",
                        help="seed of the generated recordings (default: the standard recording's seed, or 0)")
    parser.add_argument("--realistic", action="store_true",
                        help="render through the independent camera (a barrel lens the estimator only "
                             "approximates, defocus, motion blur, noise, auto-exposure) instead of the "
                             "estimator's own camera model")
    return parser


def generate(name: str, out_dir: Path, seed: int | None = None, **overrides) -> Path:
    """Generate the standard recording ``name`` (:mod:`fusion_vo.simulation.standard`) into ``out_dir``.

    ``seed`` replaces the standard seed and ``overrides`` its simulator options (a shorter drive for a
    quick run); with neither, the recording is exactly the standard one.
    """
    profile, standard_seed, options, _ = STANDARD[name]
    return simulate(out_dir, profile=profile, seed=standard_seed if seed is None else seed,
                    **{**options, **overrides})


@contextlib.contextmanager
def output_dir(out: Path | None) -> Iterator[Path]:
    """``out`` (created if needed), or a temporary folder that is removed afterwards."""
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        yield out
        return
    tmp = Path(tempfile.mkdtemp(prefix="fusion-vo-example-"))
    try:
        yield tmp
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def fmt(value: float | None, digits: int = 2) -> str:
    """A number with ``digits`` decimals, or ``-`` where it is missing or not finite."""
    if value is None or not math.isfinite(float(value)):
        return "-"
    return f"{float(value):.{digits}f}"


def format_table(title: str, headers: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A plain-text table: title, header, rule, rows; cells right-aligned except the first column."""
    cells = [list(map(str, headers))] + [list(map(str, r)) for r in rows]
    widths = [max(len(row[i]) for row in cells) for i in range(len(headers))]

    def line(row: Sequence[str]) -> str:
        parts = [row[0].ljust(widths[0])] + [c.rjust(w) for c, w in zip(row[1:], widths[1:])]
        return "  ".join(parts).rstrip()

    rule = "  ".join("-" * w for w in widths)
    return "\n".join([title, line(cells[0]), rule] + [line(r) for r in cells[1:]])


def to_trajectory(poses: PoseData, name: str | None = None):
    """A planar :class:`evo.core.trajectory.PoseTrajectory3D` of a :class:`PoseData` track."""
    return planar_trajectory(poses.t, poses.xyyaw[:, 0], poses.xyyaw[:, 1], poses.xyyaw[:, 2], name=name)


def pose_at(gt: PoseData, t: float) -> np.ndarray:
    """Ground-truth ``(x, y, yaw)`` at time ``t`` (linear interpolation, unwrapped yaw)."""
    yaw = np.unwrap(gt.xyyaw[:, 2])
    return np.array([np.interp(t, gt.t, gt.xyyaw[:, 0]), np.interp(t, gt.t, gt.xyyaw[:, 1]),
                     float(se2.wrap_angle(np.interp(t, gt.t, yaw)))])


def true_twist(gt: PoseData, t0: float, t1: float) -> np.ndarray:
    """Ground-truth body twist ``(vx, vy, yaw rate)`` over ``[t0, t1]``: ``log(T(t0)^-1 T(t1)) / (t1 - t0)``.

    The same definition as the visual odometry's velocities, so the two compare like for like.
    """
    return se2.log(se2.between(pose_at(gt, t0), pose_at(gt, t1))) / (t1 - t0)
