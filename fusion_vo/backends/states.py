"""The scalar states one run carries, the same table for both backends.

Each sensor declares its states in its own module (:class:`~fusion_vo.sensors.registry.State`): the IMU its
gyro bias ``b_g`` and AHRS offset ``o_ψ``, the camera the visual scale ``k_v``, the wheels their base factor
``k_b``, distance scale ``k_r`` and curvature bias, a registered sensor whatever it adds. For one run,
:func:`run_states` turns them into the table both backends consume, in the registry's order: each state's prior
``N(initial, sigma²)``, its random walk ``q`` (``Δx ~ N(0, q² Δt)``) and whether it is estimated or held at
``initial``. The EKF appends the table to its pose and twist (:class:`~fusion_vo.backends.ekf.PlanarEkf`), the
factor graph makes one variable per estimated state and calibration segment
(:class:`~fusion_vo.backends.graph_builder.GraphBuilder`), and both report the estimates through
:func:`calibration`.

A state that :attr:`~fusion_vo.sensors.registry.State.needs` another sensor's measurement is estimated only where
the motion tells it apart (:func:`observability`): the camera's ``k_v`` needs a distance measured besides the
camera's (the wheels, the range finder: each sensor declares it), the wheels' ``k_b`` a heading change measured
besides the wheels' (the camera, the gyro, a heading sensor); ``k_r`` is estimated with both. A live run decides
this from the sensors it fuses (:func:`observable_from`), a whole recording's from the measurements on its node
grid.
"""

from __future__ import annotations

from fusion_vo.sensors import registry
from fusion_vo.sensors.registry import Sensor, State, StateContext


def _others(owner, sensors):
    """The sensors of ``sensors`` other than ``owner`` and than those that stand in for it
    (:attr:`~fusion_vo.sensors.registry.Sensor.also_available_as`: the odometry twist for the wheels)."""
    return [s for s in sensors if s.name != owner.name and owner.name not in s.also_available_as]


def _needed(needs: str):
    """The declaration a state's ``needs`` asks of another sensor."""
    return (lambda s: s.absolute_distance) if needs == "distance" else (lambda s: s.absolute_heading)


def observability(iv) -> dict[str, bool]:
    """For each state that :attr:`~fusion_vo.sensors.registry.State.needs` another sensor's measurement, whether
    the motion on the node grid ``iv`` tells it apart: its sensor's measurements are on the grid
    (:meth:`~fusion_vo.sensors.registry.Sensor.measured_on`) and another sensor measures what it needs there
    (:meth:`~fusion_vo.sensors.registry.Sensor.gives_distance`, :meth:`~fusion_vo.sensors.registry.Sensor.gives_heading`).
    """
    sensors = registry.sensors()
    out = {}
    for owner in sensors:
        for state in owner.states:
            if state.needs is None:
                continue
            gives = Sensor.gives_distance if state.needs == "distance" else Sensor.gives_heading
            out[state.name] = owner.measured_on(iv) and any(gives(s, iv) for s in _others(owner, sensors))
    return out


def observable_from(sensors) -> dict[str, bool]:
    """:func:`observability` for a live run fusing the sensors named in ``sensors`` (each declaration taken as met:
    the data is not known ahead)."""
    fused = [registry.get(n) for n in dict.fromkeys(sensors)]
    out = {}
    for owner in registry.sensors():
        for state in owner.states:
            if state.needs is None:
                continue
            present = any(s.name == owner.name or owner.name in s.also_available_as for s in fused)
            out[state.name] = present and any(_needed(state.needs)(s) for s in _others(owner, fused))
    return out


def stood_in(present) -> frozenset:
    """The sensors not in ``present`` (names) whose measurements come from a sensor of ``present`` standing in for
    them (:attr:`~fusion_vo.sensors.registry.Sensor.also_available_as`: the wheels, from an odometry twist)."""
    present = set(present)
    stand_ins = [registry.get(name) for name in present if registry.resolve(name) is not None]
    return frozenset(owner.name for owner in registry.sensors()
                     if owner.name not in present and any(owner.name in s.also_available_as for s in stand_ins))


def live_context(config, sensors, facts) -> StateContext:
    """The :class:`~fusion_vo.sensors.registry.StateContext` of a live run fusing the sensors named in
    ``sensors``, whose data is not known ahead: each counted as its live intake counts it (an odometry twist as
    the wheels, the IMU as the gyro), with what its samples may also bring (``Live.also_counted``: the IMU's AHRS
    heading, which may arrive in any interval); ``facts`` as the run's files give them (the scale priors)."""
    used = set()
    for name in sensors:
        live = registry.get(name).live
        used.add(live.counted_as or name if live is not None else name)
        used.update(live.also_counted if live is not None else ())
    s = set(sensors)
    return StateContext(config, frozenset(used), observable_from(s), stood_in(s), dict(facts))


def context_of(iv, config, present) -> StateContext:
    """The :class:`~fusion_vo.sensors.registry.StateContext` of the node grid ``iv`` of a whole recording, whose
    streams hold the data of the sensors named in ``present``."""
    return StateContext(config, frozenset(iv.counts), observability(iv), stood_in(present), dict(iv.facts))


def run_states(context: StateContext, plain=()) -> tuple[State, ...]:
    """The states a run carries (module docstring), in the registry's order: every state with a rule as its rule
    gives it for ``context``, and those of ``plain`` (the states without a rule of the sensors whose data the run
    uses, :func:`fusion_vo.sensors.registry.states`, as the sensors' steps left them)."""
    given = {st.name: st for st in plain}
    out = []
    for sensor in registry.sensors():
        for state in sensor.states:
            if state.rule is not None:
                out.append(state.rule(state, context))
            elif state.name in given:
                out.append(given.pop(state.name))
    return tuple(out) + tuple(given.values())


def estimated(states) -> tuple[State, ...]:
    """The states of ``states`` the backends estimate (the others are held at their initial value)."""
    return tuple(st for st in states if st.estimated)


def calibration(iv, values: dict, sigmas: dict | None = None) -> dict:
    """A backend's calibration report on the node grid ``iv``: each estimated state's value (``values``, by
    name) and, where ``sigmas`` has it, its standard deviation as ``NAME_sigma``, followed by the figures
    derived from it (:attr:`State.derived <fusion_vo.sensors.registry.State.derived>`: the camera height, the
    wheel base)."""
    sigmas = sigmas or {}
    out: dict = {}
    for st in estimated(iv.states):
        if st.name not in values:
            continue
        value = float(values[st.name])
        out[st.name] = value
        if st.name in sigmas:
            out[f"{st.name}_sigma"] = float(sigmas[st.name])
        if st.derived is not None:
            out.update({name: v for name, (v, _) in st.derived(value, st.sigma, iv).items()})
    return out


def calibration_priors(iv) -> dict[str, dict]:
    """The prior ``{"mean": m, "sigma": s}`` of every state the backends estimate on ``iv`` and of the figures
    derived from it (the camera height ``h`` with σ ``h σ_kv``, the wheel base ``b`` with ``b σ_kb``): the values
    the EKF starts from and the graph's prior factors hold."""
    out: dict = {}
    for st in estimated(iv.states):
        out[st.name] = {"mean": float(st.initial), "sigma": float(st.sigma)}
        if st.derived is not None:
            for name, (mean, sigma) in st.derived(st.initial, st.sigma, iv).items():
                out[name] = {"mean": mean, "sigma": sigma}
    return out
