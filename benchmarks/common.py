"""What the benchmarks share: their command line, the recordings they generate or reuse, timing, tables.

Every benchmark is a script run from the repository root (``python benchmarks/NAME.py --help``) that imports
the installed ``fusion_vo`` (and ``frontends``) and this module only. Recordings are generated into a
working folder (``--out DIR``, default a temporary folder removed at the end) unless a recording of the same
profile, seed and options is already there, so that ``--out`` keeps them for the next run; a folder of
recordings made elsewhere (``fusion-vo simulate DIR/NAME --standard NAME``) is reused the same way.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import statistics
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import numpy as np
import yaml

from fusion_vo.config import RunConfig, load_config, validate_config
from fusion_vo.errors import InputError
from fusion_vo.evaluation.gps import score_track
from fusion_vo.evaluation.metrics import align_se2, ape_rmse, associate, planar_trajectory
from fusion_vo.measurements import GpsData, PoseData
from fusion_vo.recording.rosbag import import_bag, parse_static_tf
from fusion_vo.simulation.generate import SimulationOptions, simulate
from fusion_vo.simulation.standard import STANDARD

#: robot_localization's test bags (BSD), kept with the tests
ROBOT_LOGS = Path(__file__).resolve().parents[1] / "tests" / "data" / "robot_localization"
HUSKY_BAG = ROBOT_LOGS / "test1.bag"
JACKAL_BAG = ROBOT_LOGS / "test2.bag"
#: base_link -> imu_link of robot_localization's test_ekf_localization_node_bag1.test (the IMU lies on its side)
HUSKY_IMU_TF = "0 -0.3 0.52 -1.570796327 0 1.570796327 base_link imu_link"
#: the fused trajectories, in the order the tables print them
FUSED = ("ekf", "ekf_smoothed", "gtsam", "gtsam_online")


# ------------------------------------------------------------------------------------------- command line
def fail(message: str) -> None:
    """Stop with a one-line error on standard error and exit status 2, as a usage error does."""
    print(f"{Path(sys.argv[0]).name}: error: {message}", file=sys.stderr)
    raise SystemExit(2)


def parser(doc: str) -> argparse.ArgumentParser:
    """An argument parser whose ``--help`` prints the benchmark's docstring (``doc``) in full."""
    return argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)


def add_out(ap: argparse.ArgumentParser) -> None:
    """``--out DIR``: where recordings and runs are kept (and found again)."""
    ap.add_argument("--out", type=Path, help="keep (and reuse) the recordings and runs here (default: a temporary "
                                             "folder, removed at the end)")


def add_settings(ap: argparse.ArgumentParser) -> None:
    """``--config FILE`` and ``--set KEY=VALUE``: the run configuration, as ``fusion-vo run -c`` reads it."""
    ap.add_argument("--config", "-c", type=Path, help="YAML run configuration, as for fusion-vo run -c")
    ap.add_argument("--set", dest="settings", action="append", default=[], metavar="KEY=VALUE",
                    help="one option of the run configuration by its dotted path, the value in YAML, e.g. "
                         "fusion.visual_frame_error=0.5 or odometry.range_smoothing=false (repeatable)")


def setting(text: str) -> tuple[list[str], object]:
    """``"a.b.c=VALUE"`` as (``["a", "b", "c"]``, the YAML value)."""
    key, sep, value = text.partition("=")
    if not sep or not key.strip():
        raise argparse.ArgumentTypeError(f"{text!r}: expected KEY=VALUE")
    return key.strip().split("."), yaml.safe_load(value)


def with_settings(data: dict, settings: Sequence[str]) -> dict:
    """``data`` (a configuration mapping) with each ``KEY=VALUE`` of ``settings`` set."""
    out = yaml.safe_load(yaml.safe_dump(data))  # a deep copy of plain values
    for text in settings:
        path, value = setting(text)
        node = out
        for part in path[:-1]:
            node = node.setdefault(part, {})
        node[path[-1]] = value
    return out


def run_config(args: argparse.Namespace, **fixed) -> RunConfig:
    """The :class:`~fusion_vo.config.RunConfig` of ``--config`` and ``--set``, with ``fixed`` options on top
    (e.g. ``backend="all"``), validated as ``fusion-vo run`` validates it."""
    try:
        base = load_config(getattr(args, "config", None)).to_dict()
        data = with_settings({**base, **fixed}, getattr(args, "settings", []))
        return validate_config(data, getattr(args, "config", None))
    except (InputError, argparse.ArgumentTypeError) as exc:
        fail(str(exc))


def fusion_settings(args: argparse.Namespace) -> dict:
    """The ``fusion`` section of ``--config`` and ``--set`` as a mapping (for benchmarks that fuse streams
    directly, and change it with :func:`with_settings`)."""
    return run_config(args).fusion.to_dict()


def describe_settings(args: argparse.Namespace) -> str:
    """The configuration given on the command line, for a table's title."""
    parts = ([f"-c {args.config}"] if getattr(args, "config", None) else []) + list(getattr(args, "settings", []))
    return "default configuration" if not parts else "configuration " + " ".join(parts)


# ------------------------------------------------------------------------------------------- recordings
@contextlib.contextmanager
def work_dir(out: Path | None, prefix: str = "fusion-vo-bench-") -> Iterator[Path]:
    """``out`` (created), or a temporary folder removed at the end."""
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        yield out
        return
    folder = Path(tempfile.mkdtemp(prefix=prefix))
    try:
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def recording(root: Path, folder: str, profile: str, seed: int, options: dict) -> Path:
    """``root/folder``, generated unless it already holds a recording of ``profile``, ``seed`` and ``options``."""
    seq = root / folder
    info = seq / "simulation.yaml"
    if info.exists():
        stored = yaml.safe_load(info.read_text())
        wanted = SimulationOptions.from_dict({**SimulationOptions().model_dump(), **options}).model_dump(mode="json")
        if stored.get("profile") == profile and stored.get("seed") == seed and stored.get("options") == wanted:
            return seq
    print(f"generating {folder} ...", flush=True)
    return simulate(seq, profile=profile, seed=seed, **options)


def standard(root: Path, name: str, seed_offset: int = 0, suffix: str = "", **changes) -> Path:
    """The standard recording ``name`` (``fusion_vo.simulation.standard``) in ``root``, with its seed moved by
    ``seed_offset`` and options changed by ``changes`` (folder ``name`` + ``suffix``)."""
    profile, seed, options, _ = STANDARD[name]
    return recording(root, name + suffix, profile, seed + seed_offset, {**options, **changes})


def names(text: str | None, default: Sequence[str]) -> list[str]:
    """Comma-separated standard recording names (``default`` when ``text`` is empty), each checked."""
    chosen = [n.strip() for n in text.split(",") if n.strip()] if text else list(default)
    unknown = [n for n in chosen if n not in STANDARD]
    if unknown:
        fail(f"unknown standard recording(s) {', '.join(unknown)} (see datasets/generated.md)")
    return chosen


def import_husky(folder: Path, bag: Path = HUSKY_BAG) -> Path:
    """robot_localization's Husky bag imported into ``folder`` (unless there) with its IMU mounting."""
    if not (folder / "imu0").is_dir():
        import_bag(bag, folder, static_tfs=[parse_static_tf(HUSKY_IMU_TF)], overwrite=True)
    return folder


# ------------------------------------------------------------------------------------------- scoring
def ate_against(rec) -> Callable[[PoseData], float]:
    """``ate(track)``: the ATE [mm] of a track against ``rec``'s ground truth, after SE(2) alignment."""
    from fusion_vo.evaluation.metrics import align_se2, ape_rmse, associate, planar_trajectory

    gt = rec.groundtruth()
    reference = planar_trajectory(gt.t, gt.xyyaw[:, 0], gt.xyyaw[:, 1], gt.xyyaw[:, 2])

    def ate(track: PoseData) -> float:
        est = planar_trajectory(track.t, track.xyyaw[:, 0], track.xyyaw[:, 1], track.xyyaw[:, 2])
        ref, est = associate(reference, est)
        return ape_rmse(ref, align_se2(ref, est)) * 1e3

    return ate


def gps_rms(track: PoseData, gps: GpsData) -> tuple[float, float]:
    """RMS and largest distance [m] of a track's antenna to the fixes after the robust SE(2) alignment that
    ``fusion-vo evaluate`` makes for a recording without ground truth."""
    score = score_track(track.t, track.xyyaw, gps, fused=False)
    e = score.errors
    return float(np.sqrt(np.mean(e**2))), float(e.max())


# ------------------------------------------------------------------------------------------- timing, tables
def load() -> str:
    """The machine's 1-minute load average, for the line that says under which load a figure was measured."""
    return f"{os.getloadavg()[0]:.2f}"


def cpu_seconds(fn: Callable[[], object]) -> tuple[float, object]:
    """CPU seconds of this process spent in ``fn()``, and its result."""
    start = time.process_time()
    out = fn()
    return time.process_time() - start, out


def span(values: Sequence[float], fmt: str = ".2f") -> str:
    """The median of ``values`` and, with more than one, their range: ``"3.10 (2.90-3.40)"``."""
    med = statistics.median(values)
    if len(values) == 1:
        return format(med, fmt)
    return f"{format(med, fmt)} ({format(min(values), fmt)}-{format(max(values), fmt)})"


def table(headers: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """A Markdown table."""
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def mm(values: Sequence[float], fmt: str = ".3f") -> str:
    """``"0.244 / 0.240 / 0.243 / 0.246"``: figures of the fused tracks in one cell."""
    return " / ".join(format(v, fmt) for v in values)


class Stages:
    """Wall and CPU seconds of the functions :meth:`wrap` times, summed per stage name; a stage's time excludes
    that of the stages called inside it (the evaluation's metrics inside the evaluation, say). :meth:`restore`
    puts the functions back."""

    def __init__(self):
        self.wall: dict[str, float] = defaultdict(float)
        self.cpu: dict[str, float] = defaultdict(float)
        self._stack: list[list[float]] = []  # per open stage: time spent in the stages inside it
        self._wrapped: list = []  # (module, attribute, original) to restore

    def wrap(self, module, attribute: str, stage: str) -> None:
        inner = getattr(module, attribute)
        self._wrapped.append((module, attribute, inner))

        def timed(*a, **kw):
            self._stack.append([0.0, 0.0])
            w, c = time.perf_counter(), time.process_time()
            try:
                return inner(*a, **kw)
            finally:
                dw, dc = time.perf_counter() - w, time.process_time() - c
                nested = self._stack.pop()
                self.wall[stage] += dw - nested[0]
                self.cpu[stage] += dc - nested[1]
                if self._stack:
                    self._stack[-1][0] += dw
                    self._stack[-1][1] += dc

        setattr(module, attribute, timed)

    def restore(self) -> None:
        for module, attribute, inner in reversed(self._wrapped):
            setattr(module, attribute, inner)
        self._wrapped.clear()


def ate_mm(truth: PoseData, track: PoseData) -> float:
    """ATE [mm] of ``track`` against ``truth``: the RMS position error after the SE(2) alignment that minimises
    it, over the track's poses paired with the truth in time (:func:`fusion_vo.evaluation.metrics.associate`)."""
    reference = planar_trajectory(truth.t, *truth.xyyaw.T)
    est = planar_trajectory(track.t, *track.xyyaw.T)
    reference, est = associate(reference, est)
    return float(ape_rmse(reference, align_se2(reference, est)) * 1e3)
