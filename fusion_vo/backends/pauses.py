"""Pauses in every stream: the estimate is split there and its pieces chained.

A *pause* is a stretch longer than ``FusionConfig.max_gap`` in which no stream the run uses has a
sample (no camera frame, no wheel, IMU, range or GPS reading): the logger stopped, or the recording
was cut and joined. Nothing was sampled in it, so the backends are not asked to estimate inside it (a
factor graph has nothing to tie the poses across it, a constant-velocity model would invent the motion,
and a grid of nodes over an hour would cost time for no data). :func:`split` cuts the streams into
pieces at every pause, each piece is fused on its own (starting at the origin), and :func:`chain` puts
the pieces one after the other, for every trajectory separately:

* **camera**: the frontend matched the frames on both sides of the pause (one of its increments spans
  it): the piece starts at the pose of the frame before the pause composed with that increment, and
  the increment's covariance is added to the start's;
* **held**: nothing measured the motion during the pause: the piece starts at the previous piece's
  last pose (with its covariance); the motion during the pause is unknown and is *not* in the
  covariance, which a note says;
* **gps**: a piece with GPS fixes is placed in the world frame (ENU) by its own fixes; nothing is
  chained into it.

A camera slower than ``max_gap`` alone has a pause between every two frames; :func:`cuts` leaves those
to the backends, which bridge them on the camera's increments (the node grid of
:mod:`fusion_vo.backends.timeline` is not filled where no stream has samples). Work therefore grows with
the samples, never with the seconds between them. Each pause becomes a note (:func:`pause_notes`) and
an entry of :attr:`FusionResult.pauses <fusion_vo.backends.result.FusionResult>` (``start``, ``end``,
``seconds`` on the recording clock, ``joined``: ``camera``, ``held`` or ``gps``).
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass

import numpy as np

from fusion_vo.backends.timeline import SensorStreams
from fusion_vo.geometry import se2
from fusion_vo.measurements import PoseData, VisualIncrement

logger = logging.getLogger(__name__)

#: array fields of the stream dataclasses that are not per-sample
_NOT_PER_SAMPLE = ("T_BS", "lever_arm")


@dataclass
class Pause:
    """A stretch without any sample in any stream.

    Attributes
    ----------
    start, end : float
        Last sample before and first sample after the pause [s, recording clock].
    join : VisualIncrement or None
        A usable camera increment from the last frame before the pause to the first after it (the
        frontend matched the frames on both sides), or None.
    """

    start: float
    end: float
    join: VisualIncrement | None = None

    @property
    def seconds(self) -> float:
        return self.end - self.start


def sample_times(streams: SensorStreams) -> np.ndarray:
    """Sorted, unique, finite times [s] of every sample of every stream (camera: both ends of every
    increment, failed ones included: a frame that arrived is a sample even when it gave no motion)."""
    parts = []
    if streams.visual:
        parts.append(np.array([v for inc in streams.visual for v in (inc.t0, inc.t1)], dtype=np.float64))
    for _, data in streams.sampled():
        if len(data.t):
            parts.append(np.asarray(data.t, dtype=np.float64))
    if not parts:
        return np.zeros(0)
    t = np.concatenate(parts)
    return np.unique(t[np.isfinite(t)])


def find_pauses(streams: SensorStreams, max_gap: float) -> list[Pause]:
    """Every stretch longer than ``max_gap`` [s] with no sample in any stream, in time order."""
    t = sample_times(streams)
    if len(t) < 2:
        return []
    gaps = np.flatnonzero(np.diff(t) > max_gap)
    pauses = [Pause(float(t[i]), float(t[i + 1])) for i in gaps]
    bounds = [-np.inf] + [p.end for p in pauses]
    after = [p.start for p in pauses[1:]] + [np.inf]
    for p, lo, hi in zip(pauses, bounds, after):
        for inc in streams.visual or ():
            if (inc.ok and lo <= inc.t0 <= p.start and p.end <= inc.t1 <= hi
                    and np.all(np.isfinite(inc.delta)) and np.all(np.isfinite(inc.covariance))):
                p.join = inc
    return pauses


def samples_between(data, lo: float, hi: float):
    """``data`` (a stream dataclass) with only the samples in ``[lo, hi]``; None when none are."""
    if data is None:
        return None
    t = np.asarray(data.t, dtype=np.float64)
    keep = (t >= lo) & (t <= hi)
    if not keep.any():
        return None
    n = len(t)
    changes = {}
    for f in dataclasses.fields(data):
        value = getattr(data, f.name)
        if f.name not in _NOT_PER_SAMPLE and isinstance(value, np.ndarray) and value.ndim and len(value) == n:
            changes[f.name] = value[keep]
    return dataclasses.replace(data, **changes)


def split(streams: SensorStreams, pauses: list[Pause]) -> list[SensorStreams]:
    """The streams cut at ``pauses``: one :class:`SensorStreams` per piece, in time order.

    A camera increment that spans a cut belongs to no piece (it is the pause's ``join``).
    """
    edges = [-np.inf] + [x for p in pauses for x in (p.start, p.end)] + [np.inf]
    pieces = []
    for lo, hi in zip(edges[0::2], edges[1::2]):
        visual = None
        if streams.visual is not None:
            visual = [inc for inc in streams.visual if lo <= inc.t0 and inc.t1 <= hi]
        piece = streams.replace(camera=visual)
        for name, data in streams.sampled():
            piece[name] = samples_between(data, lo, hi)
        pieces.append(piece)
    return pieces


def spans_time(streams: SensorStreams) -> bool:
    """The piece has at least two distinct sample times (something to estimate)."""
    return len(sample_times(streams)) >= 2


def _compose_cov(start: np.ndarray, start_cov: np.ndarray, rel: np.ndarray, rel_cov: np.ndarray) -> np.ndarray:
    """Covariances of ``start ⊕ rel`` for poses ``rel`` (N, 3) with covariances ``rel_cov`` (N, 3, 3)
    expressed in the frame of ``start`` (first-order propagation)."""
    c, s = np.cos(start[2]), np.sin(start[2])
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    out = np.empty((len(rel), 3, 3))
    for i, (p, P) in enumerate(zip(rel, rel_cov)):
        js = np.eye(3)
        js[0, 2] = -s * p[0] - c * p[1]
        js[1, 2] = c * p[0] - s * p[1]
        out[i] = js @ start_cov @ js.T + rot @ P @ rot.T
    return out


def _place(track: PoseData, cov: np.ndarray | None, start: np.ndarray, start_cov: np.ndarray
           ) -> tuple[PoseData, np.ndarray | None]:
    """A piece's track (starting at the origin) moved to begin at ``start``."""
    xyyaw = np.array([se2.compose(start, p) for p in track.xyyaw]).reshape(-1, 3)
    placed = PoseData(np.asarray(track.t), xyyaw)
    if cov is None:
        return placed, None
    return placed, _compose_cov(start, start_cov, track.xyyaw, np.asarray(cov))


def chain(pieces: list, pauses: list[Pause], placed: list[bool]) -> tuple[dict, dict, list[dict]]:
    """Chain the pieces' results (:class:`~fusion_vo.backends.result.FusionResult` or None for a piece
    with nothing to estimate) into whole trajectories.

    ``placed[i]`` says piece ``i`` was placed in the world frame by its own GPS fixes. The first piece
    with a result starts at the configured initial pose and is taken as it is; every later piece that
    its fixes did not place started at the origin and is moved to start at the previous piece's last
    pose, or where the camera's increment across the pause puts it. Returns name -> trajectory, name -> covariances, and one dict per pause (``start``, ``end``,
    ``seconds``, ``joined``).
    """
    tracks: dict[str, list[PoseData]] = {}
    covs: dict[str, list[np.ndarray]] = {}
    ends: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    joined = []
    for i, result in enumerate(pieces):
        pause = pauses[i - 1] if i else None
        how = None
        if pause is not None:
            how = "gps" if placed[i] else "camera" if pause.join is not None else "held"
            if result is None:
                how = "nothing to estimate after it"
            joined.append({"start": pause.start, "end": pause.end, "seconds": pause.seconds, "joined": how})
        if result is None:
            continue
        for name, track in result.trajectories.items():
            cov = result.covariances.get(name)
            if not placed[i] and name in ends:
                start, start_cov = ends[name]
                if pause is not None and pause.join is not None:
                    # the frame before the pause (on the previous track) ⊕ the camera's increment is the
                    # frame after it; the piece's own pose at that frame fixes where the piece starts
                    inc = pause.join
                    d = np.asarray(inc.delta, dtype=np.float64).reshape(3)
                    c = np.asarray(inc.covariance, dtype=np.float64).reshape(3, 3)
                    before = _pose_at(tracks[name][-1], inc.t0)
                    start_cov = _compose_cov(before, start_cov, d[None], c[None])[0]
                    start = se2.compose(se2.compose(before, d), se2.inverse(_pose_at(track, inc.t1)))
                track, cov = _place(track, cov, start, start_cov)
            if not len(track):
                continue
            tracks.setdefault(name, []).append(track)
            if cov is not None:
                covs.setdefault(name, []).append(np.asarray(cov))
            last_cov = np.asarray(cov)[-1] if cov is not None else np.zeros((3, 3))
            ends[name] = (np.asarray(track.xyyaw)[-1], last_cov)
    out = {name: PoseData(np.concatenate([p.t for p in parts]), np.concatenate([p.xyyaw for p in parts]))
           for name, parts in tracks.items()}
    out_cov = {name: np.concatenate(parts) for name, parts in covs.items()
               if sum(len(p) for p in parts) == len(out[name])}
    return out, out_cov, joined


def _pose_at(track: PoseData, t: float) -> np.ndarray:
    """The pose of ``track`` nearest in time to ``t``."""
    return np.asarray(track.xyyaw)[int(np.argmin(np.abs(np.asarray(track.t) - t)))]


def cuts(streams: SensorStreams, pauses: list[Pause]) -> list[Pause]:
    """The pauses to split the estimate at: all, except those the camera spans next to a piece with
    fewer than two sample times (a camera slower than ``max_gap`` alone: its frame gaps are pauses, and
    cutting there would leave nothing to estimate; the backends bridge them on its increments)."""
    chosen = list(pauses)
    while True:
        pieces = split(streams, chosen)
        short = [i for i, piece in enumerate(pieces) if not spans_time(piece)]
        drop = {id(p) for i in short for p in (chosen[i - 1] if i else None, chosen[i] if i < len(chosen) else None)
                if p is not None and p.join is not None}
        if not drop:
            return chosen
        chosen = [p for p in chosen if id(p) not in drop]


def note(entry: dict, t_first: float) -> str:
    """The run's note for one pause (an entry of :attr:`FusionResult.pauses`)."""
    where = (f"no sample in any stream for {entry['seconds']:.2f} s from t={entry['start']:.2f} "
             f"({entry['start'] - t_first:.2f} s in)")
    how = {
        "camera": "the camera's increment across it joins the estimate on either side",
        "held": "the estimate is split there and the next piece starts at the last pose: the motion during "
                "the pause is not measured and not in the covariance",
        "gps": "the estimate is split there; the next piece is placed by its own GPS fixes",
    }.get(entry["joined"], f"the estimate is split there ({entry['joined']})")
    return f"pause: {where}; {how}"


#: more pauses bridged by the camera than this are summed up in one note (a slow camera alone)
MAX_NOTES = 5


def pause_notes(entries: list[dict], t_first: float) -> list[str]:
    """Notes for the pauses: one each, except that many the camera bridged are summed up in one."""
    bridged = [e for e in entries if e["joined"] == "camera"]
    if len(bridged) <= MAX_NOTES:
        return [note(e, t_first) for e in entries]
    longest = max(bridged, key=lambda e: e["seconds"])
    summary = (f"pause: {len(bridged)} times no sample in any stream for longer than max_gap between two camera "
               f"frames (the longest {longest['seconds']:.2f} s from t={longest['start']:.2f}); the camera's "
               "increments carry the estimate through (all in summary.json)")
    return [summary] + [note(e, t_first) for e in entries if e["joined"] != "camera"]
