"""The sensors the backends know, each registered by its own module.

A :class:`Sensor` gathers everything about one sensor that the rest of the library needs: where its data
lives in a recording and how it is read, its data in :class:`~fusion_vo.sensors.streams.SensorStreams`,
its configuration section, how its samples become measurements on the node grid
(:func:`~fusion_vo.backends.timeline.build_intervals`; kept in ``Intervals.sensors[name]``, a container its module
defines), and its contributions to the EKF
(:meth:`~fusion_vo.backends.ekf.PlanarEkf.step`) and to the factor graph
(:class:`~fusion_vo.backends.graph_builder.GraphBuilder`), and the heading components the heading monitor judges
(:class:`HeadingSource`) and the distances the speed check compares (:class:`DistanceSource`). The timeline, both backends, ``SensorStreams``, the monitor and the recording reader
iterate :func:`sensors` instead of naming sensors, so adding a sensor is one module
plus one :func:`register` call (README, "Adding a sensor")::

    register(Sensor(name="compass", where="compass0/", ...))

The built-in sensors register themselves in :mod:`~fusion_vo.sensors.visual` (``camera``),
:mod:`~fusion_vo.sensors.wheel` (``wheel``, ``odom``), :mod:`~fusion_vo.sensors.imu` (``imu``),
:mod:`~fusion_vo.sensors.range` (``range``) and :mod:`~fusion_vo.sensors.gps` (``gps``), in that order;
:mod:`~fusion_vo.sensors.instances` declares the kinds ``odom`` and ``imu`` (:func:`register_kind`).

Hooks with an ``order`` run sorted by it across all sensors (stable, so equal orders keep the
registration order): a sensor's measurements may need another's (the camera's slope projection needs the
IMU's), and the EKF's stacked update and the graph's factor lists keep one fixed order. The built-in
sensors use multiples of 10; a new one picks any number (the default 100 runs after them).

A sensor may add state (:mod:`fusion_vo.sensors.state`): each :class:`State` it declares (a bias, a scale, an
offset: a scalar with a prior and a random walk) becomes a measurement-model argument of that name, carried by both
backends whenever the sensor's data is used. Its estimate at the end is reported in
``FusionResult.calibration`` under its name, with its standard deviation as ``NAME_sigma``. The built-in
calibrations are states of the built-in sensors declared the same way, each with a rule (:attr:`State.rule`) that
decides its prior and whether the run estimates it (the gyro bias and AHRS offset in
:mod:`~fusion_vo.sensors.imu`, the visual scale in :mod:`~fusion_vo.sensors.visual`, the wheels' in
:mod:`~fusion_vo.sensors.wheel_states`); :mod:`fusion_vo.backends.states` makes one table of a run's states for both
backends. Only the pose, the twist and the heading are arguments the backends supply themselves
(:data:`fusion_vo.sensors.model.ARGUMENT_SIZES`).

A sensor fed live (:meth:`fusion_vo.backends.streaming.StreamingFusion.add`) declares a :class:`Live`
intake: how one sample is read and checked, and how buffered samples become its data, or (the camera, GPS:
samples that make nodes) where a checked sample goes instead (``Live.take``).

Several instances of a kind (``odom1`` ... ``odom9``, ``imu1`` ... ``imu9``, besides instance 0, the sensors
``odom`` and ``imu``) are made by a factory the kind registers (:func:`register_kind`), the first time a name asks
for one (:func:`get`, :func:`known`, :func:`ensure`): a sensor like any other from then on. A name whose number is
outside ``1..MAX_INSTANCE`` or written otherwise (``odom0``, ``odom01``, ``odom10``) is no sensor.
"""

from __future__ import annotations

import re
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Callable

from fusion_vo.config.base import Section
from fusion_vo.sensors.model import ARGUMENT_SIZES
from fusion_vo.sensors.sources import DistanceSource, HeadingSource  # noqa: F401 (a Sensor's, here too)
from fusion_vo.sensors.state import State, StateContext, StatePrior  # noqa: F401 (a Sensor's, here too)

#: the built-in sensor modules, imported (and so registered) on first use of the registry
BUILTIN_MODULES = ("fusion_vo.sensors.visual", "fusion_vo.sensors.wheel", "fusion_vo.sensors.imu",
                   "fusion_vo.sensors.range", "fusion_vo.sensors.gps", "fusion_vo.sensors.instances")
DEFAULT_ORDER = 100.0


@dataclass(frozen=True)
class Step:
    """One contribution of a sensor to a stage, run in ``order`` among all sensors' contributions."""

    order: float
    run: Callable


@dataclass(frozen=True)
class ClockOffset:
    """A clock offset a sensor's :attr:`Sensor.clock` step found and removed from its data in a batch run.

    Attributes
    ----------
    key : str
        Its name in ``FusionResult.time_offsets`` (``odom_delay``).
    seconds : float
        The offset removed [s].
    note : str
        The sentence the run's notes give it.
    """

    key: str
    seconds: float
    note: str


@dataclass(frozen=True)
class Live:
    """How :meth:`StreamingFusion.add <fusion_vo.backends.streaming.StreamingFusion.add>` takes a sensor's samples.

    Attributes
    ----------
    sample : callable
        ``sample(m) -> (t, payload)``: the time and the values of one sample ``m`` (a number, an array or a tuple
        of them; ``None`` entries are allowed and not checked); a non-finite or malformed one is counted as gated.
    data : callable
        ``data(t, payloads, fusion) -> data``: the buffered samples around a node interval (``t`` an array, the
        payloads a list, ``fusion`` the :class:`~fusion_vo.backends.streaming.StreamingFusion` for its
        calibrations) as the sensor's data for :class:`~fusion_vo.sensors.streams.SensorStreams`.
    min_rows : int
        Samples an interval needs to be built from (default 2: they are interpolated at the node times).
    neighbours : int or callable
        Extra samples read on each side of an interval (a running median around them; default 0), or
        ``neighbours(config) -> int``.
    counted_as : str or None
        The name its counts are reported under (default: the sensor's).
    also_counted : tuple of str
        Other kinds of measurement its samples may bring (the IMU: its AHRS headings, ``ahrs``), taken as used by a
        live run's states (:attr:`StateContext.used`), since they may arrive in any interval.
    samples : callable or None
        ``samples(data) -> iterable of (t, sample)``: its data as live samples (``t`` their arrival time), for
        replaying a recording (:func:`~fusion_vo.backends.streaming.time_ordered_messages`, ``fusion-vo replay``).
    message : str or None
        The kind its replayed samples are named by (default: the sensor's name; the camera's are ``visual``, the
        odometry's ``twist``, the names of :class:`~fusion_vo.backends.streaming.StreamingFusion`'s ``add_*``).
    order : float
        Among samples that arrive at the same time, those of a smaller ``order`` come first (default 4: after the
        built-in sensors' 0 to 4, in registration order).
    take : callable or None
        ``take(fusion, payload)``: for a sensor whose samples make nodes rather than being interpolated at them
        (the camera's increments, GPS fixes): what the fusion does with a sample that was read and passed the
        checks every sample gets (declared, finite, within the horizon) instead of buffering it (``data``,
        ``min_rows`` and ``neighbours`` are then unused).
    values : callable or None
        ``values(payload) -> list``: the numbers of a sample that must be finite (default: the payload's
        entries that are not None).
    clock : callable or None
        ``clock(fusion) -> clock or None``: what puts its samples on the run's clock as they come (the odometry
        twist's delay behind the gyro, :class:`~fusion_vo.sensors.sync.TwistClock`), made when the engine is
        built (None: the run needs none). The engine hands it every sample of another stream
        (``observe(stream, t, payload)``) and takes the time of each of its own from it (``correct(t, payload)``);
        when its ``offset`` [s] changes, the samples of its ``stream`` buffered and not yet processed move by the
        change, and the intervals that read them are processed again. Nodes wait ``lag()`` seconds for its
        samples; ``remounted(t, rates)`` gives it the gyro's yaw rates re-read after the IMU's mounting was
        corrected; ``note(t_first)`` is its sentence in the run's notes, or None.
    """

    sample: Callable
    data: Callable | None = None
    min_rows: int = 2
    neighbours: Any = 0
    counted_as: str | None = None
    also_counted: tuple = ()
    samples: Callable | None = None
    take: Callable | None = None
    values: Callable | None = None
    message: str | None = None
    order: float = 4
    clock: Callable | None = None


@dataclass(frozen=True)
class Carry:
    """A value a sensor's ``intervals`` step finds once, from its first samples, and every later build of the
    node grid keeps (the IMU: the offset between its AHRS's north and the initial heading). It lives in
    ``Intervals.carry[name]``: a batch run builds the whole grid at once, the streaming engine hands the value from
    one interval to the next and keeps it with each node for its rewinds.

    Attributes
    ----------
    turn : callable
        ``turn(value, yaw) -> value``: the value once the world frame is turned by ``yaw`` (GPS's alignment,
        :mod:`fusion_vo.backends.world`).
    ahead : callable or None
        ``ahead(rows) -> float``: while the value is not found, the seconds after an interval's start whose samples
        the interval's build reads to find it, given the sensor's buffered live samples ``rows`` (``(t, payload)``);
        the streaming engine waits for them. None: none beyond the interval.
    """

    turn: Callable
    ahead: Callable | None = None


def turned(carry: dict, yaw: float) -> dict:
    """The carried values ``carry`` (sensor name -> value, :class:`Carry`) once the world frame is turned by ``yaw``."""
    return {name: get(name).carry.turn(value, yaw) for name, value in carry.items()}


@dataclass(frozen=True)
class Sensor:
    """A sensor as the library sees it (module docstring).

    Attributes
    ----------
    name : str
        The name of ``--sensors`` and of ``SensorStreams.select``.
    where : str
        What a recording lacks when the sensor is asked for but has no data (``"gps0/ (usable fixes)"``).
    field : str or None
        A second name its data answers to in :class:`~fusion_vo.sensors.streams.SensorStreams` (the camera's
        increments are ``visual``), besides its own name; None: its own name only. The data is a dataclass with
        sample times ``t`` and per-sample arrays (the camera's: a list of increments), so that the node grid
        covers it and a pause in every stream cuts it (:mod:`fusion_vo.backends.pauses`).
    min_samples : int
        Samples (``len(data)``) it needs to be available (default 1).
    folder : str or None
        Its folder in a recording (``"gps0"``); None: not read from a recording.
    read : callable or None
        ``read(recording) -> data``: the reader of that folder.
    has : callable or None
        ``has(recording) -> bool``: whether the recording has the sensor (default: its folder is present,
        :meth:`fusion_vo.recording.Recording.has`).
    wanted : callable or None
        ``wanted(selected, present) -> bool``: whether to read it for the sensor names ``selected`` given what
        the recording has (``present``: name -> bool); default: when its own name is selected.
    default : callable or bool
        Used when no sensors are named: a bool, or ``default(present) -> bool`` (default True).
    pick : callable or None
        ``pick(streams, selected) -> data or None``: its data for :meth:`SensorStreams.select`; default: its
        data when its name is selected.
    also_available_as : tuple of str
        Names this sensor's data also answers to in ``select`` (odometry twist data for ``wheel``).
    config : tuple (str, type) or None
        ``(section, model)``: its configuration section, a :class:`~fusion_vo.config.base.Section` whose fields
        carry their defaults, ranges and descriptions. A section that is not a field of
        :class:`~fusion_vo.backends.config.FusionConfig` is read from the configuration's ``fusion: {section: ...}``
        key into ``FusionConfig.sensors[section]`` and checked like any other (unknown keys are errors).
    absolute_position : bool
        The sensor measures the position in a world frame of its own (GPS: East-North-Up at its datum). When
        its data is used, the backends estimate in that frame and start at the pose aligned to its first
        measurements (:func:`fusion_vo.backends.world.align_world`: ``Intervals.initial_pose`` and
        ``initial_sigma``); a piece of a recording with such data is placed by it (:mod:`fusion_vo.backends.pauses`).
    node_times : callable or None
        ``node_times(data, nodes, config) -> nodes``: node times the sensor needs besides the grid's.
    grid : callable or None
        ``grid(n_steps, config) -> measurements``: the empty container of its measurements on a node grid of
        ``n_steps`` intervals (a dataclass of its module), put in ``Intervals.sensors[name]`` before any
        sensor's ``intervals`` step runs, so that every sensor (and the consistency monitor) finds it there
        whether or not the sensor has data. None: the sensor's ``intervals`` step puts what it needs in
        ``iv.sensors[name]`` itself.
    intervals : Step or None
        ``run(iv, streams, config, counts)``: its samples onto the node grid, into ``iv.sensors[name]`` of
        :class:`~fusion_vo.backends.timeline.Intervals`, updating ``counts[name]``
        (:class:`~fusion_vo.backends.result.SensorCount`).
    coverage : callable or None
        ``coverage(iv) -> (label, ok)``: the node intervals its samples cover (``ok``, after the consistency
        monitor's decisions) and the name its counts go under; a run of uncovered intervals longer than half a
        second inside the data becomes a note (``"label unavailable from ... to ..."``).
    on_grid : callable or None
        ``on_grid(iv) -> bool``: whether its measurements are on the node grid ``iv``, which its states that
        :attr:`State.needs` another sensor's measurement require too (the camera: when an increment is placed).
        Default: its samples are used there (``Intervals.uses(name)``).
    whole_recording : Step or None
        ``run(iv, config)``: on a whole recording's node grid ``iv``, once every sensor's samples are on it and before
        the consistency monitor judges them, what needs all of them (the camera's heading noise estimated against
        the gyro, :func:`fusion_vo.sensors.visual_noise.apply`). Not run by the streaming engine.
    readings : callable or None
        ``readings(iv, config) -> list of Readings``: its measurements on the node grid of
        :class:`~fusion_vo.backends.timeline.Intervals`, as readings of its measurement models
        (:class:`~fusion_vo.sensors.readings.Readings`): what both backends consume, each through its one adapter.
    carry : Carry or None
        A value its ``intervals`` step finds once and later builds keep (:class:`Carry`).
    turn : callable or None
        ``turn(iv, yaw)``: its measurements in ``iv`` re-expressed once the world frame is turned by ``yaw``
        (absolute headings: the AHRS's; GPS's alignment, :mod:`fusion_vo.backends.world`).
    graph_keyframes : callable or None
        ``graph_keyframes(iv) -> indices``: grid nodes that must stay pose variables when the graph keeps only
        every ``keyframe_every``-th (a GPS fix's node).
    states : tuple of State
        State variables the sensor adds to both backends: while its data is used, or, for a state with a rule,
        as the rule decides for every run (module docstring).
    absolute_heading : bool or callable
        The sensor measures the heading (absolute, or up to an offset it estimates as a state) or its change on
        a scale of its own (a gyro): beside the wheels it is a heading reference, so the wheel-base factor is
        estimated (:func:`~fusion_vo.backends.states.observability`). True: when its samples are used on
        the node grid (``Intervals.uses(name)``); ``absolute_heading(iv) -> bool``: when that says so (the camera:
        when an increment is measured; the IMU: when its gyro or its AHRS is used). Default False.
    absolute_distance : bool or callable
        The sensor measures distance on a scale of its own (the wheels' travel, the range finder's height of the
        camera, GPS's fixes): beside the camera the visual scale is estimated, and with a heading reference beside the wheels
        their distance scale too (:func:`~fusion_vo.backends.states.observability`). True and callable as
        :attr:`absolute_heading`. Default False.
    heading_reference : bool, callable or None
        The sensor measures the heading, or its change, without a bias of its own (the camera, the IMU's AHRS,
        GPS, a compass): beside the wheels and a gyro it tells a difference of the wheels' radii (their
        curvature bias) from the gyro's bias, so ``wheel.estimate_curvature: auto`` estimates the curvature
        (:func:`~fusion_vo.sensors.wheel_states.curvature_observable`). ``heading_reference(data) -> bool``
        decides from the sensor's data, or with ``data`` None for a live run, which has none yet (the camera:
        some increment measured; the IMU: its samples carry an orientation, unknown live). None (the
        default): as :attr:`absolute_heading` when that is a bool (a gyro of its own declares False).
    live : Live or None
        Its intake in :class:`~fusion_vo.backends.streaming.StreamingFusion` (``add(name, sample)``); the
        camera and GPS, whose samples make nodes, hand them on with ``Live.take``.
    heading : tuple of HeadingSource
        The heading components it gives the heading monitor (the IMU: its gyro and its AHRS).
    distance : tuple of DistanceSource
        The distances it gives the speed check (the wheels', the camera's).
    first_guesses : Step or None
        ``run(iv, guesses) -> {state: value}``: closed-form first values of states on the node grid ``iv`` for the
        factor graph's first linearisation (a state without one starts at its prior mean), given those of the steps
        before it in ``order`` (``guesses``): the gyro bias's (the IMU, 10), the visual scale's (the camera, 20), the
        wheel base's (the wheels, 30), each from another sensor's motion on the grid.
    motion : Step or None
        ``run(iv, motion) -> motion``: the body motion ``(dx, dy, dψ)`` over each node interval of ``iv`` ((K, 3), NaN
        where unknown) as this sensor measures it, given that of the steps before it in ``order``: the streaming
        engine's motion from a node to a time between nodes (a GPS fix's, a late increment's frame). The built-in
        ones: the wheels' arc (10, the odometry twist's too), then the gyro's turn where the arc is known (20).
    clock : Step or None
        ``run(streams, config) -> (streams, offset)``: in a batch run, before the node grid is built, its data in
        ``streams`` moved onto another sensor's clock (the odometry twist's timestamps onto the gyro's), with the
        :class:`ClockOffset` removed or None, which the run reports (``FusionResult.time_offsets`` and a note).
    dead_reckoning : tuple (str, callable) or None
        ``(track, make)``: ``make(data, config) -> PoseData`` (``config``: the
        :class:`~fusion_vo.backends.config.FusionConfig`) is the track its data alone gives, which a batch run
        keeps beside the fused ones as ``track`` (``track.tum``); where several sensors with data name the same
        track, the first in :func:`sensors`' order makes it (the wheels' ticks before the odometry twist, both
        ``wheel``).
    """

    name: str
    where: str = ""
    field: str | None = None
    min_samples: int = 1
    folder: str | None = None
    read: Callable | None = None
    has: Callable | None = None
    wanted: Callable | None = None
    default: Any = True
    pick: Callable | None = None
    also_available_as: tuple = ()
    config: tuple | None = None
    absolute_position: bool = False
    node_times: Callable | None = None
    grid: Callable | None = None
    intervals: Step | None = None
    coverage: Callable | None = None
    on_grid: Callable | None = None
    whole_recording: Step | None = None
    readings: Callable | None = None
    graph_keyframes: Callable | None = None
    carry: Carry | None = None
    turn: Callable | None = None
    states: tuple = ()
    live: Live | None = None
    absolute_heading: Any = False
    absolute_distance: Any = False
    heading_reference: Any = None
    heading: tuple = ()
    distance: tuple = ()
    first_guesses: Step | None = None
    motion: Step | None = None
    clock: Step | None = None
    dead_reckoning: tuple | None = None

    def data(self, streams) -> Any:
        """Its data in ``streams`` (a :class:`~fusion_vo.sensors.streams.SensorStreams`), or None."""
        return streams.get(self.name)

    def gives_heading(self, iv) -> bool:
        """Whether it is a heading reference on the node grid ``iv`` (:attr:`absolute_heading`)."""
        return self._declared(self.absolute_heading, iv)

    def gives_distance(self, iv) -> bool:
        """Whether it measures distance on the node grid ``iv`` (:attr:`absolute_distance`)."""
        return self._declared(self.absolute_distance, iv)

    def measured_on(self, iv) -> bool:
        """Whether its measurements are on the node grid ``iv`` (:attr:`on_grid`)."""
        return bool(self.on_grid(iv)) if self.on_grid is not None else iv.uses(self.name)

    def _declared(self, declaration, iv) -> bool:
        """A declaration on the node grid ``iv``: a callable's answer, or True when its samples are used there."""
        if callable(declaration):
            return bool(declaration(iv))
        return bool(declaration) and iv.uses(self.name)

    def references_heading(self, data=None) -> bool:
        """Whether it is a heading reference for the wheels' curvature (:attr:`heading_reference`) with its
        ``data`` (None: a live run's, not known yet)."""
        ref = self.heading_reference
        if ref is None:
            ref = self.absolute_heading if isinstance(self.absolute_heading, bool) else False
        return bool(ref(data)) if callable(ref) else bool(ref)

    def available(self, data) -> bool:
        """Whether ``data`` has enough samples to be used."""
        return data is not None and len(data) >= self.min_samples

    def present(self, recording) -> bool:
        """Whether ``recording`` has this sensor's folder (:meth:`fusion_vo.recording.Recording.has`: a broken link
        too, which its reader then reports)."""
        if self.has is not None:
            return bool(self.has(recording))
        if self.folder is None or not hasattr(recording, "has"):
            return False
        return recording.has(self.folder)

    def is_wanted(self, selected, present: dict) -> bool:
        if self.wanted is not None:
            return bool(self.wanted(selected, present))
        return self.name in selected and present.get(self.name, False)

    def by_default(self, present: dict) -> bool:
        if callable(self.default):
            return bool(self.default(present))
        return bool(self.default)


_REGISTRY: dict[str, Sensor] = {}
_ORDERED: dict = {}  # attribute -> the sorted steps (cleared when a sensor is added or removed)
_ALIASES: dict = {}  # second name (Sensor.field) -> its sensor (cleared likewise)
_SORTED: list = []  # the sensors in sensors() order (cleared likewise)
_KINDS: dict[str, Callable[[int], Sensor]] = {}  # kind -> factory of its instance N (register_kind)
_loaded = False

#: the highest instance number of a kind (``odom1`` ... ``odom9``)
MAX_INSTANCE = 9
_INSTANCE_NAME = re.compile(r"([a-z]+)([1-9])")


def register_kind(kind: str, factory: Callable[[int], Sensor]) -> None:
    """Declare that the sensors ``KIND1`` ... ``KIND9`` exist: ``factory(n)`` makes instance ``n`` (a
    :class:`Sensor` named ``f"{kind}{n}"``), registered the first time its name is asked for (module docstring)."""
    _KINDS[kind] = factory


def instance(name: str) -> Sensor | None:
    """The sensor ``name``: a registered one, or an instance of a declared kind made and registered now; None
    when it is neither."""
    _load_builtins()
    sensor = _REGISTRY.get(name)
    if sensor is not None or not isinstance(name, str):
        return sensor
    match = _INSTANCE_NAME.fullmatch(name)
    if match is None or match.group(1) not in _KINDS:
        return None
    sensor = _KINDS[match.group(1)](int(match.group(2)))
    if sensor.name != name:
        raise ValueError(f"the factory of kind '{match.group(1)}' made sensor '{sensor.name}' for '{name}'")
    return register(sensor)


def is_instance(name: str) -> bool:
    """Whether ``name`` is an instance of a declared kind (``odom1``), registered or not."""
    match = _INSTANCE_NAME.fullmatch(name) if isinstance(name, str) else None
    return match is not None and match.group(1) in _KINDS


def known(name: str) -> bool:
    """Whether ``name`` is a sensor (registered, or an instance of a declared kind, then registered)."""
    return instance(name) is not None


def ensure(names) -> None:
    """Register the instances of declared kinds among ``names`` (other names are left alone)."""
    for name in names:
        if isinstance(name, str):
            instance(name)


def register(sensor: Sensor, replace: bool = False) -> Sensor:
    """Add ``sensor`` to the registry (after those registered before it); returns it.

    A second sensor of the same name is an error unless ``replace``.
    """
    if sensor.name in _REGISTRY and not replace:
        raise ValueError(f"sensor '{sensor.name}' is already registered")
    if sensor.config is not None and not (isinstance(sensor.config[1], type) and issubclass(sensor.config[1], Section)):
        raise ValueError(f"sensor '{sensor.name}': its configuration section must be a fusion_vo.config.base.Section "
                         f"(a pydantic model of its options), not {sensor.config[1]!r}")

    others = [st for s in _REGISTRY.values() if s.name != sensor.name for st in s.states]
    taken = set(ARGUMENT_SIZES) | {st.name for st in others}
    symbols = {st.symbol for st in others if st.symbol}
    for state in sensor.states:
        if not isinstance(state, State):
            raise ValueError(f"sensor '{sensor.name}': states must be registry.State, not {type(state).__name__}")
        if state.name in taken:
            raise ValueError(f"sensor '{sensor.name}': state '{state.name}' is already a state of the backends")
        if state.symbol is not None and (not re.fullmatch(r"[a-wyz]", state.symbol) or state.symbol in symbols):
            raise ValueError(f"sensor '{sensor.name}': state '{state.name}': symbol must be a lower-case letter other "
                             f"than x that no other state uses, not {state.symbol!r}")
        taken.add(state.name)
        symbols.add(state.symbol)
    _REGISTRY[sensor.name] = sensor
    _forget_lookups()
    return sensor


def unregister(name: str) -> None:
    """Remove a sensor registered with :func:`register` (no error when it is not)."""
    _REGISTRY.pop(name, None)
    _forget_lookups()


def _forget_lookups() -> None:
    """Clear what is derived from the registered sensors (their sorted steps, second names and order)."""
    for cache in (_ORDERED, _ALIASES, _SORTED):
        cache.clear()


@contextmanager
def registered(sensor: Sensor):
    """``with registered(Sensor(...)):`` the sensor is known inside the block only."""
    _load_builtins()
    register(sensor)
    try:
        yield sensor
    finally:
        unregister(sensor.name)


#: the entry-point group through which an installed package adds its sensors (the command line included)
ENTRY_POINTS = "fusion_vo.sensors"


def _load_builtins() -> None:
    global _loaded
    if _loaded:
        return
    _loaded = True
    import importlib

    for module in BUILTIN_MODULES:
        importlib.import_module(module)
    load_entry_points()


def load_entry_points(group: str = ENTRY_POINTS) -> list[str]:
    """Register the sensors that installed packages declare in the entry-point ``group``; returns their names.

    An entry point names a :class:`Sensor` (registered), a function (called: it registers) or a module
    (imported: it registers at import), e.g. in a package's ``pyproject.toml``::

        [project.entry-points."fusion_vo.sensors"]
        compass = "my_robot.compass:COMPASS"

    One that fails to load is logged and skipped (the command line then reports its name as unknown).
    """
    import logging
    from importlib.metadata import entry_points

    log = logging.getLogger(__name__)
    before = set(_REGISTRY)
    for ep in entry_points(group=group):
        try:
            obj = ep.load()
            if isinstance(obj, Sensor):
                if obj.name not in _REGISTRY:
                    register(obj)
            elif callable(obj):
                obj()
        except Exception as exc:  # a broken plugin must not stop the library
            log.warning("sensor entry point %s (%s) not loaded: %s", ep.name, ep.value, exc)
    return [name for name in _REGISTRY if name not in before]


#: the built-in sensors' order (whichever module is imported first)
BUILTIN_ORDER = ("camera", "wheel", "odom", "imu", "range", "gps")


def sensors() -> list[Sensor]:
    """Every registered sensor: the built-in ones in :data:`BUILTIN_ORDER`, then the others in registration order."""
    _load_builtins()
    if not _SORTED:  # (the backends ask at every node)
        rank = {name: i for i, name in enumerate(BUILTIN_ORDER)}
        _SORTED.extend(sorted(_REGISTRY.values(), key=lambda s: rank.get(s.name, len(rank))))
    return list(_SORTED)


def names() -> tuple[str, ...]:
    """The registered sensor names."""
    return tuple(s.name for s in sensors())


def resolve(key: str) -> Sensor | None:
    """The sensor ``key`` names: a registered sensor or an instance of a declared kind (:func:`instance`), or the
    sensor whose second name (:attr:`Sensor.field`) it is; None when it is neither."""
    sensor = _REGISTRY.get(key) if _loaded else None  # (the common case, asked for at every node)
    if sensor is not None:
        return sensor
    sensor = instance(key)
    if sensor is not None:
        return sensor
    if not _ALIASES:
        _ALIASES.update({s.field: s for s in _REGISTRY.values() if s.field is not None})
    return _ALIASES.get(key)


def get(name: str) -> Sensor:
    """The sensor called ``name``, an instance of a declared kind made on first use (KeyError when none is)."""
    sensor = instance(name)
    if sensor is None:
        raise KeyError(name)
    return sensor


def heading_sources() -> list[tuple[Sensor, HeadingSource]]:
    """``(sensor, source)`` of every registered heading source, in :func:`sensors` order."""
    return [(s, h) for s in sensors() for h in s.heading]


def distance_sources() -> list[tuple[Sensor, DistanceSource]]:
    """``(sensor, source)`` of every registered distance source, in :func:`sensors` order."""
    return [(s, d) for s in sensors() for d in s.distance]


def states(used, config=None) -> tuple[State, ...]:
    """The configurable state variables (:attr:`State.configurable`) that the sensors named in ``used`` add (in
    :func:`sensors` order), with the prior and random walk ``config`` (a
    :class:`~fusion_vo.backends.config.FusionConfig`) sets in its ``states`` section."""
    used = set(used)
    configured = getattr(config, "states", None) or {}
    return tuple(state.configured(configured.get(state.name)) for s in sensors() if s.name in used
                 for state in s.states if state.configurable)


def all_states() -> tuple[State, ...]:
    """Every registered sensor's state variables, as registered (in :func:`sensors` order)."""
    return tuple(state for s in sensors() for state in s.states)


def configurable_states() -> tuple[State, ...]:
    """The registered states whose prior ``fusion: {states: {NAME: ...}}`` sets: those without a rule (a state
    with one takes its prior from its sensor's section)."""
    return tuple(state for state in all_states() if state.configurable)


def ordered(attribute: str, used=None) -> list[tuple[Sensor, Step]]:
    """``(sensor, step)`` of every registered step ``attribute`` (a :class:`Step` or a tuple of them), sorted by
    order; ``used`` (names) keeps only those sensors."""
    if used is None and attribute in _ORDERED:  # the backends ask for the same steps at every node
        return _ORDERED[attribute]
    steps = []
    for s in sensors():
        if used is not None and s.name not in used:
            continue
        value = getattr(s, attribute)
        for step in (value if isinstance(value, tuple) else (value,) if value is not None else ()):
            steps.append((s, step))
    steps.sort(key=lambda item: item[1].order)
    if used is None:
        _ORDERED[attribute] = steps
    return steps
