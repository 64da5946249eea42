"""The state variables a sensor adds to both backends, and what decides how a run carries them.

Each :class:`State` a sensor declares (:attr:`~fusion_vo.sensors.registry.Sensor.states`: a bias, a scale, an
offset) is a scalar with a prior and a random walk, and a measurement-model argument of that name: the EKF appends
it to its state vector (the prior as its initial value and variance, the random walk as process noise), the factor
graph makes it a variable per calibration segment tied by the random walk. Its prior and random walk are the
registered ones unless the configuration sets them (``fusion: {states: {NAME: {initial, sigma, random_walk}}}``,
:class:`StatePrior`). A state with a rule (:attr:`State.rule`) is decided per run from a :class:`StateContext`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Callable, Mapping

from pydantic import Field

from fusion_vo.config.base import MAX_NUMBER, ConfigError, Float, Section, Sigma, Walk


@dataclass(frozen=True)
class State:
    """A scalar state variable a sensor adds to both backends (module docstring).

    Attributes
    ----------
    name : str
        The measurement-model argument it is (unique among all sensors' states and the built-in arguments).
    initial : float
        Prior mean and initial value (default 0).
    sigma : float
        Prior standard deviation (default 1; positive).
    random_walk : float
        Random walk [unit/√s] (default 0: a constant, estimated from all the data).
    estimated : bool
        Whether the backends estimate it (default True). When False it is held at ``initial``: the EKF keeps it in
        its state vector with a negligible variance and no random walk, the factor graph makes no variable for it.
    symbol : str or None
        The letter of its variables among GTSAM's symbols (None: one the graph picks among the free letters).
    rule : callable or None
        ``rule(state, context) -> State``: the state as a run carries it, decided from the run's
        :class:`StateContext` (its prior, random walk and ``estimated`` taken from the sensor's configuration
        section and the observability of the run). A state with a rule is carried by every run, its sensor's
        data used or not (another sensor's model may take it as an argument: the range finder's visual scale),
        and is configured in its sensor's section, not in ``fusion: {states: ...}``. None: carried, as registered
        or configured, while its sensor's data is used.
    derived : callable or None
        ``derived(value, sigma, iv) -> {name: (value, sigma)}``: further calibration figures its estimate gives on
        the node grid ``iv`` (the camera height from the visual scale), reported beside it.
    needs : {"distance", "heading"} or None
        What another sensor must measure (:attr:`~fusion_vo.sensors.registry.Sensor.absolute_distance`,
        :attr:`~fusion_vo.sensors.registry.Sensor.absolute_heading`) for
        the motion to tell this state apart: a distance for the visual scale, a heading for the wheel base
        (:func:`~fusion_vo.backends.states.observability`); its rule reads ``context.observable[name]``.
    """

    name: str
    initial: float = 0.0
    sigma: float = 1.0
    random_walk: float = 0.0
    estimated: bool = True
    symbol: str | None = None
    rule: Callable | None = None
    derived: Callable | None = None
    needs: str | None = None

    def __post_init__(self) -> None:
        if self.needs not in (None, "distance", "heading"):
            raise ValueError(f"state {self.name}: needs must be 'distance', 'heading' or None, not {self.needs!r}")
        try:
            self.prior()
        except ConfigError as exc:
            raise ValueError(f"state {self.name}: {str(exc).removeprefix('StatePrior: ')}") from None

    @property
    def configurable(self) -> bool:
        """Whether ``fusion: {states: {NAME: ...}}`` sets its prior: a state without a :attr:`rule` (one with a rule
        takes its prior from its sensor's section)."""
        return self.rule is None

    def prior(self) -> StatePrior:
        """Its prior and random walk as a configuration section (the defaults of ``fusion: {states: {NAME: ...}}``)."""
        return StatePrior(initial=self.initial, sigma=self.sigma, random_walk=self.random_walk)

    def configured(self, prior: StatePrior | None) -> State:
        """This state with the prior and random walk of ``prior`` (itself when None)."""
        if prior is None:
            return self
        return dataclasses.replace(self, initial=prior.initial, sigma=prior.sigma, random_walk=prior.random_walk)


@dataclass(frozen=True)
class StateContext:
    """What decides the states a run carries (:attr:`State.rule`), the same whether the run is a whole recording's
    (:func:`~fusion_vo.backends.timeline.build_intervals`) or a live one's
    (:class:`~fusion_vo.backends.streaming.StreamingFusion`, from the sensors it fuses).

    Attributes
    ----------
    config : FusionConfig
    used : frozenset of str
        The measurement kinds the run fuses, as its counts name them (``camera``, ``wheel``, ``gyro``, ``ahrs``,
        ``range``, ``gps``, a registered sensor's name).
    observable : dict of str to bool
        For each state that :attr:`State.needs` a measurement of another sensor, whether the run has it and the
        motion can tell the state apart (:func:`~fusion_vo.backends.states.observability`).
    stood_in : frozenset of str
        The sensors whose measurements the run takes from a sensor standing in for them
        (:attr:`~fusion_vo.sensors.registry.Sensor.also_available_as`: the wheels, when only an odometry twist is fused).
    facts : mapping
        Facts of the run a rule may read, by name: those of its node grid
        (:attr:`~fusion_vo.backends.timeline.Intervals.facts`), among them the priors ``visual_scale_sigma`` and
        ``wheel_scale_sigma`` the run's files give (:func:`~fusion_vo.backends.timeline.scale_priors`).
    """

    config: Any
    used: frozenset
    observable: dict
    stood_in: frozenset
    facts: Mapping


class StatePrior(Section):
    """Prior and random walk of a sensor's state variable, as configured (``fusion: {states: {NAME: ...}}``).

    Its defaults are those the sensor registers (:class:`State`); a configuration replaces them.
    """

    initial: Float = Field(0.0, ge=-MAX_NUMBER, le=MAX_NUMBER, description="Prior mean and initial value.")
    sigma: Sigma = Field(1.0, description="Prior standard deviation.")
    random_walk: Walk = Field(0.0, description="Random walk [unit/√s] (0: a constant, estimated from all the data).")
