"""Merging sensor streams of different rates onto one clock of nodes.

Both backends estimate the robot at a sequence of *node times* ``T_0 < T_1 < … < T_K``: every camera
frame time, plus fill-in nodes at ``step_hz`` wherever the camera leaves a gap longer than
``1.5 / step_hz`` (dropped frames, a camera starting late) and another stream has samples at most ``max_gap``
apart around it (where no stream has any, there is nothing to put on a node, and the nodes grow with the
samples, not with the seconds). Between two frames the fill-in nodes are evenly spaced (:func:`fill_nodes`);
after the last frame (no camera at all, the camera stream stopping early) no later frame is known, and the
nodes step ``1 / step_hz`` at a time up to the last sample (:func:`step_nodes`), as a live run places them.
Every measurement is applied at its own time:

* visual increments relate the nodes at their own ``t0`` and ``t1`` (which are node times);
* wheel travel and the gyro's integrated angle are *cumulative* quantities ``L(t), R(t), Θ(t)``; they
  are interpolated linearly at the node times (exact for constant speed between two samples, whatever
  the rates and jitter), so each node interval gets ``d_l = L(T_{k+1}) - L(T_k)`` etc.;
* AHRS headings and range readings are interpolated at the node times; the AHRS's north is aligned
  to the initial heading over its first quarter second (the gyro carries the heading within it);
* GPS fixes are not interpolated: every fix time is a node (a fix within 1 ms of a camera frame uses
  that frame's node), so both backends apply the fix to the pose at its own time. A camera increment
  that a fix node splits spans two intervals (the backends already handle increments spanning several).

Each sensor's part of this (its node times, how its samples go onto the grid) is registered by its own
module (:mod:`fusion_vo.sensors.registry`); :func:`node_times` and :func:`build_intervals` run the
registered steps in their order.

An interval is only given a wheel or gyro measurement when the stream covers it without a gap longer
than ``max_gap`` and without a gated sample; otherwise the sensor is counted as missing there and the
other sensors carry the estimate. Streams whose timestamps are not increasing are put in order (counted
as ``reordered``); exact duplicates are dropped and counted as gated.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from fusion_vo.backends.config import FusionConfig
from fusion_vo.measurements import SensorCount
from fusion_vo.measurements.grid import (  # noqa: F401 (the grid's helpers, here too)
    coverage, node_index, node_indices, ordered_fields, outage_notes, time_order, uncovered_runs, when,
)
from fusion_vo.errors import InputError
from fusion_vo.sensors import registry
from fusion_vo.sensors.readings import Readings
from fusion_vo.sensors.streams import SensorStreams  # noqa: F401 (the run's input, here too)
from fusion_vo.backends.monitor import check_heading_sources, check_speed_sources
from fusion_vo.backends.states import context_of, run_states
from fusion_vo.sensors.gps import GPS_SNAP

logger = logging.getLogger(__name__)


def __getattr__(name: str):
    if name == "SENSORS":  # the registered sensor names (:mod:`fusion_vo.sensors.registry`)
        return registry.names()
    if name == "GPS_SNAP":
        return GPS_SNAP
    raise AttributeError(name)


@dataclass
class Intervals:
    """All measurements expressed on the node grid.

    Attributes
    ----------
    t : ndarray (K+1,)
        Node times [s].
    sensors : dict
        Sensor name -> its measurements on the grid: a container its own module defines and registers
        (:attr:`Sensor.grid <fusion_vo.sensors.registry.Sensor.grid>`; the camera's
        :class:`~fusion_vo.sensors.visual.CameraGrid`, the wheels' :class:`~fusion_vo.sensors.wheel.WheelGrid`,
        the IMU's :class:`~fusion_vo.sensors.imu.ImuGrid`, the range finder's
        :class:`~fusion_vo.sensors.range.RangeGrid`, GPS's :class:`~fusion_vo.sensors.gps.GpsGrid`), or what its
        ``intervals`` step put there.
    cx, cy : ndarray (K,)
        Slope factors projecting body travel to the horizontal (1 on flat ground or without a sensor measuring
        the tilt).
    facts : dict
        What the streams carry about the camera besides the sensors' data (:data:`fusion_vo.sensors.streams.FACTS`:
        ``camera_height``, the height the visual increments assume, and its stated σ, ...), for the models that
        need them (the range finder's, the visual scale's), and the run's scale priors ``visual_scale_sigma`` and
        ``wheel_scale_sigma`` (:func:`scale_priors`): the relative prior standard deviations of the visual scale
        ``k_v`` (camera height) and of the wheels' distance scale ``k_r`` (common wheel radius),
        ``height_sigma / height`` of ``cam0/sensor.yaml`` and ``radius_sigma / radius`` of ``wheel0/sensor.yaml``
        when stated, else ``FusionConfig.visual_scale_sigma`` and ``FusionConfig.wheel_scale_sigma``. The common
        scale of camera and wheels is unobservable from the two alone: their ratio is measured, and these priors
        (or a range finder) decide how a disagreement is shared.
    counts : dict[str, SensorCount]
        Bookkeeping of the input stage (gated samples, reordering, missing coverage).
    notes : list[str]
        Camera outages and streams that stop.
    carry : dict
        Sensor name -> the value its ``intervals`` step found once and later builds keep
        (:class:`~fusion_vo.sensors.registry.Carry`; the IMU's: AHRS heading minus the estimate's heading, from
        the first AHRS sample).
    episodes : list
        The monitor's :class:`~fusion_vo.backends.monitor.Episode` s.
    initial_pose, initial_sigma : ndarray (3,) or None
        Start pose and its standard deviations ``(x, y, yaw)`` when the world frame was aligned to the
        fixes (ENU at the datum, :func:`~fusion_vo.sensors.gps.align_to_fixes`); None: the configured
        ``initial_pose``, taken as exact.
    states : tuple of registry.State
        The scalar states both backends carry (:func:`fusion_vo.backends.states.run_states`): the built-in
        calibrations, estimated or held, and the states of the sensors with data; in streaming use the run's.
    """

    t: np.ndarray
    sensors: dict = field(default_factory=dict)
    cx: np.ndarray | None = None
    cy: np.ndarray | None = None
    facts: dict = field(default_factory=dict)
    counts: dict[str, SensorCount] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    carry: dict = field(default_factory=dict)
    episodes: list = field(default_factory=list)
    initial_pose: np.ndarray | None = None
    initial_sigma: np.ndarray | None = None
    states: tuple = ()

    def __post_init__(self) -> None:
        K = len(self.t) - 1
        if self.cx is None:
            self.cx = np.ones(K)
        if self.cy is None:
            self.cy = np.ones(K)

    @property
    def extra(self) -> dict:
        """:attr:`sensors`, under the name a sensor registered outside the library may also use."""
        return self.sensors

    @property
    def n_steps(self) -> int:
        return len(self.t) - 1

    @property
    def dt(self) -> np.ndarray:
        return np.diff(self.t)

    def uses(self, sensor: str) -> bool:
        return sensor in self.counts


# --------------------------------------------------------------------------- grid
def fill_nodes(a: float, b: float, step: float) -> np.ndarray:
    """The fill-in nodes strictly between the nodes ``a`` and ``b``: none when ``b`` comes within 1.5 steps of
    ``a``, else the fewest evenly spaced nodes that keep every interval at most ``step``.

    The one rule of the node grid between known nodes (camera frames, the ends of the data): a batch run fills
    every gap with it (:func:`node_times`), a live run fills the gap to the next frame with it once that frame
    has arrived (:class:`~fusion_vo.backends.streaming.StreamingFusion`), so both put their nodes at the same
    times.
    """
    if b - a <= 1.5 * step:
        return np.zeros(0)
    return np.linspace(a, b, int(np.ceil((b - a) / step)) + 1)[1:-1]


def step_node(after: float, step: float, end: float = np.inf, own: float | None = None) -> float | None:
    """The node after ``after`` where no later frame is known, as a live run places it: one ``step`` on, or the last
    sample's time ``end`` when that comes first; None when ``end`` is within half a step (no node is left). A time
    ``own`` that is a node of its own (a GPS fix) is the node instead when it comes more than :data:`GPS_SNAP`
    before that."""
    if end - after <= 0.5 * step:
        return None
    return fix_first(min(after + step, end), own)


def fix_first(nxt: float, own: float | None) -> float:
    """The next node: ``nxt``, or the time ``own`` of a node of its own (a GPS fix) when it comes more than
    :data:`GPS_SNAP` before it (within that, the fix is at ``nxt``)."""
    return float(own) if own is not None and own < nxt - GPS_SNAP else nxt


def step_nodes(after: float, end: float, step: float, own: np.ndarray = np.zeros(0)) -> np.ndarray:
    """The nodes after ``after`` up to the last sample's time ``end`` where no later frame is known: :func:`step_node`
    after :func:`step_node` (so added up as a live run adds them), with the times ``own`` (sorted) that are nodes of
    their own; one within :data:`GPS_SNAP` of a node is at that node."""
    out = []
    i = 0
    while True:
        while i < len(own) and own[i] <= after + GPS_SNAP:  # (at a node already)
            i += 1
        nxt = step_node(after, step, end, own[i] if i < len(own) else None)
        if nxt is None:
            return np.array(out)
        out.append(nxt)
        after = nxt


def node_times(streams: SensorStreams, config: FusionConfig) -> np.ndarray:
    """Camera frame times plus fill-in nodes at ``step_hz`` over the span of all streams (:func:`fill_nodes`)."""
    starts, ends, others = [], [], []
    cam = np.zeros(0)
    if streams.visual:
        cam = np.array([v for inc in streams.visual for v in (inc.t0, inc.t1)], dtype=np.float64)
        cam = np.unique(cam[np.isfinite(cam)])
        # times within a nanosecond are one frame, kept at its first time (rounding to nanoseconds would move
        # an epoch-scale time by a float step, 0.24 µs, off the frame time a live run uses)
        cam = cam[np.concatenate([[True], np.diff(cam) > 1e-9])]
        if len(cam):
            starts.append(cam[0])
            ends.append(cam[-1])
    for _, data in streams.sampled():
        if len(data.t):
            tt = np.asarray(data.t, dtype=np.float64)
            tt = tt[np.isfinite(tt)]
            if len(tt):
                starts.append(tt.min())
                ends.append(tt.max())
                others.append(tt)
    if not starts:
        raise InputError("no measurements to fuse")
    start, end = min(starts), max(ends)
    step = 1.0 / config.step_hz
    nodes = list(cam)
    for edge in (start, end):
        if not len(cam) or np.min(np.abs(cam - edge)) > 0.5 * step:
            nodes.append(edge)
    nodes = np.unique(np.asarray(nodes))
    tail = np.zeros(0)  # the nodes after the last frame; the last of them replaces the last sample's time
    if len(nodes) > 1 and (not len(cam) or end - cam[-1] > 0.5 * step):
        # no later frame is known there: a live run's steps (step_nodes) up to the last sample
        own = [np.setdiff1d(s.node_times(data, nodes, config), nodes) for s in registry.sensors()
               if s.node_times is not None and (data := s.data(streams)) is not None]
        tail = step_nodes(nodes[-2], end, step, np.unique(np.concatenate([np.zeros(0), *own])))
        if len(tail):  # (none: the data spans less than half a step, its two ends are the nodes)
            nodes = nodes[:-1]
    gaps = np.diff(nodes)
    fill = [fill_nodes(a, b, step) for a, b, g in zip(nodes[:-1], nodes[1:], gaps) if g > 1.5 * step] + [tail[:-1]]
    nodes = np.append(nodes, tail[-1:])
    if sum(map(len, fill)):
        fill = np.concatenate(fill)
        # only between two samples of the other streams at most max_gap apart: a stretch without samples has
        # nothing to put on the nodes, and filling it would make the work grow with its seconds, not the samples
        sampled = np.unique(np.concatenate(others)) if others else np.zeros(0)
        if len(sampled) > 1:
            j = np.clip(np.searchsorted(sampled, fill, side="right"), 1, len(sampled) - 1)
            covered = (fill >= sampled[0]) & (fill <= sampled[-1]) & (sampled[j] - sampled[j - 1] <= config.max_gap)
            fill = fill[covered]
        else:
            fill = fill[:0]
        nodes = np.unique(np.concatenate([nodes, fill]))
    for s in registry.sensors():
        data = s.data(streams)
        if s.node_times is not None and data is not None:
            nodes = s.node_times(data, nodes, config)
    if len(nodes) < 2:
        raise InputError("the measurements span no time (need at least two distinct timestamps)")
    return nodes


@dataclass
class ScalePriors:
    """Prior standard deviations (relative) of the visual scale and of the wheels' distance scale, and the
    notes that say where they came from (:func:`scale_priors`)."""

    visual_scale_sigma: float
    wheel_scale_sigma: float
    notes: list[str] = field(default_factory=list)

    def facts(self) -> dict:
        """The two priors as facts of a run (:attr:`Intervals.facts`, :class:`~fusion_vo.sensors.registry.StateContext`)."""
        return {"visual_scale_sigma": self.visual_scale_sigma, "wheel_scale_sigma": self.wheel_scale_sigma}


def scale_priors(config: FusionConfig, camera_height: float | None, camera_height_sigma: float | None = None,
                 range_height_sigma: float | None = None, wheel_config=None, range_fused: bool = False) -> ScalePriors:
    """The priors of the two scales, the same for batch and streaming runs.

    The visual scale: ``camera_height_sigma / camera_height`` (``height_sigma`` of ``cam0/sensor.yaml``),
    else ``config.visual_scale_sigma`` (a mounting dimension that nothing measures during the run); when the
    backends measure the height with the range finder (``range_fused``) and nothing states it, the readings
    set it, not the mounting: at least one reading's ``config.range.sigma / camera_height``. When the
    increments were scaled with the range finder's heights (``range_height_sigma`` given: their typical
    standard deviation), at most ``range_height_sigma / camera_height``. The wheels' distance scale:
    ``radius_sigma / radius`` of ``wheel_config`` (``wheel0/sensor.yaml``), else ``config.wheel_scale_sigma``.
    """
    visual, wheel, notes = config.visual_scale_sigma, config.wheel_scale_sigma, []
    if camera_height_sigma is not None and camera_height:
        visual = float(camera_height_sigma / camera_height)
    elif range_fused and camera_height:
        visual = max(visual, float(config.range.sigma / camera_height))
    if range_height_sigma and camera_height:
        ranged = float(range_height_sigma / camera_height)
        if ranged < visual:  # the range finder's heights set the increments' scale
            visual = ranged
            notes.append(f"visual scale: prior σ {ranged:.2g} from the range finder's heights in the visual "
                         f"increments ({1e3 * range_height_sigma:.3g} mm)")
    if wheel_config is not None and wheel_config.radius_sigma is not None:
        wheel = wheel_config.relative_radius_sigma(wheel)
    return ScalePriors(visual, wheel, notes)


def sensor_readings(iv: "Intervals", config: FusionConfig) -> list[Readings]:
    """Every registered sensor's readings on the grid of ``iv`` (:attr:`Sensor.readings
    <fusion_vo.sensors.registry.Sensor.readings>`), after the consistency monitor's decisions."""
    out: list[Readings] = []
    for sensor in registry.sensors():
        if sensor.readings is not None:
            out.extend(r for r in sensor.readings(iv, config) if len(r))
    return out


# --------------------------------------------------------------------------- builder
def build_intervals(streams: SensorStreams, config: FusionConfig, nodes: np.ndarray | None = None,
                    carry: dict | None = None, states: tuple | None = None,
                    priors: ScalePriors | None = None) -> Intervals:
    """Express every stream of ``streams`` on the node grid (see the module docstring).

    ``nodes`` overrides the grid (streaming use builds one interval at a time); ``carry`` the values earlier
    builds found (:attr:`Intervals.carry`; by default each sensor finds its own, the AHRS's first heading is
    aligned to the initial yaw); ``states`` are the run's states when they are decided for the whole run (streaming use: one
    interval's data must not change them), else they are decided from this grid
    (:func:`~fusion_vo.backends.states.run_states`); ``priors`` likewise the run's scale priors
    (:func:`scale_priors`; streaming use: one interval's samples do not carry the sensors' files), else those of
    ``streams``, with their notes.
    """
    T = node_times(streams, config) if nodes is None else np.asarray(nodes, dtype=np.float64)
    K = len(T) - 1
    counts: dict[str, SensorCount] = {}
    notes: list[str] = []
    iv = Intervals(t=T, facts=streams.facts(), counts=counts, notes=notes)
    for sensor in registry.sensors():  # every sensor's (empty) measurements, data or not
        if sensor.grid is not None:
            iv.sensors[sensor.name] = sensor.grid(K, config)
    if priors is None:
        range_in_visual = streams.visual is not None and streams.range_in_visual
        priors = scale_priors(config, streams.camera_height, streams.camera_height_sigma,
                              streams.range_height_sigma if range_in_visual else None,
                              None if streams.wheel is None else streams.wheel.config,
                              range_fused=streams.range is not None and not range_in_visual)
        notes.extend(priors.notes)
    iv.facts.update(priors.facts())
    iv.carry = dict(carry or {})
    iv.states = registry.states([s.name for s in registry.sensors() if s.states and s.data(streams) is not None],
                                config)
    for sensor, step in registry.ordered("intervals"):  # each sensor's samples onto the grid (its own module)
        if sensor.data(streams) is not None:
            step.run(iv, streams, config, counts)
    if nodes is None:  # whole-recording use: check the heading sources and the speeds against each other
        for _, step in registry.ordered("whole_recording"):  # (the camera's heading noise from the gyro's)
            step.run(iv, config)
        iv.episodes = check_heading_sources(iv, config)
        iv.episodes += check_speed_sources(iv, config)
        iv.episodes.sort(key=lambda e: e.start)
        notes.extend(ep.note(T[0], T[-1]) for ep in iv.episodes)
    for sensor in registry.sensors():
        if sensor.coverage is None:
            continue
        name, ok = sensor.coverage(iv)
        if name in counts:
            notes.extend(outage_notes(name, T, ok))
    # with the built-in calibrations, decided here unless given for the run
    iv.states = run_states(context_of(iv, config, streams), iv.states) if states is None else tuple(states)
    return iv


