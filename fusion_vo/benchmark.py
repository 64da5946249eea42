"""Speed of the visual odometry chain on a recording, beside the plain OpenCV script.

End to end (:func:`compare_end_to_end`): the wall time of :func:`fusion_vo.odometry.run_visual_odometry`
over the whole recording, decoding included, with one thread and with all threads, and the wall time of
the plain OpenCV script (:mod:`fusion_vo.baseline`: Shi-Tomasi corners, pyramidal LK, RANSAC
similarity, one frame at a time) over the same frames. The runs are interleaved and repeated, and each
ratio is taken between runs made next to each other, so that a shared machine's changing speed
affects both sides alike.

Where the time goes (:func:`time_frontend`), three timings per frontend, per frame:

``decode``     reading and decoding the PNG (``cv2.imread``)
``frontend``   the frontend's ``process`` on the decoded image
``geometry``   rectification is inside the frontend; this is the similarity -> body increment step

Times are CPU time of the process (``time.process_time``) with OpenCV and the BLAS libraries limited
to one thread, so the figures depend less on what else the machine is doing. Frames per second are reported with decode
included (the end-to-end figure) and excluded. Memory is
sampled as the process's resident set size after each quarter of the frames: flat in recording length
means the last quarter is no larger than the first.
"""

from __future__ import annotations

import json
import logging
import os
import resource
import statistics
import tempfile
import time
from contextlib import nullcontext
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import cv2

from frontends import make_frontend
from fusion_vo import baseline as plain_script
from fusion_vo.geometry.ground import GroundGeometry
from fusion_vo.config.odometry import available_cores
from fusion_vo.odometry import OdometryConfig, opencv_threads, run_visual_odometry
from fusion_vo.recording import Recording
from fusion_vo.recording.csvio import read_frame_list

log = logging.getLogger(__name__)

#: below this share of frame pairs tracked, a run's frames per second are not a speed (frames that
#: measured nothing, e.g. textureless ones, cost almost nothing) and its row says so instead of a rate
MIN_TRACKED = 0.5


def tracked_share(frames: int, failed: int) -> float:
    """The share of the ``frames - 1`` frame pairs of a run that were measured, from its failures."""
    return min(max(1.0 - failed / max(frames - 1, 1), 0.0), 1.0)


def not_a_speed(share: float) -> str:
    """What a row shows instead of a rate when fewer than :data:`MIN_TRACKED` of its frame pairs were tracked."""
    return f"not a speed: {100 * share:.0f} % of frame pairs tracked"


@dataclass
class FrontendTiming:
    """Per-frame timings [ms] of one frontend over a recording."""

    frontend: str
    frames: int
    decode_ms: float
    frontend_ms: float
    geometry_ms: float
    ok_fraction: float
    rss_mb: list = field(default_factory=list)

    @property
    def fps_end_to_end(self) -> float:
        return 1000.0 / (self.decode_ms + self.frontend_ms + self.geometry_ms)

    @property
    def fps_without_decode(self) -> float:
        return 1000.0 / (self.frontend_ms + self.geometry_ms)


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def time_frontend(sequence: str | Path, frontend: str, max_frames: int | None = None,
                  options: dict | None = None) -> FrontendTiming:
    """Time decode + frontend + geometry over the frames of a recording (one thread)."""
    rec = Recording(sequence)
    geometry = GroundGeometry(rec.camera)
    fe = make_frontend(frontend, options or {}, point_map=geometry.rectifier)
    n = len(rec) if max_frames is None else min(max_frames, len(rec))
    frames = rec.frames(stop=n)  # decoding happens in next(): timed as decode
    with opencv_threads(1):
        dec, fro, geo, ok, rss = _time_stages(frames, n, fe, geometry)
    return FrontendTiming(frontend, n, 1000 * dec / n, 1000 * fro / n, 1000 * geo / n,
                          ok / max(n - 1, 1), rss)


def _time_stages(frames, n, fe, geometry) -> tuple[float, float, float, int, list]:
    dec = fro = geo = 0.0
    ok = 0
    rss = []
    quarter = max(n // 4, 1)
    for i in range(n):
        a = time.process_time()
        frame = next(frames)
        b = time.process_time()
        motion = fe.process(frame.image, frame.t)
        c = time.process_time()
        if motion.ok:
            geometry.increment(motion)
            ok += 1
        d = time.process_time()
        dec += b - a
        fro += c - b
        geo += d - c
        if (i + 1) % quarter == 0:
            rss.append(round(_rss_mb(), 1))
    return dec, fro, geo, ok, rss


def format_timing(t: FrontendTiming) -> str:
    if t.ok_fraction < MIN_TRACKED:
        rate = f"{not_a_speed(t.ok_fraction)};"
    else:
        rate = (f"{t.fps_end_to_end:7.1f} frames/s end to end, {t.fps_without_decode:7.1f} without decode; "
                f"ok {100 * t.ok_fraction:5.1f} %;")
    return (f"{t.frontend:<9} {t.frames:5d} frames  decode {t.decode_ms:6.3f} ms  frontend {t.frontend_ms:6.3f} ms  "
            f"geometry {t.geometry_ms:6.3f} ms  ->  {rate} peak RSS by quarter {t.rss_mb} MB")


def summary_table(timings: list[FrontendTiming]) -> str:
    return "\n".join(format_timing(t) for t in timings)



# ---------------------------------------------------------------------- end to end, beside the baseline
#: ``run(seq) -> (results, wall seconds)`` of the plain OpenCV script (:func:`fusion_vo.baseline.run`)
BaselineRun = Callable[[str | Path], tuple[list, float]]


@dataclass
class EndToEnd:
    """Frames per second over repeated, interleaved runs on one recording.

    Attributes
    ----------
    name : str
        ``"plain OpenCV script"`` or the frontend's name.
    threads : int or None
        Threads given to fusion-vo (``None`` for the plain script, which uses OpenCV's default).
    frames : int
        Frames in the recording.
    fps : list of float
        Frames per second of each repeat, decoding included.
    ratio : list of float
        Each repeat's frames per second over the faster of the plain script's two runs (OpenCV's default
        threads, one thread) in the same repeat (empty for the script).
    failed : int
        Frames the run could not measure (last repeat).
    baseline : bool
        Whether this is the plain script.
    rss_mb : list of float
        Resident memory of the process after each quarter of the frames (last repeat; fusion-vo only).
    cpu_ms : list of float
        CPU time of the process per frame [ms] (all its threads), per repeat: less sensitive than the
        wall clock to other work on the machine.
    thread_ms : list of float
        CPU time per frame [ms] of the calling thread alone, per repeat: in fusion-vo the thread that
        tracks, which sets the pace with several threads (on an idle machine the wall time per frame
        cannot be shorter).
    """

    name: str
    threads: int | None
    frames: int
    fps: list = field(default_factory=list)
    ratio: list = field(default_factory=list)
    failed: int = 0
    baseline: bool = False
    rss_mb: list = field(default_factory=list)
    cpu_ms: list = field(default_factory=list)
    thread_ms: list = field(default_factory=list)

    @property
    def tracked(self) -> float:
        """The share of frame pairs measured (last repeat): below :data:`MIN_TRACKED` the rate is not a speed."""
        return tracked_share(self.frames, self.failed)

    @property
    def label(self) -> str:
        if self.baseline:
            if self.threads is None:
                return f"{self.name}, OpenCV's default threads ({cv2.getNumThreads()})"
            return f"{self.name}, OpenCV on {self.threads} thread{'s' if self.threads > 1 else ''}"
        return f"{self.name}, {self.threads} thread{'s' if self.threads > 1 else ''}"


def current_rss_mb() -> float:
    """Resident memory of this process now [MB] (Linux ``/proc``; the peak elsewhere)."""
    try:
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError):
        return _rss_mb()


def split_spec(spec: str) -> tuple[str, dict]:
    """A frontend as the benchmark names it, ``"klt"`` or ``'klt:{"fb_skip_ratio": 0.9}'`` (a frontend and
    its options as JSON), as ``(frontend, options)``."""
    name, _, options = spec.partition(":")
    return name, (json.loads(options) if options else {})


def time_run(sequence: str | Path, frontend: str, threads: int) -> tuple[float, int, list, float, float]:
    """Frames per second of visual odometry over a recording (wall clock, decoding included), failures,
    the resident memory after each quarter of the frames [MB], the CPU time per frame [ms] and that of
    the calling thread (the tracker) alone [ms]. ``frontend`` may carry options (:func:`split_spec`)."""
    frontend, options = split_spec(frontend)
    rec = Recording(sequence)
    n = len(rec)
    quarter = max(n // 4, 1)
    rss: list = []

    def progress(done: int, total: int) -> None:
        if done % quarter == 0 and len(rss) < 4:
            rss.append(round(current_rss_mb(), 1))

    cpu, own = time.process_time(), time.thread_time()
    result = run_visual_odometry(rec, OdometryConfig(frontend=frontend, threads=threads, frontend_options=options),
                                 progress=progress)
    cpu, own = time.process_time() - cpu, time.thread_time() - own
    return (n / result.elapsed_s, sum(result.failures.values()) + len(result.skipped), rss, 1000 * cpu / n,
            1000 * own / n)


def time_baseline(sequence: str | Path, baseline: BaselineRun, threads: int | None = None) -> tuple[float, int, float, float]:
    """Frames per second of the plain OpenCV script over a recording, the frame pairs it failed on, its
    CPU time per frame [ms] and that of the calling thread alone [ms].

    ``threads`` limits OpenCV's threads for the run (``None``: OpenCV's default, as the script is).
    """
    cpu, own = time.process_time(), time.thread_time()
    with opencv_threads(threads) if threads is not None else nullcontext():
        results, seconds = baseline(sequence)
    cpu, own = time.process_time() - cpu, time.thread_time() - own
    n = len(results) + 1
    return n / seconds, sum(m is None for *_, m in results), 1000 * cpu / n, 1000 * own / n


def compare_end_to_end(sequence: str | Path, frontends: list[str], baseline: BaselineRun,
                       thread_counts: list[int] | None = None, repeats: int = 3,
                       report: Callable[[str], None] | None = None) -> list[EndToEnd]:
    """fusion-vo beside the plain OpenCV script, frames per second end to end.

    Each repeat runs the plain script twice (OpenCV's default threads, as written, and OpenCV on one
    thread), then every frontend with every thread count, on the same recording; each ratio is taken
    against the faster of the two script runs of the same repeat.

    Parameters
    ----------
    sequence : path
    frontends : list of str
    baseline : callable
        :func:`fusion_vo.baseline.run`, or another script's ``run``.
    thread_counts : list of int, optional
        Default ``[1, cores available]`` (just ``[1]`` on one core).
    repeats : int
    report : callable, optional
        Called with a line after each run (progress).
    """
    if thread_counts is None:
        thread_counts = sorted({1, available_cores()})
    n = len(Recording(sequence))
    bases = [EndToEnd("plain OpenCV script", None, n, baseline=True),
             EndToEnd("plain OpenCV script", 1, n, baseline=True)]
    rows = [EndToEnd(fe, th, n) for fe in frontends for th in thread_counts]
    for r in range(repeats):
        for base in bases:
            fps, base.failed, cpu, own = time_baseline(sequence, baseline, base.threads)
            base.fps.append(fps)
            base.cpu_ms.append(cpu)
            base.thread_ms.append(own)
            if report:
                report(f"repeat {r + 1}/{repeats}: {base.label} {_rate(base, fps)}")
        best = max(base.fps[-1] for base in bases)
        for row in rows:
            fps, row.failed, row.rss_mb, cpu, own = time_run(sequence, row.name, row.threads)
            row.fps.append(fps)
            row.cpu_ms.append(cpu)
            row.thread_ms.append(own)
            row.ratio.append(fps / best)
            if report:
                report(f"repeat {r + 1}/{repeats}: {row.label} {_rate(row, fps, row.ratio[-1])}")
    return [*bases, *rows]


def _rate(row: EndToEnd, fps: float, ratio: float | None = None) -> str:
    """A progress line's rate: frames per second (and the ratio), or why there is none."""
    if row.tracked < MIN_TRACKED:
        return f"({not_a_speed(row.tracked)})"
    return f"{fps:.1f} frames/s" + ("" if ratio is None else f" ({ratio:.2f}x)")


def not_comparable(rows: list[EndToEnd]) -> list[EndToEnd]:
    """The rows of :func:`compare_end_to_end` whose rate is not a speed (too few frame pairs tracked)."""
    return [row for row in rows if row.tracked < MIN_TRACKED]


def _span(values: list[float], fmt: str) -> str:
    med = statistics.median(values)
    if len(values) == 1:
        return format(med, fmt)
    return f"{format(med, fmt)} ({format(min(values), fmt)}-{format(max(values), fmt)})"


def end_to_end_table(rows: list[EndToEnd]) -> str:
    """A Markdown table: frames/s and the ratio to the plain script (median, and range over repeats)."""
    lines = ["| run | frames/s end to end | x plain script (the faster run) | CPU time per frame | of it in the "
             "calling thread | failed frames | memory after each quarter |", "|---|---|---|---|---|---|---|"]
    bases_measured = all(row.tracked >= MIN_TRACKED for row in rows if row.baseline)
    for row in rows:
        ratio = _span(row.ratio, ".2f") if row.ratio else "–"
        if row.ratio and not (bases_measured and row.tracked >= MIN_TRACKED):
            ratio = "not comparable"
        fps = _span(row.fps, ".0f") if row.tracked >= MIN_TRACKED else not_a_speed(row.tracked)
        memory = " / ".join(f"{m:.0f}" for m in row.rss_mb) + " MB" if row.rss_mb else "–"
        own = f"{_span(row.thread_ms, '.2f')} ms" if row.thread_ms else "–"
        lines.append(f"| {row.label} | {fps} | {ratio} | {_span(row.cpu_ms, '.2f')} ms | {own} "
                     f"| {row.failed} | {memory} |")
    return "\n".join(lines)


#: end-to-end targets, times the plain script's frames per second: (one thread, all threads)
TARGETS = {"klt": (3.0, 5.0), "features": (2.0, 2.0)}


def wall_bound_ms(row: EndToEnd, repeat: int, cores: int) -> float:
    """The shortest wall time per frame [ms] that a run's CPU time allows: the calling thread (the tracker)
    cannot go faster than its own CPU time, nor the run than its total CPU time spread over
    ``min(threads, cores)`` cores. An idle machine with no waiting between the threads would reach it."""
    usable = max(min(row.threads or cores, cores), 1)
    return max(row.thread_ms[repeat], row.cpu_ms[repeat] / usable)


def bound_table(rows: list[EndToEnd], cores: int | None = None) -> str:
    """A Markdown table: for each fusion-vo row of :func:`compare_end_to_end`, the lower bound on its wall
    time per frame (:func:`wall_bound_ms`) and the highest ratio to the plain script it allows, beside the
    target (``TARGETS``).

    The plain script's side is the same bound of its faster run in the same repeat: it has no pipeline
    to wait on, so on an idle machine its wall time per frame is that bound. Both sides are CPU times, so
    the ratio holds up on a loaded machine, where the wall-clock ratios do not. It is a ceiling for
    fusion-vo: a target above it cannot be met without cutting CPU time, and waits between fusion-vo's
    threads can keep it from being reached.
    """
    cores = cores or available_cores()
    bases = [row for row in rows if row.baseline]
    lines = ["| run | CPU time per frame (all threads / calling thread) | shortest possible wall time per frame "
             "| the same for the plain script | highest possible x plain script | target | within reach |",
             "|---|---|---|---|---|---|---|"]
    for row in rows:
        if row.baseline or not row.cpu_ms:
            continue
        repeats = range(min(len(row.cpu_ms), *(len(b.cpu_ms) for b in bases)))
        bound = [wall_bound_ms(row, r, cores) for r in repeats]
        plain = [min(wall_bound_ms(b, r, cores) for b in bases) for r in repeats]
        ceiling = [p / b for p, b in zip(plain, bound)]
        one, every = TARGETS.get(split_spec(row.name)[0], (float("nan"), float("nan")))
        target = one if row.threads == 1 else every
        reach = "yes" if statistics.median(ceiling) >= target else "no"
        if row.tracked < MIN_TRACKED or any(b.tracked < MIN_TRACKED for b in bases):
            reach = "not comparable: too few frame pairs tracked"
        lines.append(f"| {row.label} | {_span(row.cpu_ms, '.2f')} / {_span(row.thread_ms, '.2f')} ms | "
                     f"{_span(bound, '.2f')} ms | {_span(plain, '.2f')} ms | {_span(ceiling, '.2f')} | {target:g} | "
                     f"{reach} |")
    return "\n".join(lines)


def first_frames(sequence: str | Path, n: int, out: str | Path) -> Path:
    """A recording of the first ``n`` frames of ``sequence`` (its camera only; frame files linked, not copied)."""
    sequence, out = Path(sequence), Path(out)
    t_ns, names, _ = read_frame_list(sequence / "cam0" / "data.csv")
    (out / "cam0" / "data").mkdir(parents=True)
    (out / "cam0" / "sensor.yaml").write_bytes((sequence / "cam0" / "sensor.yaml").read_bytes())
    with open(out / "cam0" / "data.csv", "w", newline="") as fh:
        fh.write("#timestamp [ns],filename\n")
        for stamp, name in zip(t_ns[:n], names[:n]):
            os.symlink((sequence / "cam0" / "data" / name).resolve(), out / "cam0" / "data" / Path(name).name)
            fh.write(f"{int(stamp)},{Path(name).name}\n")
    return out


def run_benchmark(sequence: str | Path, frontends: list[str], baseline: BaselineRun | None = plain_script.run,
                  thread_counts: list[int] | None = None, repeats: int = 3, max_frames: int | None = None,
                  stages: bool = True, out: Callable[[str], None] = print) -> list[EndToEnd]:
    """The whole benchmark of ``fusion-vo bench`` and ``benchmarks/frontend_speed.py end-to-end``; prints as
    it goes.

    With ``max_frames`` both fusion-vo and the plain script run on the first ``max_frames`` frames.
    With ``baseline=None`` the plain script is not run and the fusion-vo figures are printed without ratios.
    """
    with tempfile.TemporaryDirectory(prefix="fusion-vo-bench-") as tmp:
        seq = Path(sequence)
        if max_frames is not None and max_frames < len(Recording(seq)):
            seq = first_frames(seq, max_frames, Path(tmp) / "first")
        n = len(Recording(seq))
        out(f"{n} frames of {Recording(seq).camera.width}x{Recording(seq).camera.height} from {sequence}; "
            f"{available_cores()} cores available; {repeats} interleaved repeats; load average "
            f"{os.getloadavg()[0]:.2f} before")
        if baseline is None:
            out("no plain-script baseline: fusion-vo's figures without ratios")
            rows = [EndToEnd(fe, th, n) for fe in frontends for th in (thread_counts or sorted({1, available_cores()}))]
            for _ in range(repeats):
                for row in rows:
                    fps, row.failed, row.rss_mb, cpu, own = time_run(seq, row.name, row.threads)
                    row.fps.append(fps)
                    row.cpu_ms.append(cpu)
                    row.thread_ms.append(own)
        else:
            rows = compare_end_to_end(seq, frontends, baseline, thread_counts, repeats, report=out)
        out("")
        out(f"load average {os.getloadavg()[0]:.2f} after; frames per second end to end (decoding included, "
            "wall clock), median (range) over the repeats; each ratio is taken against the faster plain-script "
            "run of the same repeat:")
        out("")
        out(end_to_end_table(rows))
        if baseline is not None:
            out("")
            out("what the CPU time allows: the shortest wall time per frame is the larger of the calling thread's "
                "CPU time and the total CPU time over the cores used; the highest ratio is the plain script's "
                "(its faster run's) over fusion-vo's (median (range) over the repeats):")
            out("")
            out(bound_table(rows))
        if stages:
            out("")
            out("where the time goes, one thread, CPU time per frame:")
            for fe in frontends:
                name, options = split_spec(fe)
                timing = time_frontend(seq, name, options=options)
                timing.frontend = fe
                out(format_timing(timing))
    return rows
